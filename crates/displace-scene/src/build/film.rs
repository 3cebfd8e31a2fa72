//! `[image]` and `[camera]`: the film (size, samples, bounces, integrator,
//! what escaping rays see) and the camera, each key checked against its
//! limit before anything of its size is allocated.

use super::super::spec::{CameraSpec, ImageSpec};
use super::super::SceneOptions;
use super::ctx::Ctx;
use crate::camera::Camera;
use crate::environment::{Environment, EnvironmentMap};
use crate::error::{Error, Result};
use crate::sampler::SamplerKind;
use crate::settings::{Integrator, Sampling};
use glam::Vec3;
use std::sync::Arc;

/// Image sizes above this many pixels are refused before allocating.
const MAX_PIXELS: u64 = 1 << 28;

/// Bytes per image pixel counted in a scene's memory estimate: the linear
/// film (12), its 8-bit output (3) and room for AOVs (16).
const IMAGE_BYTES_PER_PIXEL: u128 = 31;

/// Most reflection bounces (`image.max_depth`). Bounces are traced
/// recursively, one chain of stack frames per bounce on a worker thread's
/// stack: two facing mirrors at 5000 bounces overflow it, while 64 leaves a
/// wide margin and is far more than any visible contribution needs (each
/// bounce is weighted by the mirror's colour).
pub const MAX_DEPTH: i64 = 64;

/// Most samples per pixel (`image.spp`, `--spp`).
pub const MAX_SPP: i64 = 1 << 16;

/// Most shadow rays per area light at each hit (`image.shadow_samples`).
pub const MAX_SHADOW_SAMPLES: i64 = 1 << 12;

/// Most camera samples of one render (pixels times `spp`): about 6.9e10,
/// hours of work at any speed this renderer reaches, so a typo such as
/// `spp = 4000000000` is refused rather than left to run for years.
pub const MAX_SAMPLES: u64 = 1 << 36;

/// The checked `[image]` table, with the command line's overrides.
pub(super) struct Film {
    pub(super) width: u32,
    pub(super) height: u32,
    pub(super) spp: u32,
    pub(super) max_depth: u32,
    pub(super) seed: u64,
    pub(super) shadow_samples: u32,
    pub(super) background: Vec3,
    pub(super) environment: Environment,
    pub(super) integrator: Integrator,
    pub(super) sampling: Sampling,
    pub(super) sampler: SamplerKind,
}

/// One of a key's named choices (`image.integrator`, `image.sampling`,
/// `image.sampler`), an unknown name reported under the key.
fn choice<T: std::str::FromStr<Err = Error>>(cx: &Ctx, text: &str, key: &str) -> Result<T> {
    text.parse()
        .map_err(|e: Error| cx.err(format!("{key}: {e}")))
}

/// The film of `img`, `opts` overriding its size, samples and integrator;
/// its image buffers start the scene's memory estimate.
pub(super) fn film(cx: &mut Ctx, img: &ImageSpec, opts: &SceneOptions) -> Result<Film> {
    let (width, height) = match opts.size {
        Some([w, h]) => (
            cx.positive(w as i64, "--size width")?,
            cx.positive(h as i64, "--size height")?,
        ),
        None => (
            cx.positive(img.width, "image.width")?,
            cx.positive(img.height, "image.height")?,
        ),
    };
    if width as u64 * height as u64 > MAX_PIXELS {
        return Err(cx.err(format!(
            "image {width}x{height} has more than {MAX_PIXELS} pixels"
        )));
    }
    // The film and its AOVs: at most a few colour-sized buffers, checked
    // on their own first, so that an image too big for the machine is named
    // as the image rather than as the first bake that comes after it.
    if !opts.no_image {
        cx.memory = width as u128 * height as u128 * IMAGE_BYTES_PER_PIXEL;
        displace_core::memory::check(
            &format!("the {width}x{height} image and its outputs"),
            cx.memory,
        )
        .map_err(|e| cx.err(e.to_string()))?;
    }
    let spp = match opts.spp {
        Some(s) => cx.bounded(s as i64, MAX_SPP, "--spp")?,
        None => cx.bounded(img.spp, MAX_SPP, "image.spp")?,
    };
    let samples = width as u64 * height as u64 * spp as u64;
    if samples > MAX_SAMPLES {
        return Err(cx.err(format!(
            "{width}x{height} pixels at {spp} spp is {samples} camera samples, more than the limit of {MAX_SAMPLES}; lower image.spp or the size"
        )));
    }
    let shadow_samples = cx.bounded(
        img.shadow_samples,
        MAX_SHADOW_SAMPLES,
        "image.shadow_samples",
    )?;
    if !(0..=MAX_DEPTH).contains(&img.max_depth) {
        return Err(cx.err(format!(
            "image.max_depth must be 0..={MAX_DEPTH} (bounces are traced recursively), got {}",
            img.max_depth
        )));
    }
    let integrator = match opts.integrator {
        Some(i) => i,
        None => choice(cx, &img.integrator, "image.integrator")?,
    };
    let sampling: Sampling = choice(cx, &img.sampling, "image.sampling")?;
    let sampler = match opts.sampler {
        Some(k) => k,
        None => choice(cx, &img.sampler, "image.sampler")?,
    };
    let background = match img.background {
        Some(b) => cx.color(b, "image.background")?,
        None => Vec3::ZERO,
    };
    let environment = match &img.environment {
        None => Environment::Constant(background),
        Some(file) => {
            if img.background.is_some() {
                return Err(cx.err(
                    "image.background and image.environment both give the light of escaping rays: give one",
                ));
            }
            let map = cx.image(
                "image.environment",
                file,
                ("environment map", EnvironmentMap::BYTES_PER_TEXEL),
                EnvironmentMap::dimensions,
                EnvironmentMap::load,
            )?;
            cx.source(cx.base.join(file));
            Environment::Map(Arc::new(map))
        }
    };

    Ok(Film {
        width,
        height,
        spp,
        max_depth: img.max_depth as u32,
        seed: img.seed,
        shadow_samples,
        background,
        environment,
        integrator,
        sampling,
        sampler,
    })
}

/// The camera of `c` for a `width` x `height` film.
pub(super) fn camera(cx: &Ctx, c: &CameraSpec, width: u32, height: u32) -> Result<Camera> {
    let position = cx.vec(c.position, "camera.position")?;
    let look_at = cx.vec(c.look_at, "camera.look_at")?;
    let up = cx.vec(c.up, "camera.up")?;
    Camera::new(
        position,
        look_at,
        up,
        c.vfov,
        width as f32 / height as f32,
        c.aperture,
        c.focus_distance,
    )
    .map_err(|e| cx.err(e.to_string()))
}
