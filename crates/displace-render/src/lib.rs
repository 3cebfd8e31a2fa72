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
//! [`material`], [`light`], [`sampler`], [`integrators`] (Whitted, and
//! path tracing with MIS) with [`bsdf`], [`emitters`], [`environment`] and
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

pub use displace_scene::bake_cache;
pub use displace_scene::bake_lock;
pub mod bsdf;
pub use displace_scene::builtin_mesh;
pub mod bvh;
pub use displace_scene::camera;
mod camera_sample;
pub mod curved_face;
pub use displace_scene::curved_shell;
pub mod displaced;
pub mod displaced_surface;
pub use displace_scene::distribution;
pub mod emitters;
pub use displace_scene::environment;
pub use displace_scene::error;
pub use displace_scene::geometry;
pub mod integrators;
pub use displace_scene::light;
pub use displace_scene::material;
pub mod merge;
pub use displace_scene::mesh;
pub use displace_scene::mesh_shells;
pub mod output;
pub mod probe;
pub mod render;
pub mod sampler;
pub mod scene;
pub use displace_scene::settings;
pub use displace_scene::shapes;
pub mod sobol;
pub use displace_scene::texture;
pub mod tile_file;
pub mod tiling;
pub use displace_scene::vertex_normals;

pub use bake_cache::{default_cache_dir, CacheStats};
pub use error::{Error, Result};
pub use render::{render, Aov, AovImage, Crop, Image, RenderOptions, Rendered};
pub use sampler::SamplerKind;
pub use scene::{Scene, SceneOptions};
pub use settings::{Integrator, Sampling};
