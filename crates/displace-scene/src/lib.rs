//! # displace-scene
//!
//! The scene as every renderer of `displace` reads it, free of any
//! renderer: the error type scenes report with, the geometry of the shapes
//! (quads, triangles, spheres, meshes, the built-in meshes and their vertex
//! normals), the curved shells of displaced meshes and which triangles
//! continue each other, materials, lights, the camera, the environment and
//! textures, the render settings, the per-sample hashes, the bake cache
//! shared between runs, and the scene file itself: parsed, checked (every
//! error at its file, line and column) and placed in the world
//! ([`World`]). As pbrt-v4's `BasicScene` feeds both its CPU
//! aggregate and its wavefront GPU renderer, this crate feeds
//! `displace-render`'s primitives and BVH and `displace-gpu`'s draws.

#![warn(missing_docs)]

pub mod animation;
pub mod bake_cache;
pub mod bake_lock;
mod build;
pub mod builtin_mesh;
pub mod camera;
mod content;
pub mod curved_shell;
pub mod distribution;
pub mod environment;
pub mod error;
pub mod geometry;
mod heights;
pub mod light;
mod locate;
pub mod material;
pub mod mesh;
pub mod mesh_shells;
pub mod placed;
pub mod sampler;
pub mod settings;
pub mod shapes;
pub mod spec;
pub mod texture;
pub mod vertex_normals;
pub mod world;

pub use bake_cache::{default_cache_dir, CacheStats};
pub use build::{
    MAX_COORDINATE, MAX_DEPTH, MAX_RADIANCE, MAX_SAMPLES, MAX_SHADOW_SAMPLES, MAX_SPP,
};
pub use error::{Error, Result};
pub use world::{RenderSettings, SceneOptions, World, DEFAULT_SCENE, DEFAULT_SCENE_NAME};
