//! Whitted ray tracing (Whitted 1980) with the distributed rays of Cook,
//! Porter and Carpenter (1984): at each hit, direct light from every light
//! (one shadow ray for a point light, `shadow_samples` stratified ones over
//! an area light), plus one recursive reflection ray for mirror and glossy
//! materials (glossy rays spread around the mirror direction; the spread is
//! integrated over the pixel's many samples, as the paper distributes it).
//! Displaced faces are ordinary primitives here: shadows and reflections on
//! and of them need nothing special (the ray-tracer paper, section 1.2, in
//! `docs/architecture.md`'s "References": only the intersection routine
//! changes, so its shadows and reflections carry over).
//!
//! [`super::path`] is the physically based alternative (pbrt-v4 section
//! 13.4, Veach 1997's multiple importance sampling); this one is the paper's
//! own renderer, and the default.

use crate::camera_sample::camera_sample;
use crate::geometry::Ray;
use crate::light::Light;
use crate::scene::batch::Batch;
use crate::scene::{Interaction, Scene};
use crate::shading::sampler::Rng;
use glam::Vec3;

/// Which of a pixel's `count` samples this is: at the first hit, area-light
/// samples are stratified over all the pixel's shadow rays together (`count
/// x shadow_samples` strata), not each sample's few.
///
/// Stratifying across the whole pixel is what lets a few shadow rays a
/// sample add up to a smooth penumbra: Cook, Porter and Carpenter's
/// distribution of the shadow rays over the pixel's samples.
#[derive(Clone, Copy, Debug)]
pub struct PixelSample {
    /// This sample's index in `0..count`; it picks the sample's strata.
    pub index: u32,
    /// Samples in the pixel (the scene's `spp`).
    pub count: u32,
}

/// Radiance arriving along `ray` (linear RGB): the environment on a miss,
/// else the hit's emission, direct light and reflection.
///
/// `depth` is the number of reflections already taken (0 for a camera
/// ray), bounded by the scene's `max_depth`; `sample` is `Some` only for a
/// camera ray, whose shadow rays it stratifies over the pixel (reflection
/// rays pass `None`). The one-ray reference that the render loop's batched
/// pixels ([`radiance_deferred`]) must match bit for bit.
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
///
/// Returns `(ng, ns, p)`. The offset by the scene's `epsilon` along `ng`
/// keeps a secondary ray from hitting its own surface again; it is shared
/// by both integrators and the benchmarks' ray sets, so they start rays alike.
pub fn facing(scene: &Scene, ray: &Ray, hit: &Interaction) -> (Vec3, Vec3, Vec3) {
    let (mut ng, mut ns) = (hit.geometric_normal, hit.shading_normal);
    if ng.dot(ray.dir) > 0.0 {
        ng = -ng;
        ns = -ns;
    }
    (ng, ns, hit.position + ng * scene.epsilon)
}

/// A shadow ray towards a light sample, as [`radiance`] casts it.
///
/// Kept apart from its tracing so that shadow rays can be traced one at a
/// time or in batches, with the same rays either way.
#[derive(Clone, Copy, Debug)]
pub struct ShadowQuery {
    /// From the offset surface point towards the light sample, unit
    /// direction, so that [`Self::t_max`] is a world distance.
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
/// the surface. Shared with the benchmarks' ray sets, which time these rays.
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
    let mut l = emitted(scene, ray, hit);
    let at = Surface::new(scene, ray, hit);
    if at.lit() {
        for light in &scene.lights {
            let n = light.samples(scene.shadow_samples);
            let mut sum = Vec3::ZERO;
            for i in 0..n {
                let Some((q, value)) = at.light_term(scene, light, i, n, sample, rng) else {
                    continue;
                };
                if !scene.occluded(&q.ray, 0.0, q.t_max) {
                    sum += value;
                }
            }
            l += sum / n as f32;
        }
    }
    l + at.reflected(scene, ray, depth, rng)
}

/// What a hit sends back along `ray` by itself: a visible area light's
/// quad from its front, plus its material's `emission` (both sides). Shared
/// with the path integrator.
pub(crate) fn emitted(scene: &Scene, ray: &Ray, hit: &Interaction) -> Vec3 {
    let mut le = scene.materials[hit.material as usize].emission;
    if let Some(e) = hit.emitter {
        if let Light::Area { quad, radiance } = &scene.lights[e as usize] {
            if quad.normal.dot(ray.dir) < 0.0 {
                le += *radiance;
            }
        }
    }
    le
}

/// A hit as shading sees it: its material and albedo, the normals turned
/// to the viewer and the point secondary rays start from.
struct Surface<'a> {
    mat: &'a crate::material::Material,
    albedo: Vec3,
    hit: &'a Interaction,
    wo: Vec3,
    ng: Vec3,
    ns: Vec3,
    p: Vec3,
}

impl<'a> Surface<'a> {
    fn new(scene: &'a Scene, ray: &Ray, hit: &'a Interaction) -> Self {
        let mat = &scene.materials[hit.material as usize];
        let (ng, ns, p) = facing(scene, ray, hit);
        Surface {
            mat,
            albedo: mat.albedo(hit.uv, hit.tint),
            hit,
            wo: -ray.dir,
            ng,
            ns,
            p,
        }
    }

    /// Whether direct light is gathered at all (a black, non-specular
    /// surface casts no shadow rays).
    fn lit(&self) -> bool {
        self.albedo != Vec3::ZERO || self.mat.specular != Vec3::ZERO
    }

    /// Shadow ray `i` of `n` towards `light` and what it carries if
    /// nothing blocks it, or `None` where no ray is cast.
    fn light_term(
        &self,
        scene: &Scene,
        light: &Light,
        i: u32,
        n: u32,
        sample: Option<PixelSample>,
        rng: &mut Rng,
    ) -> Option<(ShadowQuery, Vec3)> {
        let (first, strata) = match sample {
            Some(ps) => (ps.index * n, ps.count * n),
            None => (0, n),
        };
        let s = light.sample(self.hit.position, first + i, strata, rng)?;
        let q = shadow_query(scene, self.hit.position, self.p, self.ng, self.ns, s.point)?;
        let value = self.mat.brdf(self.albedo, self.ns, self.wo, q.wi) * s.weight * q.cos;
        Some((q, value))
    }

    /// The mirror or glossy reflection (drawn after the light samples, from
    /// the same generator).
    fn reflected(&self, scene: &Scene, ray: &Ray, depth: u32, rng: &mut Rng) -> Vec3 {
        if self.mat.reflects() && depth < scene.max_depth {
            let dir = self.mat.reflection_dir(ray.dir, self.ns, rng);
            if dir.dot(self.ng) > 0.0 {
                return self.mat.reflect
                    * radiance(scene, &Ray::new(self.p, dir), depth + 1, None, rng);
            }
        }
        Vec3::ZERO
    }
}

/// A first hit's shading with its shadow rays held back, so that a pixel's
/// shadow rays are traced together ([`Scene::occluded_many`]) and then
/// summed by [`Deferred::finish`] exactly as [`radiance`] sums them.
#[derive(Clone, Copy, Debug)]
pub struct Deferred {
    emitted: Vec3,
    reflected: Vec3,
    lit: bool,
    /// This hit's shadow rays: `terms[first..first + count]` of the pixel's
    /// list.
    first: usize,
    count: usize,
}

/// A held-back shadow ray: the light it samples and what it carries when
/// nothing blocks it.
///
/// [`Deferred::finish`] sums these per light, in the order they were
/// appended, so the held-back sums equal [`radiance`]'s.
#[derive(Clone, Copy, Debug)]
pub struct Term {
    /// The shadow ray to trace.
    pub query: ShadowQuery,
    /// Index of the light sampled, in the scene's `lights`: which light's
    /// sum (divided by its sample count) the term goes to.
    pub light: u32,
    /// BRDF times the light sample's weight times the receiver's cosine:
    /// what the term adds when the ray is not blocked.
    pub value: Vec3,
}

/// [`radiance`] of a camera ray whose first hit (or miss) is already
/// known, its shadow rays appended to `terms` instead of traced.
///
/// Camera rays are intersected together and their shadow rays traced
/// together (batch queries, [`crate::scene::batch`]), which is faster
/// through displaced faces; this splits [`radiance`] at the shadow rays so
/// that the image stays the one-ray tracer's. The reflection ray is still
/// traced here, one at a time. Pass the result to [`Deferred::finish`].
pub fn radiance_deferred(
    scene: &Scene,
    ray: &Ray,
    hit: Option<&Interaction>,
    sample: Option<PixelSample>,
    rng: &mut Rng,
    terms: &mut Vec<Term>,
) -> Deferred {
    let first = terms.len();
    let Some(hit) = hit else {
        return Deferred {
            emitted: scene.environment.radiance(ray.dir),
            reflected: Vec3::ZERO,
            lit: false,
            first,
            count: 0,
        };
    };
    let emitted = emitted(scene, ray, hit);
    let at = Surface::new(scene, ray, hit);
    let lit = at.lit();
    if lit {
        for (k, light) in scene.lights.iter().enumerate() {
            let n = light.samples(scene.shadow_samples);
            for i in 0..n {
                if let Some((query, value)) = at.light_term(scene, light, i, n, sample, rng) {
                    terms.push(Term {
                        query,
                        light: k as u32,
                        value,
                    });
                }
            }
        }
    }
    let reflected = at.reflected(scene, ray, 0, rng);
    Deferred {
        emitted,
        reflected,
        lit,
        first,
        count: terms.len() - first,
    }
}

impl Deferred {
    /// The radiance, given which of the pixel's held-back shadow rays are
    /// blocked: the sums of [`radiance`], in its order.
    pub fn finish(&self, scene: &Scene, terms: &[Term], blocked: &[bool]) -> Vec3 {
        let mut l = self.emitted;
        if self.lit {
            let mine = self.first..self.first + self.count;
            let mut k = mine.start;
            for (li, light) in scene.lights.iter().enumerate() {
                let n = light.samples(scene.shadow_samples);
                let mut sum = Vec3::ZERO;
                while k < mine.end && terms[k].light == li as u32 {
                    if !blocked[k] {
                        sum += terms[k].value;
                    }
                    k += 1;
                }
                l += sum / n as f32;
            }
        }
        l + self.reflected
    }
}

/// What one tile's pixels reuse from pixel to pixel: the batch queries'
/// buffers and the pixel's rays, hits and held-back shadow rays.
#[derive(Default)]
pub(crate) struct PixelScratch {
    batch: Batch,
    rays: Vec<Ray>,
    rngs: Vec<Rng>,
    limits: Vec<f32>,
    hits: Vec<Option<(u32, Interaction)>>,
    shaded: Vec<Deferred>,
    terms: Vec<Term>,
    shadow_rays: Vec<Ray>,
    shadow_limits: Vec<f32>,
    blocked: Vec<bool>,
}

/// Camera samples traced together: a pixel's at most, so that what a
/// sample sees never depends on its neighbours' (the packet tracer's hits
/// are the one-ray tracer's anyway).
const SAMPLES_PER_BATCH: u32 = 64;

/// The mean of the pixel's stratified samples. Its camera rays are traced
/// together (the displaced faces' eight at a time), then shaded one by
/// one with their shadow rays held back, which are then traced together
/// too and summed as [`radiance`] sums them: the same image as tracing
/// each sample on its own.
pub(crate) fn pixel(scene: &Scene, x: u32, y: u32, scratch: &mut PixelScratch) -> Vec3 {
    let mut sum = Vec3::ZERO;
    let mut s0 = 0;
    while s0 < scene.spp {
        let s1 = (s0 + SAMPLES_PER_BATCH).min(scene.spp);
        let sc = &mut *scratch;
        sc.rays.clear();
        sc.rngs.clear();
        for s in s0..s1 {
            let (ray, rng) = camera_sample(scene, x, y, s);
            sc.rays.push(ray);
            sc.rngs.push(rng);
        }
        sc.limits.clear();
        sc.limits.resize(sc.rays.len(), f32::INFINITY);
        scene.intersect_many(&sc.rays, 0.0, &sc.limits, &mut sc.batch, &mut sc.hits);
        sc.terms.clear();
        sc.shaded.clear();
        for (k, s) in (s0..s1).enumerate() {
            let sample = PixelSample {
                index: s,
                count: scene.spp,
            };
            let hit = sc.hits[k].as_ref().map(|(_, h)| h);
            let d = radiance_deferred(
                scene,
                &sc.rays[k],
                hit,
                Some(sample),
                &mut sc.rngs[k],
                &mut sc.terms,
            );
            sc.shaded.push(d);
        }
        sc.shadow_rays.clear();
        sc.shadow_rays.extend(sc.terms.iter().map(|t| t.query.ray));
        sc.shadow_limits.clear();
        sc.shadow_limits
            .extend(sc.terms.iter().map(|t| t.query.t_max));
        scene.occluded_many(
            &sc.shadow_rays,
            0.0,
            &sc.shadow_limits,
            &mut sc.batch,
            &mut sc.blocked,
        );
        for d in &sc.shaded {
            sum += d.finish(scene, &sc.terms, &sc.blocked);
        }
        s0 = s1;
    }
    sum / scene.spp as f32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::SceneOptions;
    use std::path::Path;

    /// A pixel as the one-ray integrator computes it: each sample's camera
    /// ray traced, shaded and its shadow rays traced on their own.
    fn pixel_one_ray(scene: &Scene, x: u32, y: u32) -> Vec3 {
        let mut sum = Vec3::ZERO;
        for s in 0..scene.spp {
            let (ray, mut rng) = camera_sample(scene, x, y, s);
            let sample = PixelSample {
                index: s,
                count: scene.spp,
            };
            sum += radiance(scene, &ray, 0, Some(sample), &mut rng);
        }
        sum / scene.spp as f32
    }

    #[test]
    fn batched_pixels_are_the_one_ray_pixels_bit_for_bit() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
        // Soft shadows from an area light, a mirror, a gaussian floor, and
        // meshes: every kind of term the batch holds back.
        for name in [
            "cornell_studded_shadows.toml",
            "cornell_stud_reflection.toml",
            "cornell_gaussian.toml",
            "gpu_meshes.toml",
        ] {
            let opts = SceneOptions {
                size: Some([24, 24]),
                spp: Some(5),
                ..SceneOptions::default()
            };
            let scene = Scene::load(&dir.join(name), &opts).unwrap();
            let mut scratch = PixelScratch::default();
            let mut lit = 0;
            for y in 0..24 {
                for x in 0..24 {
                    let batched = pixel(&scene, x, y, &mut scratch);
                    assert_eq!(batched, pixel_one_ray(&scene, x, y), "{name} ({x}, {y})");
                    lit += usize::from(batched != Vec3::ZERO);
                }
            }
            assert!(lit > 100, "{name}: only {lit} pixels lit");
        }
    }
}
