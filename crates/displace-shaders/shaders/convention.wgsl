#define_import_path displace::convention

// Map-space conventions shared with the CPU (crates/displace-core/src/convention.rs,
// sphere_trace.rs, exact.rs). Every constant here is parsed by the test
// `convention_constants_match_rust` and compared with the Rust side: change
// both together.
//
// A shader module (`#import displace::convention::{...}`), composed by
// naga_oil both in displace-gpu (shaders.rs) and in Bevy's shader cache. The
// resources the trace reads are declared by a `displace::bindings` module
// of each user: bindings_load.wgsl / bindings_filtered.wgsl here, the
// material's bind group in displace-bevy.
//
// Map space: x along the tangent (u), y along the bitangent (v), z along the
// normal, lengths in shell depths; one tile is [0, ax] x [0, ay] x [0, 1].

// Texel (i) of n sits at texture coordinate (i + TEXEL_CENTRE) / n.
const TEXEL_CENTRE: f32 = 0.5;

// Addressing across the face (depth always clamps).
const ADDRESS_CLAMP: u32 = 0u;
const ADDRESS_REPEAT: u32 = 1u;

// Trace methods (displace_core::Method).
const METHOD_SPHERE: u32 = 0u;
const METHOD_SPHERE_FIXED: u32 = 1u;
const METHOD_EXACT: u32 = 2u;

// Self-shadowing modes (displace_gpu::Shadows).
const SHADOWS_NONE: u32 = 0u;
const SHADOWS_HARD: u32 = 1u;
const SHADOWS_SOFT: u32 = 2u;

// What a ray hit (displace_core::sphere_trace::HitKind, plus "nothing").
const HIT_NONE: u32 = 0u;
const HIT_SURFACE: u32 = 1u;
const HIT_WALL: u32 = 2u;
// A non-displaced scene shape (plain.wgsl writes it to the AOV).
const HIT_PLAIN: u32 = 3u;

// Result flags.
const FLAG_CONVERGED: u32 = 1u;
// The exact walk ran into its cell budget: a bug guard, never expected.
const FLAG_CELL_CAP: u32 = 2u;
// The driver ended a trace loop early (surface.wgsl `loop_cut`).
const FLAG_LOOP_CUT: u32 = 4u;

// A segment starts under the surface when z < h - INSIDE_EPS (exact.rs).
const INSIDE_EPS: f32 = 1e-7;
// Root tolerance of the patch solve, relative to (1 + |t at the segment's
// end|), as exact.rs `patch_hit`.
const ROOT_EPS: f32 = 1e-6;
// The patch quadratic degenerates to a line when |k2| <= LINEAR_EPS * scale.
const LINEAR_EPS: f32 = 1e-12;

// How far (map units) a chord of a curved mesh's ray may stray from the
// curve at its midpoint before it is halved (curved_face.rs).
const CHORD_TOLERANCE: f32 = 1e-3;

// Stands in for infinity (WGSL has no infinity literal, and shader compilers
// may assume none occurs).
const BIG: f32 = 1e30;

// Everything the map-space trace needs, one uniform (Rust: `MapParams`).
struct MapParams {
    aspect: vec2f,
    tiles: vec2f,
    dist_size: vec3u,
    address: u32,
    height_size: vec2u,
    // Early-out threshold and the width of the exact walk after it
    // (sphere_trace.rs: tau = voxel / 4, band = 1.5 underestimate + tau).
    tau: f32,
    band: f32,
    // Filtered distance textures store (value - offset) / scale.
    decode_scale: f32,
    decode_offset: f32,
    max_cells: u32,
    method: u32,
    iterations: u32,
    t_min: f32,
    t_max: f32,
    pad_end: u32,
}

// One map-space ray of a batch query (Rust: `trace::RayIn`).
struct RayIn {
    origin: vec3f,
    pad_origin: f32,
    dir: vec3f,
    pad_dir: f32,
}

// Texel index i of a map n texels wide, wrapped or clamped (convention.rs
// `wrap_index`). The remainder is spelled as division and product, not `%`:
// WGSL's `%` truncates, but the GLSL that naga writes for OpenGL drivers keeps
// `%`, whose result GLSL leaves undefined for a negative operand, and the
// texels left of a repeating map's first tile are negative.
fn wrap_index(i: i32, n: u32, address: u32) -> i32 {
    let m = i32(n);
    if (address == ADDRESS_REPEAT) {
        let r = i - (i / m) * m;
        return select(r, r + m, r < 0);
    }
    return clamp(i, 0, m - 1);
}

// Lower texel index of the linear footprint of coordinate t over n texels, and
// the weight of the upper one (convention.rs `texel_lerp`).
fn texel_lerp(t: f32, n: u32) -> vec2f {
    let x = t * f32(n) - TEXEL_CENTRE;
    let i = floor(x);
    return vec2f(i, x - i);
}

// a + (b - a) t, in the CPU's order of operations (WGSL `mix` rounds differently).
fn lerp(a: f32, b: f32, t: f32) -> f32 {
    return a + (b - a) * t;
}
