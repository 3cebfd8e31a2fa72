//! # displace-render
//!
//! A CPU ray tracer after the distance-map ray-tracer paper
//! (`docs/architecture.md`, "References"): Whitted ray tracing with the
//! distributed soft shadows and glossy reflections of Cook, Porter and
//! Carpenter (1984), whose intersection routine knows displaced faces. A
//! displaced quad or triangle is a shell (that paper's section 2.4, the
//! extruded bounding box): a ray that meets it is carried into the face's
//! map space and sphere traced through the conservative
//! distance map of `displace-core`, so shadows and reflections on and of
//! displaced surfaces come for free.
//!
//! Modules, one job each (after pbrt-v4's layout): [`scene`] (TOML, checks,
//! construction), [`camera`], [`shapes`], [`displaced`],
//! [`displaced_surface`] (a displaced mesh tessellated: the curved
//! surface's ground truth), [`bvh`],
//! [`material`], [`light`], [`sampler`], [`integrator`] (Whitted), [`path`]
//! (path tracing with MIS) with [`bsdf`], [`emitters`], [`environment`] and
//! [`distribution`], [`render`](mod@render) (tiles,
//! threads, crops, AOVs), [`probe`] (ray sets for benchmarks), [`output`]
//! (PNG/EXR/npy, atomic), [`bake_cache`].
//!
//! ```no_run
//! use displace_render::{render, RenderOptions, Scene, SceneOptions};
//! let scene = Scene::default_scene(&SceneOptions::default()).unwrap();
//! let out = render(&scene, &RenderOptions::default()).unwrap();
//! displace_render::output::write_image(std::path::Path::new("out.png"), &out.image).unwrap();
//! ```

#![warn(missing_docs)]

pub mod bake_cache;
pub mod bake_lock;
pub mod bsdf;
pub mod builtin_mesh;
pub mod bvh;
pub mod camera;
pub mod curved_face;
pub mod curved_shell;
pub mod displaced;
pub mod displaced_surface;
pub mod distribution;
pub mod emitters;
pub mod environment;
pub mod error;
pub mod geometry;
mod heights;
pub mod integrator;
pub mod light;
pub mod material;
pub mod merge;
pub mod mesh;
pub mod mesh_shells;
pub mod output;
pub mod path;
pub mod probe;
pub mod render;
pub mod sampler;
pub mod scene;
pub mod settings;
pub mod shapes;
pub mod sobol;
pub mod texture;
pub mod tile_file;
pub mod tiling;
pub mod vertex_normals;

pub use bake_cache::{default_cache_dir, CacheStats};
pub use error::{Error, Result};
pub use render::{render, Aov, AovImage, Crop, Image, RenderOptions, Rendered};
pub use sampler::SamplerKind;
pub use scene::{Scene, SceneOptions};
pub use settings::{Integrator, Sampling};
