#import displace::bindings::params
#import displace::shade::{FsOut, frame, march_shell, shade_hit, shell_out}

// The raster path (GPU Gems 2 ch. 8, section 8.5) for one planar face: its
// shell box is drawn; the vertex stage moves the eye and light vectors into
// tangent space (listing 8-1), the fragment stage marches the distance map
// from the fragment's point on the shell (listing 8-2) and shades the hit
// (shade.wgsl).

struct VsOut {
    @builtin(position) clip: vec4f,
    // Map-space point on the shell: the ray's start (Donnelly's texCoord,
    // in depth units).
    @location(0) map_pos: vec3f,
    @location(1) tan_eye: vec3f,
    @location(2) tan_light: vec3f,
}

// Corner (u, v, w) of the shell box for each of the 36 vertices of its six
// faces, wound counter-clockwise seen from outside.
fn box_corner(index: u32) -> vec3f {
    var faces = array<vec4u, 6>(
        vec4u(4u, 5u, 7u, 6u), // top, w = 1
        vec4u(0u, 2u, 3u, 1u), // bottom, w = 0
        vec4u(0u, 1u, 5u, 4u), // v = 0
        vec4u(2u, 6u, 7u, 3u), // v = 1
        vec4u(0u, 4u, 6u, 2u), // u = 0
        vec4u(1u, 3u, 7u, 5u), // u = 1
    );
    var tri = array<u32, 6>(0u, 1u, 2u, 0u, 2u, 3u);
    let c = faces[index / 6u][tri[index % 6u]];
    return vec3f(f32(c & 1u), f32((c >> 1u) & 1u), f32((c >> 2u) & 1u));
}

@vertex
fn vs_main(@builtin(vertex_index) index: u32) -> VsOut {
    // The box spans every tile of the face (params.tiles; 1 x 1 unless the
    // map repeats).
    let uvw = box_corner(index) * vec3f(params.tiles, 1.0);
    let depth = 1.0 / frame.inv_bump_depth;
    let t = frame.face_t.xyz;
    let b = frame.face_b.xyz;
    let n = frame.face_n.xyz;
    let obj = frame.face_origin.xyz + uvw.x * t + uvw.y * b + uvw.z * depth * n;
    var out: VsOut;
    out.clip = frame.view_proj * vec4f(obj, 1.0);
    out.map_pos = vec3f(uvw.x * params.aspect.x, uvw.y * params.aspect.y, uvw.z);
    // Listing 8-1, as the direction of travel (the listing's eyeVec points
    // back at the eye): texture-space components scaled to the map's metric,
    // the normal component by the inverse bump depth.
    let eye_vec = obj - frame.eye.xyz;
    out.tan_eye = vec3f(
        dot(t, eye_vec) / dot(t, t) * params.aspect.x,
        dot(b, eye_vec) / dot(b, b) * params.aspect.y,
        dot(n, eye_vec) * frame.inv_bump_depth,
    );
    let light_vec = frame.light.xyz - obj;
    out.tan_light = vec3f(dot(normalize(t), light_vec), dot(normalize(b), light_vec), dot(n, light_vec));
    return out;
}

@fragment
fn fs_main(in: VsOut) -> FsOut {
    // Derivatives, listing 8-2's normalisation and the hit, or a discarded
    // fragment (shade.wgsl).
    let m = march_shell(in.map_pos, in.tan_eye);
    let depth = 1.0 / frame.inv_bump_depth;
    // Map units to the face's physical tangent frame: the baked proportions
    // across, the live depth along the normal.
    let to_phys = vec3f(length(frame.face_t.xyz) / params.aspect.x, length(frame.face_b.xyz) / params.aspect.y, depth);
    let rgb = shade_hit(m.hit, in.map_pos, m.dir, in.tan_light, to_phys, m.dx, m.dy);
    let p = in.map_pos + m.dir * m.hit.t;
    let uv = p.xy / params.aspect;
    let world = frame.face_origin.xyz + uv.x * frame.face_t.xyz + uv.y * frame.face_b.xyz + p.z * depth * frame.face_n.xyz;
    return shell_out(rgb, uv, m.hit, world);
}
