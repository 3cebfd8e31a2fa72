//! What every constructor of a scene shares while it builds: the scene's
//! name and directory for errors and relative paths, the bake cache and
//! the loaded height maps and textures (each input read once), the memory
//! estimate and the list of files read, and the checks every key goes
//! through (finite, in range, non-negative colours).

use super::super::spec::V3;
use super::super::SceneOptions;
use crate::bake_cache::BakeCache;
use crate::error::{Error, Result};
use crate::texture::Texture;
use displace_core::{Address, HeightMap, Method};
use glam::Vec3;
use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Largest magnitude of a coordinate or vector component in a scene. Past
/// it a squared length overflows float32, and a camera at `-3e38` would be
/// reported as looking nowhere instead of as out of range.
pub const MAX_COORDINATE: f32 = 1e18;

/// Most light a scene key may give off (emission, radiance, intensity,
/// background), per component. A sample is at most that light times
/// reflectances of at most 1 and the geometry of one light sample, and a
/// pixel the mean of at most 2^16 samples: 1e15 keeps those sums more than
/// twenty orders of magnitude inside single precision's 3.4e38, while
/// lights thousands of times brighter than any scene of `scenes/` pass.
pub const MAX_RADIANCE: f32 = 1e15;

/// A loaded height map's source, generated size, addressing and height
/// range (as its `Debug` text: the range holds floats, which do not hash).
pub(super) type HeightKey = (String, [usize; 2], Address, String);

/// The state of one scene's build.
pub(super) struct Ctx<'a> {
    pub(super) name: &'a Path,
    pub(super) base: &'a Path,
    pub(super) cache: BakeCache,
    pub(super) heights: HashMap<HeightKey, Arc<HeightMap>>,
    pub(super) textures: HashMap<(PathBuf, bool), Arc<Texture>>,
    pub(super) method: Option<Method>,
    /// The bakes counted in `memory`: height source and map size.
    pub(super) planned: HashSet<(HeightKey, [usize; 3])>,
    /// Estimated bytes the scene holds: its image, its bakes' peaks, its
    /// textures and environment map, all together (each also passes the
    /// one-buffer check, but a scene of many can still exhaust the machine).
    pub(super) memory: u128,
    /// Every file the scene reads besides itself, for its content hash.
    pub(super) sources: Vec<PathBuf>,
}

impl<'a> Ctx<'a> {
    /// A fresh context for the scene `name`, its relative paths under
    /// `base`, bakes through `opts.cache_dir`.
    pub(super) fn new(name: &'a Path, base: &'a Path, opts: &SceneOptions) -> Self {
        Self {
            name,
            base,
            cache: BakeCache::new(opts.cache_dir.clone()).cancelled_by(opts.cancel.clone()),
            heights: HashMap::new(),
            textures: HashMap::new(),
            method: opts.method,
            planned: HashSet::new(),
            memory: 0,
            sources: Vec::new(),
        }
    }

    pub(super) fn err(&self, message: impl Into<String>) -> Error {
        Error::Scene {
            path: self.name.to_path_buf(),
            at: None,
            message: message.into(),
        }
    }

    pub(super) fn vec(&self, v: V3, what: &str) -> Result<Vec3> {
        if !v.iter().all(|c| c.is_finite()) {
            return Err(self.err(format!(
                "{what} = {v:?}: every component must be a finite number"
            )));
        }
        if v.iter().any(|c| c.abs() > MAX_COORDINATE) {
            return Err(self.err(format!(
                "{what} = {v:?}: components must be at most {MAX_COORDINATE:e} in magnitude (squared lengths must fit in float32)"
            )));
        }
        Ok(Vec3::from_array(v))
    }

    /// Light given off (emission, a light's radiance or intensity, the
    /// background): not negative, and at most [`MAX_RADIANCE`].
    pub(super) fn color(&self, v: V3, what: &str) -> Result<Vec3> {
        let c = self.vec(v, what)?;
        if c.min_element() < 0.0 {
            return Err(self.err(format!("{what} = {v:?}: colours cannot be negative")));
        }
        if c.max_element() > MAX_RADIANCE {
            return Err(self.err(format!(
                "{what} = {v:?}: at most {MAX_RADIANCE:e} (larger values overflow single \
                 precision in the sums of a pixel's samples)"
            )));
        }
        Ok(c)
    }

    /// A surface's reflectance (a material's colour, specular or diffuse
    /// part): each component in `[0, 1]`, since a surface reflects at most
    /// the light that reaches it. A larger one multiplies the light at
    /// every bounce: two facing mirrors of colour 1e18 reach infinity in
    /// three.
    pub(super) fn reflectance(&self, v: V3, what: &str) -> Result<Vec3> {
        let c = self.color(v, what)?;
        if c.max_element() > 1.0 {
            return Err(self.err(format!(
                "{what} = {v:?}: a reflectance is at most 1 in each component (a surface \
                 reflects at most the light that reaches it)"
            )));
        }
        Ok(c)
    }

    /// A whole number in `1..=u32::MAX` (a count), the bound named in the
    /// message as [`Self::bounded`] names its own.
    pub(super) fn positive(&self, v: i64, what: &str) -> Result<u32> {
        self.bounded(v, u32::MAX.into(), what)
    }

    /// A whole number in `1..=max` (`max` at most `u32::MAX`), the bound
    /// named in the message.
    pub(super) fn bounded(&self, v: i64, max: i64, what: &str) -> Result<u32> {
        if v <= 0 {
            return Err(self.err(format!("{what} must be a positive whole number, got {v}")));
        }
        let max = max.min(u32::MAX.into());
        if v > max {
            return Err(self.err(format!("{what} = {v} is more than the limit of {max}")));
        }
        Ok(v as u32)
    }

    /// Records a file the scene reads, once.
    pub(super) fn source(&mut self, path: PathBuf) {
        if !self.sources.contains(&path) {
            self.sources.push(path);
        }
    }

    /// Adds `bytes` for `what` to the scene's memory estimate and refuses
    /// the scene when the whole so far exceeds the limit
    /// ([`displace_core::memory::check`]): called before each large input
    /// is decoded or baked, so the input that tips the scene over is named
    /// and nothing of its size has been allocated.
    pub(super) fn reserve(&mut self, what: &str, bytes: u128) -> Result<()> {
        self.memory += bytes;
        displace_core::memory::check(
            &format!("{what} (with the scene's image, bakes and textures before it)"),
            self.memory,
        )
        .map_err(|e| self.err(e.to_string()))
    }

    /// The texture `file` that scene key `key` names, counted in the
    /// memory estimate before it is decoded (once per file, as it is
    /// loaded once); a failure to load it names the key as well as the
    /// file.
    pub(super) fn texture(&mut self, file: &str, srgb: bool, key: &str) -> Result<Arc<Texture>> {
        let path = self.base.join(file);
        if let Some(t) = self.textures.get(&(path.clone(), srgb)) {
            return Ok(t.clone());
        }
        self.source(path.clone());
        let t = Arc::new(self.image(
            key,
            file,
            ("texture", Texture::BYTES_PER_TEXEL),
            Texture::dimensions,
            |p| Texture::load(p, srgb),
        )?);
        self.textures.insert((path, srgb), t.clone());
        Ok(t)
    }

    /// Reads the image input `file` that scene key `key` names, of `kind`
    /// (a texture, an environment map) at `bytes_per_texel` held: its size
    /// from the header by `dimensions`, counted in the memory estimate,
    /// then decoded by `load`. A failure names the key as well as the file.
    pub(super) fn image<T>(
        &mut self,
        key: &str,
        file: &str,
        (kind, bytes_per_texel): (&str, u128),
        dimensions: fn(&Path) -> Result<[usize; 2]>,
        load: impl FnOnce(&Path) -> Result<T>,
    ) -> Result<T> {
        let path = self.base.join(file);
        let named = |e: Error| format!("{key} = \"{file}\": {e}");
        let [w, h] = dimensions(&path).map_err(|e| self.err(named(e)))?;
        self.reserve(
            &format!("{key} = \"{file}\": a {w}x{h} {kind}"),
            w as u128 * h as u128 * bytes_per_texel,
        )?;
        load(&path).map_err(|e| self.err(named(e)))
    }
}
