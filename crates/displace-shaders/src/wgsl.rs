//! The WGSL sources, one constant a file of `shaders/`: the modules (a
//! `#define_import_path displace::...` line, then `#import`s of what each
//! takes from the others) and the entry points that only import. naga_oil
//! composes them: displace-gpu per entry point and distance-lookup flavour,
//! Bevy's shader cache for displace-bevy's material (which registers
//! [`CONVENTION`], [`DISTANCE_FILTERED`] and [`SURFACE`] beside its own
//! `displace::bindings`), so both run the one trace.

/// `displace::convention`: map-space constants, `MapParams` and the ray
/// structs, mirrored by [`crate::codes`] and [`crate::MapParams`].
pub const CONVENTION: &str = include_str!("../shaders/convention.wgsl");
/// `displace::distance` by `textureLoad` with hand interpolation (R32 and
/// R8 codes, the CPU's order of operations).
pub const DISTANCE_LOAD: &str = include_str!("../shaders/distance_load.wgsl");
/// `displace::distance` through a linear sampler (Donnelly's way, 8.5.2).
pub const DISTANCE_FILTERED: &str = include_str!("../shaders/distance_filtered.wgsl");
/// `displace::surface`: the bilinear height surface, the exact walk and the
/// trace (sphere tracing, then refinement).
pub const SURFACE: &str = include_str!("../shaders/surface.wgsl");
/// `displace::bindings` of this crate's group 0 (displace-gpu's `gpu_map::map_layout`),
/// one per distance-lookup flavour.
pub const BINDINGS_LOAD: &str = include_str!("../shaders/bindings_load.wgsl");
/// The same for the filtered distance textures (with the sampler).
pub const BINDINGS_FILTERED: &str = include_str!("../shaders/bindings_filtered.wgsl");
/// What both batch queries share: group 1's rays and the result flags.
pub const BATCH: &str = include_str!("../shaders/batch.wgsl");
/// The batch ray query's compute entry point.
pub const TRACE_COMPUTE: &str = include_str!("../shaders/trace_compute.wgsl");
/// Lambert plus normalised Blinn-Phong of one point light, shared by the
/// displaced hits and the plain triangles so both light alike.
pub const LIGHTING: &str = include_str!("../shaders/lighting.wgsl");
/// Normal-mapped Blinn-Phong shading with self-shadowing, texture lookups
/// with the base coordinate's derivatives (section 8.5.3).
pub const SHADE: &str = include_str!("../shaders/shade.wgsl");
/// The face's vertex and fragment stages (listings 8-1 and 8-2).
pub const RASTER: &str = include_str!("../shaders/raster.wgsl");
/// The shell of a mesh: vertex and fragment stages with per-vertex frames.
pub const MESH: &str = include_str!("../shaders/mesh.wgsl");
/// `displace::curved_prism`: one shell of a curved mesh as its storage
/// buffer holds it, mirrored by [`crate::curved_prisms::GpuPrism`].
pub const CURVED_PRISM: &str = include_str!("../shaders/curved_prism.wgsl");
/// `displace::curved_bindings` of displace-gpu's group 2: the prisms.
pub const CURVED_BINDINGS: &str = include_str!("../shaders/curved_bindings.wgsl");
/// `displace::curved_walk`: a curved mesh's shells walked from the fragment
/// where the ray enters them to the first hit, for every raster host.
pub const CURVED_WALK: &str = include_str!("../shaders/curved_walk.wgsl");
/// The raster path of curved meshes: their shells walked per fragment.
pub const CURVED: &str = include_str!("../shaders/curved.wgsl");
/// Non-displaced triangles, shaded like the CPU's direct light.
pub const PLAIN: &str = include_str!("../shaders/plain.wgsl");
/// The roofline: dependent trilinear fetches and nothing else.
pub const FETCH_LOOP: &str = include_str!("../shaders/fetch_loop.wgsl");
/// The viewer's present pass (frame and overlay).
pub const PRESENT: &str = include_str!("../shaders/present.wgsl");
/// The techniques engines ship beside distance mapping, in map space.
pub const TECHNIQUES: &str = include_str!("../shaders/techniques.wgsl");
/// The batch query of one technique.
pub const TECHNIQUE_COMPUTE: &str = include_str!("../shaders/technique_compute.wgsl");
