//! # displace-shaders
//!
//! The GPU side of distance mapping (Donnelly, GPU Gems 2 ch. 8) as a
//! library free of any graphics API: the WGSL modules with their naga_oil
//! import paths ([`wgsl`]), the codes and tolerances the shaders share with
//! Rust ([`codes`]), and the uniform every trace reads with the computation
//! of its values from a baked map ([`MapParams`]), and the storage layout
//! of a curved mesh's shells ([`curved_prisms`]).
//!
//! displace-gpu composes these modules into its wgpu pipelines;
//! displace-bevy registers the shared ones with Bevy's shader cache, as
//! bevy_pbr registers its own, and uploads the same `MapParams` through
//! Bevy's `encase`. One source, so the plugin and `displace gpu-render`
//! run the one trace with the one set of parameters.

#![warn(missing_docs)]

pub mod codes;
pub mod curved_prisms;
pub mod map_params;
pub mod wgsl;

pub use codes::*;
pub use map_params::{cell_cap, Decode, MapParams};
