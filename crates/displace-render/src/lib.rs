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
//! Modules by interface, one job each (after pbrt-v4's layout): [`scene`]
//! (the CPU scene built from the renderer-neutral `displace_scene::World`,
//! and the batch queries of `trace --scene`), [`bvh`], [`faces`] (the
//! displaced faces traced in map space, flat and curved, and their
//! tessellated ground truth), [`shading`] (BSDFs, emitters, samplers),
//! [`integrators`] (Whitted, and path tracing with MIS), [`camera_sample`]
//! (each sample's camera ray), [`render`](mod@render) (tiles, threads,
//! crops, AOVs) and [`film`] (image files, farm tiles and their merge).
//! The scene description's own modules (camera, shapes, materials, lights,
//! meshes, the bake cache) are `displace_scene`'s, re-exported here under
//! their names.
//!
//! ```no_run
//! use displace_render::{render, RenderOptions, Scene, SceneOptions};
//! let scene = Scene::default_scene(&SceneOptions::default()).unwrap();
//! let out = render(&scene, &RenderOptions::default()).unwrap();
//! displace_render::film::output::write_image(std::path::Path::new("out.png"), &out.image).unwrap();
//! ```

#![warn(missing_docs)]

pub use displace_scene::bake_cache;
pub use displace_scene::bake_lock;
pub use displace_scene::builtin_mesh;
pub mod bvh;
pub use displace_scene::camera;
pub mod camera_sample;
pub use displace_scene::curved_shell;
pub use displace_scene::distribution;
pub use displace_scene::environment;
pub use displace_scene::error;
pub mod faces;
pub mod film;
pub use displace_scene::geometry;
pub mod integrators;
pub use displace_scene::light;
pub use displace_scene::material;
pub use displace_scene::mesh;
pub use displace_scene::mesh_shells;
pub mod render;
pub mod scene;
pub use displace_scene::settings;
pub use displace_scene::shapes;
pub mod shading;
pub use displace_scene::texture;
pub use displace_scene::vertex_normals;

pub use bake_cache::{default_cache_dir, CacheStats};
pub use error::{Error, Result};
pub use render::{render, Aov, AovImage, Crop, Image, RenderOptions, Rendered};
pub use scene::{Scene, SceneOptions};
pub use settings::{Integrator, Sampling};
pub use shading::sampler::SamplerKind;
