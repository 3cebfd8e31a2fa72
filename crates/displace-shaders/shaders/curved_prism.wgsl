#define_import_path displace::curved_prism

// One shell of a curved mesh, as the fragment walk reads it from its
// storage buffer. Rust: displace-shaders' `curved_prisms::GpuPrism` (the
// layout test checks the two agree: nine vec4, 144 bytes).
struct Prism {
    // Corners a, b, c; pa.w: the shells' top level, pb.w: the displacement depth.
    pa: vec4f,
    pb: vec4f,
    pc: vec4f,
    // Unit shell normals.
    na: vec4f,
    nb: vec4f,
    nc: vec4f,
    // Texture coordinates of the corners in map units within the mesh's
    // map window: (a, b) and (c, unused).
    mab: vec4f,
    mc: vec4f,
    // The shell across side k (corners k and k + 1 mod 3); -1: a wall.
    adj: vec4i,
}

