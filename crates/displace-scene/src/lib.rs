//! # displace-scene
//!
//! The scene as every renderer of `displace` reads it, free of any
//! renderer: the error type scenes report with, the geometry of the shapes
//! (quads, triangles, spheres, meshes, the built-in meshes and their vertex
//! normals), the curved shells of displaced meshes and which triangles
//! continue each other, materials, lights, the camera, the environment and
//! textures, the render settings, the per-sample hashes, and the bake cache
//! shared between runs. As pbrt-v4's `BasicScene` feeds both its CPU
//! aggregate and its wavefront GPU renderer, this crate feeds
//! `displace-render`'s primitives and BVH and `displace-gpu`'s draws.

#![warn(missing_docs)]

pub mod bake_cache;
pub mod bake_lock;
pub mod builtin_mesh;
pub mod camera;
pub mod curved_shell;
pub mod distribution;
pub mod environment;
pub mod error;
pub mod geometry;
pub mod light;
pub mod material;
pub mod mesh;
pub mod mesh_shells;
pub mod sampler;
pub mod settings;
pub mod shapes;
pub mod texture;
pub mod vertex_normals;

pub use bake_cache::{default_cache_dir, CacheStats};
pub use error::{Error, Result};
