//! The integrators, one module per light-transport technique, chosen by
//! the scene's settings (`image.integrator`, [`crate::settings::Integrator`]):
//! the ray-tracer paper's Whitted tracer with distributed effects
//! ([`whitted`], the default) and path tracing with next-event estimation
//! and multiple importance sampling ([`path`], pbrt-v4 section 13.4). Each
//! estimates a pixel from its samples; the render loop
//! ([`crate::render()`]) asks [`pixel`] and knows no technique.

pub mod path;
pub mod whitted;

use crate::scene::Scene;
use crate::settings::Integrator;
use glam::Vec3;

/// What one tile's pixels reuse from pixel to pixel, whichever integrator
/// runs (the Whitted tracer's batch buffers; the path tracer keeps none).
#[derive(Default)]
pub(crate) struct Scratch {
    whitted: whitted::PixelScratch,
}

/// The estimate of pixel `(x, y)` by the integrator the scene's settings
/// name.
pub(crate) fn pixel(scene: &Scene, x: u32, y: u32, scratch: &mut Scratch) -> Vec3 {
    match scene.integrator {
        Integrator::Whitted => whitted::pixel(scene, x, y, &mut scratch.whitted),
        Integrator::Path => path::pixel(scene, x, y),
    }
}
