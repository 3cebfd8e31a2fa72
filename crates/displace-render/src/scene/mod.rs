//! Scenes: parsed from TOML ([`spec`]), validated and built (`build`) into
//! primitives under one BVH, with materials, lights and a camera.

pub mod animation;
pub mod batch;
mod build;
mod content;
mod locate;
pub mod spec;
pub(crate) mod world;

pub use build::{MAX_COORDINATE, MAX_DEPTH, MAX_SAMPLES, MAX_SHADOW_SAMPLES, MAX_SPP};
pub use world::{Interaction, MeshDisplacement, Primitive, SceneMesh, Shape, TriAttr};

use crate::bake_cache::CacheStats;
use crate::bvh::Bvh;
use crate::camera::Camera;
use crate::emitters::Emitters;
use crate::environment::Environment;
use crate::error::{line_column, Error, Result};
use crate::light::Light;
use crate::material::Material;
use crate::sampler::SamplerKind;
use crate::settings::{Integrator, Sampling};
use displace_core::Method;
use glam::Vec3;
use std::path::{Path, PathBuf};

/// The built-in default scene: the studded Cornell box with soft shadows.
pub const DEFAULT_SCENE: &str = include_str!("../../../../scenes/cornell_studded_shadows.toml");
/// The name errors give the built-in scene, which has no file.
pub const DEFAULT_SCENE_NAME: &str = "<built-in default scene>";

/// What a caller may change about a scene without editing its file.
#[derive(Clone, Debug, Default)]
pub struct SceneOptions {
    /// Overrides `image.spp` (`--spp`).
    pub spp: Option<u32>,
    /// Overrides `image.width` and `image.height` (`--size`).
    pub size: Option<[u32; 2]>,
    /// Overrides every displaced face's tracing method (tests compare
    /// sphere tracing with the exact reference this way).
    pub method: Option<Method>,
    /// Where bakes are cached on disk; `None` keeps them in memory only.
    pub cache_dir: Option<PathBuf>,
    /// The frame of an `[animation]` to build (`None`: frame 0).
    pub frame: Option<u32>,
    /// Overrides `image.integrator` (`--integrator`).
    pub integrator: Option<Integrator>,
    /// Overrides `image.sampler` (`--sampler`).
    pub sampler: Option<SamplerKind>,
}

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
        let text = read_text(path)?;
        let base = path.parent().unwrap_or(Path::new("."));
        Self::from_toml(&text, path, base, opts)
    }

    /// The frame count of the `[animation]` of the scene at `path` (the
    /// built-in scene without one), checked, without building the scene:
    /// `--frames` is checked against it before any frame is rendered.
    pub fn animation_frames(path: Option<&Path>) -> Result<Option<u32>> {
        let (text, name) = match path {
            Some(p) => (read_text(p)?, p),
            None => (DEFAULT_SCENE.to_string(), Path::new(DEFAULT_SCENE_NAME)),
        };
        animation::frame_count(&parse(&text, name)?, name).map_err(|e| locate::located(e, &text))
    }

    /// The built-in default scene.
    pub fn default_scene(opts: &SceneOptions) -> Result<Self> {
        Self::from_toml(
            DEFAULT_SCENE,
            Path::new(DEFAULT_SCENE_NAME),
            Path::new("."),
            opts,
        )
    }

    /// Builds a scene from TOML `text`; `name` is used in messages, `base`
    /// resolves relative file names.
    pub fn from_toml(text: &str, name: &Path, base: &Path, opts: &SceneOptions) -> Result<Self> {
        let spec = parse(text, name)?;
        let at = |e| locate::located(e, text);
        let spec = animation::at_frame(spec, opts.frame, name).map_err(at)?;
        let mut scene = build::build(spec, name, base, opts).map_err(at)?;
        scene.content_hash = content::content_hash(text, &scene.sources, opts)?;
        Ok(scene)
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

/// The scene file at `path` as text, held to the scene file limits.
fn read_text(path: &Path) -> Result<String> {
    use displace_core::io::{check_input, MAX_SCENE_FILE_BYTES};
    check_input(path, "scene file", MAX_SCENE_FILE_BYTES)?;
    let bytes = std::fs::read(path).map_err(|source| Error::Io {
        path: path.to_path_buf(),
        source,
    })?;
    String::from_utf8(bytes).map_err(|e| {
        // Where the bad byte is, as for a TOML error.
        let good = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        let good = std::str::from_utf8(good).unwrap_or_default();
        let (line, column) = line_column(good, good.len());
        Error::Parse {
            path: path.to_path_buf(),
            line,
            column,
            message: "invalid UTF-8: a scene file is UTF-8 text".into(),
        }
    })
}

/// The scene file's TOML, parsed (not yet checked).
fn parse(text: &str, name: &Path) -> Result<spec::SceneSpec> {
    toml::from_str(text).map_err(|e| {
        let (line, column) = e.span().map_or((0, 0), |s| line_column(text, s.start));
        Error::Parse {
            path: name.to_path_buf(),
            line,
            column,
            message: e.message().trim().to_string(),
        }
    })
}
