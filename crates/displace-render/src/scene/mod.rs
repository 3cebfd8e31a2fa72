//! Scenes for the CPU renderer: the scene as placed in the world
//! ([`displace_scene::World`], read, checked and built from its TOML file
//! there) turned into primitives under one BVH, with the path tracer's
//! emitters (`build`), and the queries the integrators ask of them
//! (`world`).

pub mod batch;
mod build;
pub mod queries;
pub(crate) mod world;

pub use displace_scene::placed::{MeshDisplacement, SceneMesh, TriAttr};
pub use displace_scene::{animation, spec};
pub use displace_scene::{SceneOptions, World, DEFAULT_SCENE, DEFAULT_SCENE_NAME};
pub use displace_scene::{
    MAX_COORDINATE, MAX_DEPTH, MAX_RADIANCE, MAX_SAMPLES, MAX_SHADOW_SAMPLES, MAX_SPP,
};
pub use world::{Interaction, Primitive, Shape};

use crate::bake_cache::CacheStats;
use crate::bvh::Bvh;
use crate::camera::Camera;
use crate::environment::Environment;
use crate::error::Result;
use crate::light::Light;
use crate::material::Material;
use crate::settings::{Integrator, Sampling};
use crate::shading::emitters::Emitters;
use crate::shading::sampler::SamplerKind;
use glam::Vec3;
use std::path::{Path, PathBuf};

/// A built scene: primitives under one BVH, materials, lights, camera and
/// environment, ready for [`crate::render()`].
pub struct Scene {
    pub(crate) camera: Camera,
    pub(crate) width: u32,
    pub(crate) height: u32,
    pub(crate) spp: u32,
    pub(crate) max_depth: u32,
    pub(crate) seed: u64,
    pub(crate) shadow_samples: u32,
    pub(crate) background: Vec3,
    /// What escaping rays see: `Constant(background)` or the map.
    pub(crate) environment: Environment,
    pub(crate) integrator: Integrator,
    pub(crate) sampling: Sampling,
    /// Where the path integrator's numbers come from.
    pub(crate) sampler: SamplerKind,
    /// The path integrator's lights.
    pub(crate) emitters: Emitters,
    pub(crate) prims: Vec<Primitive>,
    pub(crate) attrs: Vec<TriAttr>,
    pub(crate) bvh: Bvh,
    pub(crate) materials: Vec<Material>,
    pub(crate) lights: Vec<Light>,
    /// Offset of secondary-ray origins off a surface, world units.
    pub(crate) epsilon: f32,
    pub(crate) meshes: Vec<SceneMesh>,
    cache_stats: CacheStats,
    /// The files the scene read besides itself (for [`Scene::content_hash`]).
    sources: Vec<PathBuf>,
    content_hash: u64,
    /// What went wrong without stopping the build (the bake cache).
    warnings: Vec<String>,
}

impl Scene {
    /// Reads and builds the scene file at `path`; relative paths inside it
    /// are relative to its directory.
    pub fn load(path: &Path, opts: &SceneOptions) -> Result<Self> {
        World::load(path, opts).map(build::build)
    }

    /// The frame count of the `[animation]` of the scene at `path`
    /// ([`World::animation_frames`]).
    pub fn animation_frames(path: Option<&Path>) -> Result<Option<u32>> {
        World::animation_frames(path)
    }

    /// The built-in default scene.
    pub fn default_scene(opts: &SceneOptions) -> Result<Self> {
        World::default_scene(opts).map(build::build)
    }

    /// Builds a scene from TOML `text`; `name` is used in messages, `base`
    /// resolves relative file names.
    pub fn from_toml(text: &str, name: &Path, base: &Path, opts: &SceneOptions) -> Result<Self> {
        World::from_toml(text, name, base, opts).map(build::build)
    }

    /// Image width in pixels.
    pub fn width(&self) -> u32 {
        self.width
    }
    /// Image height in pixels.
    pub fn height(&self) -> u32 {
        self.height
    }
    /// Samples per pixel.
    pub fn spp(&self) -> u32 {
        self.spp
    }
    /// Shadow rays per area light and sample (Whitted's soft shadows).
    pub fn shadow_samples(&self) -> u32 {
        self.shadow_samples
    }
    /// Number of primitives (a mesh counts its triangles).
    pub fn primitive_count(&self) -> usize {
        self.prims.len()
    }
    /// What the bake cache did while building.
    pub fn cache_stats(&self) -> CacheStats {
        self.cache_stats
    }
    /// A hash of everything the image depends on: the scene text, the bytes
    /// of every file it reads, and the overrides it was built with. Tiles of
    /// one render carry it, so that a merge can refuse tiles of another.
    pub fn content_hash(&self) -> u64 {
        self.content_hash
    }
    /// Problems met while building that did not stop it (a bake cache that
    /// could not be written, so bakes were kept in memory), for the caller
    /// to show.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }
    /// The files the scene read besides the scene file itself (height maps,
    /// textures, meshes), as resolved against the scene's directory.
    pub fn sources(&self) -> &[PathBuf] {
        &self.sources
    }
    /// The built primitives, for other renderers of the same scene (the GPU
    /// path of `displace gpu-render`).
    pub fn primitives(&self) -> &[Primitive] {
        &self.prims
    }
    /// The materials, indexed by [`Primitive::material`].
    pub fn materials(&self) -> &[Material] {
        &self.materials
    }
    /// The lights of the Whitted integrator.
    pub fn lights(&self) -> &[Light] {
        &self.lights
    }
    /// The camera.
    pub fn camera(&self) -> &Camera {
        &self.camera
    }
    /// Linear RGB radiance of escaping rays when there is no environment map.
    pub fn background(&self) -> Vec3 {
        self.background
    }
    /// What escaping rays see (the constant background or the map).
    pub fn environment(&self) -> &Environment {
        &self.environment
    }
    /// The light transport algorithm [`crate::render()`] runs.
    pub fn integrator(&self) -> Integrator {
        self.integrator
    }
    /// The path integrator's estimators of direct light.
    pub fn sampling(&self) -> Sampling {
        self.sampling
    }
    /// Where the path integrator's numbers come from (`image.sampler`).
    pub fn sampler(&self) -> SamplerKind {
        self.sampler
    }
    /// Bounce limit (`image.max_depth`).
    pub fn max_depth(&self) -> u32 {
        self.max_depth
    }
    /// The scene's meshes and triangles as placed in the world, with their
    /// vertex data ([`SceneMesh`]): what a rasteriser draws of them.
    pub fn meshes(&self) -> &[SceneMesh] {
        &self.meshes
    }
}
