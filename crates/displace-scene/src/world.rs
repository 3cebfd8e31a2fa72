//! A scene file read, checked and placed in the world, for any renderer:
//! the film and camera, the render settings, materials, lights, the shapes
//! as placed ([`crate::placed`]) and the bakes they trace. Parsed from TOML
//! ([`crate::spec`]), at one frame of its animation
//! ([`crate::animation`]), built by one constructor per part of the file
//! (`build`); every error names the file, the key and its line and column
//! ([`crate::locate`]).

use crate::bake_cache::CacheStats;
use crate::camera::Camera;
use crate::environment::Environment;
use crate::error::{line_column, Error, Result};
use crate::light::Light;
use crate::material::Material;
use crate::placed::{PlacedShape, SceneMesh, TriAttr};
use crate::sampler::SamplerKind;
use crate::settings::{Integrator, Sampling};
use crate::{animation, build, content, locate, spec};
use displace_core::Method;
use glam::Vec3;
use std::path::{Path, PathBuf};

/// The built-in default scene: the studded Cornell box, path-traced (384 x
/// 384 at 80 samples, a few seconds on two cores), its text kept with the
/// crate so that the crate stands on its own.
pub const DEFAULT_SCENE: &str = include_str!("default_scene.toml");
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
    /// The caller makes no image of the scene (`trace --scene`,
    /// `export-mesh --scene`): the image's film is left out of the memory
    /// estimate, which it would otherwise refuse a scene over; the image's
    /// size and samples are still checked, as the scene must stay valid.
    pub no_image: bool,
    /// Raised to stop loading (Ctrl-C, SIGTERM): a bake in progress and a
    /// wait for another process's bake end with [`crate::Error::Cancelled`].
    pub cancel: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

/// How the scene asks to be rendered (`[image]` and the command line's
/// overrides), apart from what it holds: the light transport, the sampler,
/// the samples and the bounces.
#[derive(Clone, Copy, Debug)]
pub struct RenderSettings {
    /// The light transport algorithm.
    pub integrator: Integrator,
    /// The path integrator's estimators of direct light.
    pub sampling: Sampling,
    /// Where the path integrator's numbers come from (`image.sampler`).
    pub sampler: SamplerKind,
    /// Samples per pixel.
    pub spp: u32,
    /// The seed of every pixel sample's numbers.
    pub seed: u64,
    /// Bounce limit (`image.max_depth`).
    pub max_depth: u32,
    /// Shadow rays per area light and shading point (Whitted).
    pub shadow_samples: u32,
}

/// A scene placed in the world: what every renderer builds from (module
/// docs). Plain data; the CPU renderer turns it into primitives under a
/// BVH, the GPU's raster path into draws.
pub struct World {
    /// The camera.
    pub camera: Camera,
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// How it asks to be rendered.
    pub settings: RenderSettings,
    /// Linear RGB radiance of escaping rays when there is no environment map.
    pub background: Vec3,
    /// What escaping rays see: `Constant(background)` or the map.
    pub environment: Environment,
    /// The materials, indexed by [`PlacedShape::material`].
    pub materials: Vec<Material>,
    /// The lights, in file order.
    pub lights: Vec<Light>,
    /// Which of [`Self::lights`] are fill lights (lighting the Whitted
    /// integrator's shading only, left out of the path tracer's).
    pub fill: Vec<bool>,
    /// Every shape placed in the world, in file order.
    pub shapes: Vec<PlacedShape>,
    /// Per-triangle attributes of meshes and textured triangles.
    pub attrs: Vec<TriAttr>,
    /// The scene's meshes and triangles as placed in the world, with their
    /// vertex data ([`SceneMesh`]): what a rasteriser draws of them.
    pub meshes: Vec<SceneMesh>,
    /// What the bake cache did while building.
    pub cache_stats: CacheStats,
    /// The files the scene read besides the scene file itself (height maps,
    /// textures, meshes), as resolved against the scene's directory.
    pub sources: Vec<PathBuf>,
    /// A hash of everything the image depends on: the scene text, the bytes
    /// of every file it reads, and the overrides it was built with. Tiles of
    /// one render carry it, so that a merge can refuse tiles of another.
    pub content_hash: u64,
    /// Problems met while building that did not stop it (a bake cache that
    /// could not be written, so bakes were kept in memory), for the caller
    /// to show.
    pub warnings: Vec<String>,
}

impl World {
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
        let mut world = build::build(spec, name, base, opts).map_err(at)?;
        world.content_hash = content::content_hash(text, &world.sources, opts)?;
        Ok(world)
    }
}

/// The scene file at `path` as text, held to the scene file limits.
fn read_text(path: &Path) -> Result<String> {
    use displace_core::io::{check_input, MAX_SCENE_FILE_BYTES};
    check_input(path, "scene file", MAX_SCENE_FILE_BYTES)?;
    let bytes = std::fs::read(path).map_err(|e| displace_core::Error::io(path, e))?;
    let text = String::from_utf8(bytes).map_err(|e| {
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
    })?;
    // A byte-order mark (editors on Windows write one) is not TOML: the
    // scene is what follows it.
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// The scene file's TOML, parsed (not yet checked). An error the parser
/// gives no place for (its key-depth limit) is placed at the deepest key;
/// one that cannot be placed is reported without a place rather than at
/// a line 0 that does not exist.
fn parse(text: &str, name: &Path) -> Result<spec::SceneSpec> {
    toml::from_str(text).map_err(|e| {
        let message = e.message().trim().to_string();
        let at = match e.span() {
            Some(s) => Some(line_column(text, s.start)),
            None if message.contains("recursion") => deepest_key(text),
            None => None,
        };
        match at {
            Some((line, column)) => Error::Parse {
                path: name.to_path_buf(),
                line,
                column,
                message,
            },
            None => Error::Scene {
                path: name.to_path_buf(),
                at: None,
                message: format!("not a TOML scene: {message}"),
            },
        }
    })
}

/// Line and column of the first key (a table header's or before a `=`)
/// with the most dotted parts in `text`, when one has more than one.
fn deepest_key(text: &str) -> Option<(usize, usize)> {
    let mut best: Option<(usize, (usize, usize))> = None;
    for (n, line) in text.lines().enumerate() {
        let trimmed = line.trim_start();
        let key = if trimmed.starts_with('[') {
            trimmed.trim_start_matches('[').split(']').next()
        } else {
            trimmed.split_once('=').map(|(k, _)| k)
        };
        let Some(key) = key else { continue };
        let parts = key.split('.').count();
        if parts > 1 && best.is_none_or(|(p, _)| parts > p) {
            let column = line[..line.len() - trimmed.len()].chars().count() + 1;
            best = Some((parts, (n + 1, column)));
        }
    }
    best.map(|(_, at)| at)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A key nested past the parser's limit used to be reported at
    /// `file:0:0`; it is placed at its line, and the parser's own spanned
    /// errors keep their places.
    #[test]
    fn errors_without_a_span_are_placed_at_the_deepest_key() {
        let deep = format!("[image]\nwidth = 8\n  [{}]\n", vec!["a"; 300].join("."));
        let e = parse(&deep, Path::new("s.toml")).err().unwrap().to_string();
        assert!(e.starts_with("s.toml:3:3: "), "{e}");
        assert!(e.contains("recursion"), "{e}");
        let e = parse("[image]\nwidth = = 8\n", Path::new("s.toml"))
            .err()
            .unwrap()
            .to_string();
        assert!(e.starts_with("s.toml:2:"), "{e}");
        assert_eq!(deepest_key("a = 1\nb = 2\n"), None);
    }
}
