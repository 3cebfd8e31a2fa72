//! Unidirectional path tracing (Kajiya 1986) with next-event estimation and
//! multiple importance sampling, after pbrt-v4's `PathIntegrator` (section
//! 13.4): at every vertex one light is sampled (chosen by power, see
//! [`crate::shading::emitters`]) and one BSDF direction ([`crate::shading::bsdf`]); the light
//! that either finds is weighted by the power heuristic with exponent 2
//! (Veach 1997, section 9.2.4), so small bright lights are found by light
//! sampling and large ones, and glossy reflections of them, by BSDF
//! sampling. Light reached right after a mirror bounce (a delta lobe, which
//! light sampling cannot produce) and light no light sampler can reach
//! (point lights; emitting displaced faces) takes weight 1. After
//! [`RR_DEPTH`] bounces, Russian roulette ends paths whose throughput is
//! below 1 with probability `1 - throughput` and reweights the survivors
//! (pbrt-v4 section 13.4.3). `image.max_depth` bounds the bounces: 0 sees
//! emitters alone, 1 is direct lighting, as in pbrt.
//!
//! Displaced faces are ordinary surfaces here: paths bounce off and under
//! their bumps, and their shading normals are handled as every surface's
//! are (see [`crate::shading::bsdf`]).
//!
//! For testing the estimators one at a time, `image.sampling` chooses
//! light sampling alone or BSDF sampling alone instead of both (each
//! unbiased by itself; Veach 1997, figure 9.2's comparison).

use super::whitted::{emitted, facing, shadow_query};
use crate::camera_sample::{camera_ray, camera_sample};
use crate::geometry::Ray;
use crate::scene::{Interaction, Scene};
use crate::settings::Sampling;
use crate::shading::bsdf::Bsdf;
use crate::shading::sampler::SampleStream;
use crate::shading::sampler::SamplerKind;
use glam::Vec3;

/// Bounces before Russian roulette may end a path (pbrt-v3's choice; pbrt-v4
/// starts after the first).
pub const RR_DEPTH: u32 = 3;

/// The power heuristic, `beta = 2` (Veach 1997, eq. 9.13): the weight of a
/// sample drawn with density `f` when `g` could also have drawn it.
#[inline]
pub fn power_heuristic(f: f32, g: f32) -> f32 {
    let (f2, g2) = (f * f, g * g);
    if f2.is_infinite() {
        return 1.0;
    }
    if f2 + g2 > 0.0 {
        f2 / (f2 + g2)
    } else {
        0.0
    }
}

/// What the last vertex knew of the direction it sent the path in.
#[derive(Clone, Copy, Debug)]
struct Bounce {
    /// The vertex.
    position: Vec3,
    /// BSDF density of the direction (unused after a delta lobe).
    pdf: f32,
    /// The direction came from a delta lobe (or the camera).
    delta: bool,
}

/// The weight of light found by BSDF sampling (or by the camera) at a
/// vertex after `prev`, when light sampling would have chosen it with
/// density `light_pdf`.
fn hit_weight(scene: &Scene, prev: Option<Bounce>, light_pdf: f32) -> f32 {
    let Some(b) = prev.filter(|b| !b.delta) else {
        return 1.0;
    };
    match scene.sampling {
        Sampling::Mis => power_heuristic(b.pdf, light_pdf),
        Sampling::Bsdf => 1.0,
        // Counted by light sampling where it can be.
        Sampling::Light => {
            if light_pdf > 0.0 {
                0.0
            } else {
                1.0
            }
        }
    }
}

/// The sample dimensions of the camera: the film position and the lens.
pub const CAMERA_DIMENSIONS: u32 = 2;

/// The sample dimensions each bounce draws, in this order: the light's
/// choice and its point, the BSDF's lobe and direction, Russian roulette.
/// A bounce starts at a fixed dimension, so that with stratified samples
/// the same decision of every sample of a pixel is drawn from one set
/// whatever the paths before it did.
const BOUNCE_DIMENSIONS: u32 = 5;

/// Radiance arriving along the camera ray `ray` (linear RGB), drawing its
/// random numbers from `rng`. A sample that comes out not finite (which
/// the estimator never produces from finite scene data) counts as black
/// rather than poisoning the pixel.
pub fn radiance(scene: &Scene, ray: &Ray, rng: &mut SampleStream) -> Vec3 {
    let l = trace(scene, *ray, rng);
    if l.is_finite() {
        l
    } else {
        Vec3::ZERO
    }
}

fn trace(scene: &Scene, mut ray: Ray, rng: &mut SampleStream) -> Vec3 {
    let mut l = Vec3::ZERO;
    let mut beta = Vec3::ONE;
    let mut prev: Option<Bounce> = None;
    let mut depth = 0u32;
    loop {
        let Some((prim, hit)) = scene.intersect_primitive(&ray, 0.0, f32::INFINITY) else {
            let le = scene.environment.radiance(ray.dir);
            if le != Vec3::ZERO {
                let pdf = scene.emitters.pdf_environment(&scene.environment, ray.dir);
                l += beta * le * hit_weight(scene, prev, pdf);
            }
            break;
        };
        let le = emitted(scene, &ray, &hit);
        if le != Vec3::ZERO {
            let pdf = prev.map_or(0.0, |b| {
                scene
                    .emitters
                    .pdf_hit(prim, b.position, hit.position, hit.geometric_normal)
            });
            l += beta * le * hit_weight(scene, prev, pdf);
        }
        if depth == scene.max_depth {
            break;
        }
        let dimensions = CAMERA_DIMENSIONS + depth * BOUNCE_DIMENSIONS;
        rng.set_dimension(dimensions);
        depth += 1;

        let mat = &scene.materials[hit.material as usize];
        let wo = -ray.dir;
        let (ng, ns, p) = facing(scene, &ray, &hit);
        let bsdf = Bsdf::new(mat, mat.albedo(hit.uv, hit.tint), ng, ns, wo);
        if bsdf.is_black() {
            break;
        }
        if bsdf.has_non_delta() {
            l += beta * direct(scene, &hit, &bsdf, ng, p, rng);
        }
        rng.set_dimension(dimensions + 2);
        let pick = rng.next_choice(bsdf.chooses_lobe());
        let Some(s) = bsdf.sample(pick, rng.next_2d()) else {
            break;
        };
        beta *= s.weight;
        if beta == Vec3::ZERO {
            break;
        }
        prev = Some(Bounce {
            position: hit.position,
            pdf: s.pdf,
            delta: s.delta,
        });
        ray = Ray::new(p, s.wi);
        if depth >= RR_DEPTH {
            let m = beta.max_element();
            if m < 1.0 {
                let q = (1.0 - m).max(0.0);
                if rng.next_1d() < q {
                    break;
                }
                beta /= 1.0 - q;
            }
        }
    }
    l
}

/// Next-event estimation at `hit`: one light sample, weighted against BSDF
/// sampling by the power heuristic (pbrt-v4 `PathIntegrator::SampleLd`).
fn direct(
    scene: &Scene,
    hit: &Interaction,
    bsdf: &Bsdf,
    ng: Vec3,
    p: Vec3,
    rng: &mut SampleStream,
) -> Vec3 {
    if scene.emitters.is_empty() {
        return Vec3::ZERO;
    }
    // The cosine that agrees with `bsdf.f` (see `Bsdf::shading_normal`).
    let ns = bsdf.shading_normal();
    let pick = rng.next_choice(scene.emitters.len() > 1);
    let u = rng.next_2d();
    let Some(ls) = scene
        .emitters
        .sample(&scene.environment, hit.position, pick, u)
    else {
        return Vec3::ZERO;
    };
    if scene.sampling == Sampling::Bsdf && ls.hittable {
        // BSDF sampling finds this light by itself.
        return Vec3::ZERO;
    }
    let cos = match ls.point {
        Some(point) => {
            let Some(q) = shadow_query(scene, hit.position, p, ng, ns, point) else {
                return Vec3::ZERO;
            };
            if scene.occluded(&q.ray, 0.0, q.t_max) {
                return Vec3::ZERO;
            }
            q.cos
        }
        None => {
            let cos = ns.dot(ls.wi);
            if cos <= 0.0 || ng.dot(ls.wi) <= 0.0 {
                return Vec3::ZERO;
            }
            if scene.occluded(&Ray::new(p, ls.wi), 0.0, f32::INFINITY) {
                return Vec3::ZERO;
            }
            cos
        }
    };
    let f = bsdf.f(ls.wi);
    if f == Vec3::ZERO {
        return Vec3::ZERO;
    }
    let w = if ls.hittable && scene.sampling == Sampling::Mis {
        power_heuristic(ls.pdf, bsdf.pdf(ls.wi))
    } else {
        1.0
    };
    f * ls.radiance * (cos * w / ls.pdf)
}

/// The camera ray of sample `s` of pixel `(x, y)` under the path
/// integrator and the stream the rest of its path draws from: with
/// independent numbers [`camera_sample`]'s, with Sobol points the film and
/// lens positions are the stream's first two dimensions.
fn path_camera_sample(scene: &Scene, x: u32, y: u32, s: u32) -> (Ray, SampleStream) {
    match scene.sampler {
        SamplerKind::Independent => {
            let (ray, rng) = camera_sample(scene, x, y, s);
            (ray, SampleStream::independent(rng))
        }
        SamplerKind::Sobol => {
            let mut st = SampleStream::sobol(scene.seed, x, y, s);
            let jitter = st.next_2d();
            let lens = st.next_2d();
            (camera_ray(scene, x, y, jitter, lens), st)
        }
    }
}

/// The mean of the pixel's samples under the path integrator, each sample's path traced on its own from its
/// [`path_camera_sample`].
pub(crate) fn pixel(scene: &Scene, x: u32, y: u32) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for s in 0..scene.spp {
        let (ray, mut rng) = path_camera_sample(scene, x, y, s);
        sum += radiance(scene, &ray, &mut rng);
    }
    sum / scene.spp as f32
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn power_heuristic_weights_sum_to_one() {
        for (a, b) in [(1.0f32, 3.0f32), (0.2, 0.0), (5.0, 5.0)] {
            let s = power_heuristic(a, b) + power_heuristic(b, a);
            assert!((s - 1.0).abs() < 1e-6);
        }
        assert_eq!(power_heuristic(0.0, 0.0), 0.0);
    }
}
