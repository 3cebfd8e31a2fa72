//! `MapParams`, the uniform every trace reads (convention.wgsl), and how a
//! baked map and a trace's options set it: written once here for
//! displace-gpu's pipelines and displace-bevy's material alike.

use crate::codes::{address_code, method_code, BAND_FACTOR, BIG, TAU_VOXELS};
use bytemuck::{Pod, Zeroable};
use displace_core::{Address, TraceOptions};
use encase::ShaderType;
use glam::{UVec2, UVec3, Vec2, Vec3};

/// Mirror of WGSL `MapParams` (convention.wgsl), 80 bytes: `repr(C)` with
/// the WGSL offsets, so its bytes upload as they are (`bytemuck`), and
/// `encase`'s layout of it is the same bytes (Bevy writes its uniforms
/// with `encase`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable, ShaderType)]
pub struct MapParams {
    /// Tile width and height in shell depths (the metric of
    /// `displace_core::convention`, Donnelly's "normalization factor", 8.5.2).
    pub aspect: Vec2,
    /// How many tiles the face spans; `[1, 1]` for a clamped map.
    pub tiles: Vec2,
    /// Distance map size in voxels `W, H, D` (section 8.4).
    pub dist_size: UVec3,
    /// Addressing across the face ([`address_code`]).
    pub address: u32,
    /// Height map size in texels, for the exact walk's cells.
    pub height_size: UVec2,
    /// Early-out threshold of sphere tracing in shell depths
    /// ([`TAU_VOXELS`] of the smallest voxel side).
    pub tau: f32,
    /// Length of the exact walk after the early out: [`BAND_FACTOR`] times the
    /// map's underestimate, plus `tau`.
    pub band: f32,
    /// Filtered textures store `(value - offset) / scale`: the scale.
    pub decode_scale: f32,
    /// The offset of that encoding.
    pub decode_offset: f32,
    /// Most cells the exact walk visits ([`cell_cap`]).
    pub max_cells: u32,
    /// Trace method ([`method_code`]).
    pub method: u32,
    /// Most sphere-tracing steps.
    pub iterations: u32,
    /// Ray parameter where the query starts.
    pub t_min: f32,
    /// Ray parameter where it ends (a shadow ray stops at its light).
    pub t_max: f32,
    /// Pads the struct to WGSL's 16-byte uniform alignment.
    pub pad_end: u32,
}

/// How the values a shader fetches from a distance texture decode to shell
/// depths, and how far below the true distance they may lie.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decode {
    /// Depth units per unit of the fetched value.
    pub scale: f32,
    /// Depth units a fetch of 0 stands for; for filtered formats with the
    /// worst overestimate of a fixed-point filter already taken off
    /// (`displace_core::DistanceMap::filtered_texels`).
    pub offset: f32,
    /// Bound on how far the decoded values lie below the true distance,
    /// filter included: it sets the width of the exact walk after the
    /// early out.
    pub underestimate: f32,
}

impl MapParams {
    /// The parameters of a map that hold for every trace: its proportions
    /// (`aspect`, shell depths), the distance map's voxels and their size
    /// in map units (`voxel`), the addressing, the height map's texels and
    /// how the distance texture decodes. One tile; no trace options yet
    /// ([`Self::with_trace`]).
    pub fn for_map(
        aspect: [f32; 2],
        dist_size: [usize; 3],
        voxel: Vec3,
        address: Address,
        height_size: [usize; 2],
        decode: &Decode,
    ) -> Self {
        let tau = TAU_VOXELS * voxel.min_element();
        let [w, h, d] = dist_size;
        let [hw, hh] = height_size;
        MapParams {
            aspect: Vec2::from(aspect),
            tiles: Vec2::ONE,
            dist_size: UVec3::new(w as u32, h as u32, d as u32),
            address: address_code(address),
            height_size: UVec2::new(hw as u32, hh as u32),
            tau,
            band: BAND_FACTOR * decode.underestimate + tau,
            decode_scale: decode.scale,
            decode_offset: decode.offset,
            ..MapParams::default()
        }
    }

    /// These parameters with one trace's options: tiles, method, steps and
    /// the ray's interval (clamped to [`BIG`], WGSL having no infinity),
    /// and the cell cap for those tiles. The options are checked by the
    /// caller (`displace_core::DisplacementMap::check_trace` on the CPU).
    pub fn with_trace(self, opts: &TraceOptions) -> Self {
        MapParams {
            tiles: Vec2::from(opts.tiles),
            method: method_code(opts.method),
            iterations: opts.iterations,
            t_min: opts.t_min.clamp(-BIG, BIG),
            t_max: opts.t_max.clamp(-BIG, BIG),
            max_cells: cell_cap(self.height_size, opts.tiles),
            ..self
        }
    }
}

/// Most cells the exact walk may visit on a face of `tiles` tiles of a
/// `height_size` height map: a walk inside the shell crosses at most one
/// cell per texel column and row of the face, plus the half cells at its
/// borders. A guard against runaway loops that a ray inside the shell
/// never reaches.
pub fn cell_cap(height_size: UVec2, tiles: [f32; 2]) -> u32 {
    let cells = 2.0
        * (height_size.x as f64 * tiles[0] as f64 + height_size.y as f64 * tiles[1] as f64)
        + 64.0;
    cells.min(u32::MAX as f64) as u32
}
