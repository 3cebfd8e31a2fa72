//! Whitted ray tracing (Whitted 1980) with the distributed rays of Cook,
//! Porter and Carpenter (1984): at each hit, direct light from every light
//! (one shadow ray for a point light, `shadow_samples` stratified ones over
//! an area light), plus one recursive reflection ray for mirror and glossy
//! materials (glossy rays spread around the mirror direction; the spread is
//! integrated over the pixel's many samples, as the paper distributes it).
//! Displaced faces are ordinary primitives here: shadows and reflections on
//! and of them need nothing special (seed 002, section 1.2).

use crate::geometry::Ray;
use crate::light::Light;
use crate::sampler::Rng;
use crate::scene::{Interaction, Scene};
use glam::Vec3;

/// Which of a pixel's `count` samples this is: at the first hit, area-light
/// samples are stratified over all the pixel's shadow rays together (`count
/// x shadow_samples` strata), not each sample's few.
#[derive(Clone, Copy, Debug)]
pub struct PixelSample {
    pub index: u32,
    pub count: u32,
}

/// Radiance arriving along `ray` (linear RGB).
pub fn radiance(
    scene: &Scene,
    ray: &Ray,
    depth: u32,
    sample: Option<PixelSample>,
    rng: &mut Rng,
) -> Vec3 {
    match scene.intersect(ray, 0.0, f32::INFINITY) {
        Some(hit) => shade(scene, ray, &hit, depth, sample, rng),
        None => scene.environment.radiance(ray.dir),
    }
}

/// Surfaces are two-sided: the geometric and shading normals turned to the
/// side `ray` arrived on, and the point secondary rays start from, just off
/// the surface on that side.
pub fn facing(scene: &Scene, ray: &Ray, hit: &Interaction) -> (Vec3, Vec3, Vec3) {
    let (mut ng, mut ns) = (hit.geometric_normal, hit.shading_normal);
    if ng.dot(ray.dir) > 0.0 {
        ng = -ng;
        ns = -ns;
    }
    (ng, ns, hit.position + ng * scene.epsilon)
}

/// A shadow ray towards a light sample, as [`radiance`] casts it.
#[derive(Clone, Copy, Debug)]
pub struct ShadowQuery {
    pub ray: Ray,
    /// Occluders count only before this distance (short of the light).
    pub t_max: f32,
    /// Unit direction from the surface point to the light sample.
    pub wi: Vec3,
    /// `ns . wi`, the receiver's cosine.
    pub cos: f32,
}

/// The shadow ray from a hit at `position` (offset to `p` off the surface,
/// normals `ng`, `ns` already facing the viewer) to light sample `target`,
/// or `None` when the light is behind the surface and no ray is cast. The
/// geometry is taken from the surface point itself; only the ray starts off
/// the surface. Shared with [`crate::probe`], which benchmarks these rays.
pub fn shadow_query(
    scene: &Scene,
    position: Vec3,
    p: Vec3,
    ng: Vec3,
    ns: Vec3,
    target: Vec3,
) -> Option<ShadowQuery> {
    let wi = (target - position).normalize();
    let cos = ns.dot(wi);
    if cos <= 0.0 || ng.dot(wi) <= 0.0 {
        return None;
    }
    let dist = (target - p).length();
    Some(ShadowQuery {
        ray: Ray::new(p, target - p),
        t_max: dist * (1.0 - 1e-4) - scene.epsilon,
        wi,
        cos,
    })
}

fn shade(
    scene: &Scene,
    ray: &Ray,
    hit: &Interaction,
    depth: u32,
    sample: Option<PixelSample>,
    rng: &mut Rng,
) -> Vec3 {
    let mut l = Vec3::ZERO;
    if let Some(e) = hit.emitter {
        if let Light::Area { quad, radiance } = &scene.lights[e as usize] {
            if quad.normal.dot(ray.dir) < 0.0 {
                l += *radiance;
            }
        }
    }
    let mat = &scene.materials[hit.material as usize];
    l += mat.emission;
    let wo = -ray.dir;
    let (ng, ns, p) = facing(scene, ray, hit);
    let albedo = mat.albedo(hit.uv, hit.tint);
    if albedo != Vec3::ZERO || mat.specular != Vec3::ZERO {
        for light in &scene.lights {
            let n = light.samples(scene.shadow_samples);
            let mut sum = Vec3::ZERO;
            let (first, strata) = match sample {
                Some(ps) => (ps.index * n, ps.count * n),
                None => (0, n),
            };
            for i in 0..n {
                let Some(s) = light.sample(hit.position, first + i, strata, rng) else {
                    continue;
                };
                let Some(q) = shadow_query(scene, hit.position, p, ng, ns, s.point) else {
                    continue;
                };
                if scene.occluded(&q.ray, 0.0, q.t_max) {
                    continue;
                }
                sum += mat.brdf(albedo, ns, wo, q.wi) * s.weight * q.cos;
            }
            l += sum / n as f32;
        }
    }
    if mat.reflects() && depth < scene.max_depth {
        let dir = mat.reflection_dir(ray.dir, ns, rng);
        if dir.dot(ng) > 0.0 {
            l += mat.reflect * radiance(scene, &Ray::new(p, dir), depth + 1, None, rng);
        }
    }
    l
}
