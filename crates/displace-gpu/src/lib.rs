//! # displace-gpu
//!
//! Distance mapping on the GPU with `wgpu` and WGSL (Donnelly, GPU Gems 2
//! ch. 8): a headless device ([`GpuContext`]), the distance and height maps
//! as textures ([`GpuMap`]), and a compute-shader batch ray query
//! ([`trace_rays`]) that runs the same map-space trace as the CPU
//! (`displace_core::sphere_trace`), so either backend answers the same
//! question with the same conventions (`shaders/convention.wgsl`); the
//! raster path of section 8.5 ([`Renderer`]: listing 8-1's vertex stage,
//! listing 8-2's fragment stage with exact refinement, normal-mapped
//! shading, self-shadowing); the techniques engines ship, beside distance
//! mapping, run on batches of rays ([`TechniqueTracer`]: parallax, POM,
//! relief, cone stepping and maximum mipmaps, measured against the exact hit);
//! GPU-timed benchmarks (`bench`, with the feature of that name); a `displace_render` scene as
//! draws of the raster path ([`scene_draws`]: the CPU's scene description
//! is the GPU's too); and the interactive viewer ([`view`]).

#![warn(missing_docs)]

mod batch;
#[cfg(feature = "bench")]
pub mod bench;
pub mod context;
pub mod convention;
pub mod curved;
mod descriptors;
pub mod error;
pub mod gpu_map;
pub mod mesh;
pub mod plain;
pub mod raster;
pub mod scene_draws;
pub mod shaders;
pub mod technique_maps;
pub mod techniques;
#[cfg(feature = "test-support")]
pub mod test_support;
pub mod timing;
pub mod trace;
pub mod view;

pub use context::GpuContext;
pub use curved::CurvedShells;
pub use error::Error;
pub use gpu_map::{GpuMap, MapParams};
pub use mesh::{MeshTriangle, ShellMesh};
pub use plain::{PlainMaterial, PlainMesh};
pub use raster::{Draw, DrawShape, Face, Image, PlaneScene, Renderer, Shadows, View};
pub use scene_draws::{from_scene, SceneDraws};
pub use shaders::DistanceTexture;
pub use techniques::{technique_costs, TechniqueCost, TechniqueTracer};
pub use trace::{trace_rays, GpuHit, GpuTraceOptions, RayTracer};

/// Result type of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
