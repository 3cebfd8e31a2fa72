//! The integrators, one module per light-transport technique, chosen by
//! the scene's settings (`image.integrator`, [`crate::settings::Integrator`]):
//! the ray-tracer paper's Whitted tracer with distributed effects
//! ([`whitted`], the default) and path tracing with next-event estimation
//! and multiple importance sampling ([`path`], pbrt-v4 section 13.4). Each
//! estimates the pixels of a tile from their samples; the render loop
//! ([`crate::render()`]) asks `tile` and knows no technique.

pub mod path;
pub mod whitted;

use crate::scene::Scene;
use crate::settings::Integrator;
use glam::Vec3;

/// What a thread's tiles reuse from tile to tile, whichever integrator
/// runs (each integrator's wavefront buffers).
#[derive(Default)]
pub(crate) struct Scratch {
    whitted: whitted::WaveScratch,
    path: path::WaveScratch,
}

/// The estimates of `pixels` (in that order, onto `out`) by the integrator
/// the scene's settings name, each as a wavefront over the tile's samples.
pub(crate) fn tile(
    scene: &Scene,
    pixels: &[(u32, u32)],
    scratch: &mut Scratch,
    out: &mut Vec<Vec3>,
) {
    match scene.integrator {
        Integrator::Whitted => whitted::tile(scene, pixels, &mut scratch.whitted, out),
        Integrator::Path => path::tile(scene, pixels, &mut scratch.path, out),
    }
}
