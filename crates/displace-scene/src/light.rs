//! Lights: points (hard shadows) and one-sided rectangles (soft shadows from
//! stratified shadow rays, Cook, Porter and Carpenter 1984).

use crate::sampler::{jittered, Rng};
use crate::shapes::Quad;
use glam::Vec3;

/// A light of the Whitted integrator: it casts shadow rays towards it.
#[derive(Clone, Debug)]
pub enum Light {
    /// Radiant intensity `intensity` (W/sr per channel).
    Point {
        /// Where the light is.
        position: Vec3,
        /// Radiant intensity.
        intensity: Vec3,
    },
    /// Emits radiance `radiance` from the side `edge_u x edge_v` points to.
    Area {
        /// The emitting parallelogram.
        quad: Quad,
        /// Emitted radiance.
        radiance: Vec3,
    },
}

/// One shadow-ray sample: where to aim and the radiance it brings, already
/// divided by its pdf (so a sum over samples divided by their count is the
/// estimate of irradiance-weighted radiance `Li cos_l / r^2 dA`).
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// The point on the light to aim the shadow ray at.
    pub point: Vec3,
    /// `Li * G / pdf` without the receiver's cosine.
    pub weight: Vec3,
}

impl Light {
    /// Sample `i` of `n` (stratified over the rectangle); point lights ignore
    /// both.
    pub fn sample(&self, from: Vec3, i: u32, n: u32, rng: &mut Rng) -> Option<LightSample> {
        match self {
            Light::Point {
                position,
                intensity,
            } => {
                let r2 = (*position - from).length_squared();
                (r2 > 0.0).then(|| LightSample {
                    point: *position,
                    weight: *intensity / r2,
                })
            }
            Light::Area { quad, radiance } => {
                let uv = jittered(i, n, rng);
                let p = quad.point(uv);
                let to = from - p;
                let r2 = to.length_squared();
                let cos_l = quad.normal.dot(to) / r2.sqrt();
                (cos_l > 0.0 && r2 > 0.0).then(|| LightSample {
                    point: p,
                    weight: *radiance * (cos_l * quad.area() / r2),
                })
            }
        }
    }

    /// How many shadow rays this light takes.
    pub fn samples(&self, shadow_samples: u32) -> u32 {
        match self {
            Light::Point { .. } => 1,
            Light::Area { .. } => shadow_samples.max(1),
        }
    }
}
