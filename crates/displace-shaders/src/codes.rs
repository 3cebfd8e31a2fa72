//! The Rust side of `shaders/convention.wgsl` and `techniques.wgsl`: the
//! codes and tolerances the shaders use, tied to `displace_core`'s
//! conventions. The test `convention_constants_match_rust` parses the WGSL
//! and checks every constant against these and against the core functions
//! they mirror; every Rust enum reaching WGSL goes through one code
//! function here.

use displace_core::techniques::Technique;
use displace_core::{Address, Method};

/// Offset of a texel's centre: texel `i` of `n` sits at `(i + 0.5) / n`
/// ([`displace_core::convention::texel_centre`]).
pub const TEXEL_CENTRE: f32 = 0.5;
/// Code of [`Address::Clamp`] (see [`address_code`]).
pub const ADDRESS_CLAMP: u32 = 0;
/// Code of [`Address::Repeat`].
pub const ADDRESS_REPEAT: u32 = 1;
/// Code of [`Method::Sphere`]: sphere tracing with early out, then the exact
/// walk (see [`method_code`]).
pub const METHOD_SPHERE: u32 = 0;
/// Code of [`Method::SphereFixed`]: Donnelly's fixed loop (listing 8-2).
pub const METHOD_SPHERE_FIXED: u32 = 1;
/// Code of [`Method::Exact`]: the exact walk alone, the reference.
pub const METHOD_EXACT: u32 = 2;
/// Hit kind: the ray left the shell without meeting the surface.
pub const HIT_NONE: u32 = 0;
/// Hit kind: the ray met the displaced surface.
pub const HIT_SURFACE: u32 = 1;
/// Hit kind: the ray enters the shell below the surface (through a side of
/// a clamped face's slab), so the shell's wall is what it meets.
pub const HIT_WALL: u32 = 2;
/// A non-displaced shape (displace-gpu's plain triangles), in the AOV's
/// kind channel.
pub const HIT_PLAIN: u32 = 3;
/// Flag: the hit converged (`MapHit::converged`): false only for
/// Donnelly's fixed loop when its steps ran out above the surface.
pub const FLAG_CONVERGED: u32 = 1;
/// Flag: the exact walk stopped at its cell cap ([`crate::MapParams::max_cells`]),
/// which a ray inside the shell never reaches; a guard against runaway loops.
pub const FLAG_CELL_CAP: u32 = 2;
/// The driver ended a trace loop before its own exits (lavapipe stops the
/// loops of one invocation after 65535 iterations in all): the result is
/// not a miss but unknown, and is refused (the batch queries' check).
pub const FLAG_LOOP_CUT: u32 = 4;
/// `exact.rs`: a segment starts inside when `z < h - 1e-7`.
pub const INSIDE_EPS: f32 = 1e-7;
/// `exact.rs`: roots of the ray-patch quadratic within this of a cell's
/// segment ends are kept, so hits on cell borders are not lost.
pub const ROOT_EPS: f32 = 1e-6;
/// `exact.rs`: below this leading coefficient the ray-patch equation is
/// solved as linear.
pub const LINEAR_EPS: f32 = 1e-12;
/// Stand-in for infinity: WGSL has no infinite literal, so `t_min` and
/// `t_max` are clamped to `[-BIG, BIG]` on the way to the GPU.
pub const BIG: f32 = 1e30;

/// The early-out threshold as a fraction of the smallest voxel side.
pub const TAU_VOXELS: f32 = displace_core::convention::TRACE_STOP_VOXELS;

/// The exact walk after the early out covers this many times the map's
/// underestimate bound, plus `tau`.
pub const BAND_FACTOR: f32 = displace_core::convention::TRACE_BAND_FACTOR;

/// The chord tolerance of curved meshes
/// ([`displace_core::convention::CHORD_TOLERANCE`]). `curved.wgsl` halves
/// a chord while its midpoint strays further than this from the ray's
/// curve in map position; the CPU measures the same offset in height
/// above the surface (the height field's slope included), which the
/// shader does not yet.
pub const CHORD_TOLERANCE: f32 = displace_core::convention::CHORD_TOLERANCE as f32;

/// Bits of fixed-point precision assumed for a linear sampler's weights.
/// Vulkan only promises `subTexelPrecisionBits >= 4`; desktop GPUs and
/// lavapipe use 8. The filtered path subtracts the resulting worst-case
/// interpolation error so the decoded distance stays a lower bound.
pub const FILTER_WEIGHT_BITS: u32 = 8;

/// Self-shadowing modes of `shade.wgsl` (displace-gpu's `Shadows`): none.
pub const SHADOWS_NONE: u32 = 0;
/// Hard shadows.
pub const SHADOWS_HARD: u32 = 1;
/// Soft shadows.
pub const SHADOWS_SOFT: u32 = 2;

/// The shader's code for an addressing mode: the only way an [`Address`]
/// reaches the GPU.
pub fn address_code(a: Address) -> u32 {
    match a {
        Address::Clamp => ADDRESS_CLAMP,
        Address::Repeat => ADDRESS_REPEAT,
    }
}

/// The shader's code for a trace method: the only way a [`Method`] reaches
/// the GPU.
pub fn method_code(m: Method) -> u32 {
    match m {
        Method::Sphere => METHOD_SPHERE,
        Method::SphereFixed => METHOD_SPHERE_FIXED,
        Method::Exact => METHOD_EXACT,
    }
}

/// Technique codes of `techniques.wgsl` (`TECH_*`), in the order of
/// [`Technique::ALL`]; the test `technique_constants_match_rust` checks the
/// WGSL side.
pub fn technique_code(t: Technique) -> u32 {
    Technique::ALL
        .iter()
        .position(|&x| x == t)
        .expect("every technique is in ALL") as u32
}
