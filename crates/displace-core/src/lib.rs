//! # displace-core
//!
//! Everything about a displaced surface that needs no scene and no GPU:
//! height maps and their generators, tangent-space normal maps, the
//! conservative 3D distance map (Donnelly, GPU Gems 2 ch. 8, section 8.4),
//! map-space ray tracing by sphere tracing that map (section 8.3) with exact
//! refinement, the exact reference intersector, and the file formats other
//! tools load (KTX2, DDS, npy).
//!
//! Conventions (map space, texel centres, units) live in [`convention`] and
//! nowhere else; the WGSL shaders read the same constants.
//!
//! ```
//! use displace_core::{bake, Address, BakeOptions, Extent, generators, Method, MapRay, TraceOptions};
//! use glam::Vec3;
//!
//! let height = generators::generate("gen:gaussian", 64, 64, Address::Clamp).unwrap();
//! let map = bake(&height, &BakeOptions {
//!     size: [32, 32, 8],
//!     extent: Extent::new(1.0, 1.0, 0.25).unwrap(),
//!     ..BakeOptions::default()
//! }).unwrap();
//! // A ray straight down onto the centre of the face, in map space (depth units).
//! let ray = MapRay::new(Vec3::new(2.0, 2.0, 1.5), Vec3::new(0.0, 0.0, -1.0));
//! let hit = map.trace(&ray, &TraceOptions::default()).expect("hit");
//! assert!((hit.position.z - 1.0).abs() < 1e-2); // the gaussian peaks at full height
//! ```

#![warn(missing_docs)]

pub mod cell_trace;
pub mod convention;
pub mod distance_map;
pub mod edt;
pub mod error;
pub mod exact;
pub mod generators;
pub mod heightmap;
pub mod horizon;
pub mod io;
pub mod memory;
pub mod names;
pub mod normal_map;
pub mod physical;
pub mod random;
pub mod sphere_trace;
pub mod techniques;

pub mod bake;
mod displacement_map;

pub use bake::{
    bake, bake_distance, bake_streamed, BakeLayout, BakeOptions, CodedSlab, Slab, SlabSink,
};
pub use convention::{Address, Extent};
pub use displacement_map::{check_iterations, DisplacementMap};
pub use distance_map::DistanceMap;
pub use error::Error;
pub use heightmap::HeightMap;
pub use normal_map::NormalMap;
pub use sphere_trace::{MapHit, MapRay, Method, TraceOptions};

/// Result type of this crate.
pub type Result<T, E = Error> = std::result::Result<T, E>;
