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

use crate::camera_sample::camera_samples8;
use crate::geometry::Ray;
use crate::geometry::PACKET;
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
/// pixels (the wavefront of `tile`) must match bit for bit.
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
        match self.reflection(scene, ray, depth, rng) {
            Some(r) => self.mat.reflect * radiance(scene, &r, depth + 1, None, rng),
            None => Vec3::ZERO,
        }
    }

    /// The reflection ray, or `None` where the material does not reflect,
    /// the depth is spent or the drawn direction goes under the surface.
    fn reflection(&self, scene: &Scene, ray: &Ray, depth: u32, rng: &mut Rng) -> Option<Ray> {
        if self.mat.reflects() && depth < scene.max_depth {
            let dir = self.mat.reflection_dir(ray.dir, self.ns, rng);
            if dir.dot(self.ng) > 0.0 {
                return Some(Ray::new(self.p, dir));
            }
        }
        None
    }
}

/// A vertex's shading with its shadow rays held back, so that a wave's
/// shadow rays are traced together ([`Scene::occluded_many`]) and then
/// summed by [`Deferred::finish`] exactly as [`radiance`] sums them.
#[derive(Clone, Copy, Debug)]
struct Deferred {
    emitted: Vec3,
    lit: bool,
    /// This vertex's shadow rays: `terms[first..first + count]` of the
    /// wave's list.
    first: usize,
    count: usize,
}

/// A held-back shadow ray's term: the light it samples and what it
/// carries when nothing blocks it (the ray itself and its range go
/// straight to the wave's shadow-ray columns, [`Shading`]).
///
/// [`Deferred::finish`] sums these per light, in the order they were
/// appended, so the held-back sums equal [`radiance`]'s.
#[derive(Clone, Copy, Debug)]
struct Term {
    /// Index of the light sampled, in the scene's `lights`: which light's
    /// sum (divided by its sample count) the term goes to.
    light: u32,
    /// BRDF times the light sample's weight times the receiver's cosine:
    /// what the term adds when the ray is not blocked.
    value: Vec3,
}

/// What a level's shading leaves for its shadow-ray batch and its sums,
/// written in place as each vertex is shaded: each vertex's [`Deferred`],
/// and per held-back shadow ray its [`Term`], its ray and its range (the
/// ray columns [`Scene::occluded_many`] reads, so nothing is copied
/// between buffers on the way).
#[derive(Default)]
struct Shading {
    shaded: Vec<Deferred>,
    terms: Vec<Term>,
    rays: Vec<Ray>,
    limits: Vec<f32>,
}

impl Shading {
    fn clear(&mut self) {
        self.shaded.clear();
        self.terms.clear();
        self.rays.clear();
        self.limits.clear();
    }
}

/// [`shade`] of a vertex whose hit (or miss) is already known, split where
/// it would trace: its [`Deferred`] and its shadow rays appended to `out`,
/// its reflection returned as `(weight, ray)` for the next level of the
/// wave. The light samples and then the reflection direction are drawn
/// from `rng`, in [`shade`]'s order.
fn shade_deferred(
    scene: &Scene,
    ray: &Ray,
    hit: Option<&Interaction>,
    depth: u32,
    sample: Option<PixelSample>,
    rng: &mut Rng,
    out: &mut Shading,
) -> Option<(Vec3, Ray)> {
    let first = out.terms.len();
    let Some(hit) = hit else {
        out.shaded.push(Deferred {
            emitted: scene.environment.radiance(ray.dir),
            lit: false,
            first,
            count: 0,
        });
        return None;
    };
    let emitted = emitted(scene, ray, hit);
    let at = Surface::new(scene, ray, hit);
    let lit = at.lit();
    if lit {
        for (k, light) in scene.lights.iter().enumerate() {
            let n = light.samples(scene.shadow_samples);
            for i in 0..n {
                if let Some((query, value)) = at.light_term(scene, light, i, n, sample, rng) {
                    out.terms.push(Term {
                        light: k as u32,
                        value,
                    });
                    out.rays.push(query.ray);
                    out.limits.push(query.t_max);
                }
            }
        }
    }
    let reflection = at
        .reflection(scene, ray, depth, rng)
        .map(|r| (at.mat.reflect, r));
    out.shaded.push(Deferred {
        emitted,
        lit,
        first,
        count: out.terms.len() - first,
    });
    reflection
}

impl Deferred {
    /// The vertex's own radiance (its reflection apart), given which of
    /// the wave's held-back shadow rays are blocked: the sums of
    /// [`shade`], in its order.
    fn finish(&self, scene: &Scene, terms: &[Term], blocked: &[bool]) -> Vec3 {
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
        l
    }
}

/// Camera samples one wave of a tile holds at most: a 16x16 tile at 16
/// samples a pixel in one wave, bounded so that a tile at thousands of
/// samples a pixel keeps its buffers to a few megabytes.
const WAVE_SAMPLES: u64 = 4096;

/// No reflection vertex follows.
const NO_CHILD: u32 = u32::MAX;

/// What a thread's tiles reuse from tile to tile: the batch queries'
/// buffers, the wave's vertices and its held-back shadow rays, so that a
/// render allocates nothing after its first tile.
#[derive(Default)]
pub(crate) struct WaveScratch {
    batch: Batch,
    /// The level being traced: its vertices (indices into the per-vertex
    /// columns below), their rays and ranges, and their hits.
    level: Vec<u32>,
    rays: Vec<Ray>,
    limits: Vec<f32>,
    hits: Vec<Option<(u32, Interaction)>>,
    /// The next level: reflection vertices and their rays.
    next: Vec<u32>,
    next_rays: Vec<Ray>,
    /// Per vertex of the wave, every level (a parent before its child):
    /// the generator its path draws from, its camera sample (`None` past
    /// the camera vertex), its own radiance, its reflection's vertex and
    /// weight.
    rngs: Vec<Rng>,
    samples: Vec<Option<PixelSample>>,
    pixel: Vec<u32>,
    local: Vec<Vec3>,
    child: Vec<u32>,
    weight: Vec<Vec3>,
    /// One level's shading and its held-back shadow rays.
    shading: Shading,
    blocked: Vec<bool>,
    /// Per pixel of the tile: the sum of its samples so far.
    sums: Vec<Vec3>,
}

/// The Whitted estimates of `pixels` (onto `out`, in that order), as a
/// wavefront over the tile's samples (Laine, Karras and Aila 2013,
/// "Megakernels considered harmful"; pbrt-v4's wavefront integrator):
/// the camera rays of up to [`WAVE_SAMPLES`] samples are traced as one
/// batch ([`Scene::intersect_many`], the displaced faces' rays in packets),
/// every hit is shaded with its shadow rays and reflection held back, the
/// shadow rays are traced as one batch ([`Scene::occluded_many`]), and the
/// reflection rays form the next level of the wave. Each vertex draws the
/// same numbers in the same order as [`radiance`], and the terms are summed
/// in its order (a vertex's own light, then its reflection's, deepest
/// first; a pixel's samples in sample order): the image is the one-sample
/// tracer's bit for bit.
pub(crate) fn tile(
    scene: &Scene,
    pixels: &[(u32, u32)],
    sc: &mut WaveScratch,
    out: &mut Vec<Vec3>,
) {
    let spp = scene.spp as u64;
    let total = pixels.len() as u64 * spp;
    sc.sums.clear();
    sc.sums.resize(pixels.len(), Vec3::ZERO);
    let mut k0 = 0;
    while k0 < total {
        let k1 = (k0 + WAVE_SAMPLES).min(total);
        wave(scene, pixels, k0..k1, sc);
        k0 = k1;
    }
    out.extend(sc.sums.iter().map(|s| *s / scene.spp as f32));
}

/// One wave: samples `range` of the tile, numbered pixel by pixel
/// (`pixel * spp + sample`), added to `sc.sums`.
fn wave(scene: &Scene, pixels: &[(u32, u32)], range: std::ops::Range<u64>, sc: &mut WaveScratch) {
    let spp = scene.spp as u64;
    sc.rngs.clear();
    sc.samples.clear();
    sc.pixel.clear();
    sc.level.clear();
    sc.rays.clear();
    // The camera rays eight at a time (their arithmetic in lanes); a last
    // short packet repeats its last sample and keeps only its own.
    let (start, end) = (range.start, range.end);
    for k0 in (start..end).step_by(PACKET) {
        let n = (end - k0).min(PACKET as u64) as usize;
        let at = |l: usize| {
            let k = k0 + l.min(n - 1) as u64;
            ((k / spp) as u32, (k % spp) as u32)
        };
        let (rays, rngs) = camera_samples8(
            scene,
            &std::array::from_fn(|l| {
                let (p, s) = at(l);
                let (x, y) = pixels[p as usize];
                (x, y, s)
            }),
        );
        for (l, (ray, rng)) in rays.into_iter().zip(rngs).take(n).enumerate() {
            let (p, s) = at(l);
            sc.level.push(sc.rngs.len() as u32);
            sc.rays.push(ray);
            sc.rngs.push(rng);
            sc.samples.push(Some(PixelSample {
                index: s,
                count: scene.spp,
            }));
            sc.pixel.push(p);
        }
    }
    let cameras = sc.rngs.len();
    sc.local.clear();
    sc.local.resize(cameras, Vec3::ZERO);
    sc.child.clear();
    sc.child.resize(cameras, NO_CHILD);
    sc.weight.clear();
    sc.weight.resize(cameras, Vec3::ZERO);
    let mut depth = 0;
    while !sc.level.is_empty() {
        level(scene, depth, sc);
        std::mem::swap(&mut sc.level, &mut sc.next);
        std::mem::swap(&mut sc.rays, &mut sc.next_rays);
        depth += 1;
    }
    // Children come after their parents: fold each reflection into its
    // parent, deepest first, as the recursion returns.
    for v in (0..sc.local.len()).rev() {
        let c = sc.child[v];
        if c != NO_CHILD {
            let reflected = sc.weight[v] * sc.local[c as usize];
            sc.local[v] += reflected;
        }
    }
    for v in 0..cameras {
        sc.sums[sc.pixel[v] as usize] += sc.local[v];
    }
}

/// Traces and shades one level of the wave (`sc.level`, its rays in
/// `sc.rays`), leaving its reflection vertices in `sc.next`.
fn level(scene: &Scene, depth: u32, sc: &mut WaveScratch) {
    sc.limits.clear();
    sc.limits.resize(sc.rays.len(), f32::INFINITY);
    scene.intersect_many(&sc.rays, 0.0, &sc.limits, &mut sc.batch, &mut sc.hits);
    sc.shading.clear();
    sc.next.clear();
    sc.next_rays.clear();
    for (k, &v) in sc.level.iter().enumerate() {
        let v = v as usize;
        let hit = sc.hits[k].as_ref().map(|(_, h)| h);
        let reflection = shade_deferred(
            scene,
            &sc.rays[k],
            hit,
            depth,
            sc.samples[v],
            &mut sc.rngs[v],
            &mut sc.shading,
        );
        if let Some((weight, ray)) = reflection {
            let c = sc.rngs.len() as u32;
            let rng = sc.rngs[v].clone();
            sc.rngs.push(rng);
            sc.samples.push(None);
            sc.pixel.push(sc.pixel[v]);
            sc.local.push(Vec3::ZERO);
            sc.child.push(NO_CHILD);
            sc.weight.push(Vec3::ZERO);
            sc.child[v] = c;
            sc.weight[v] = weight;
            sc.next.push(c);
            sc.next_rays.push(ray);
        }
    }
    let sh = &sc.shading;
    scene.occluded_many(&sh.rays, 0.0, &sh.limits, &mut sc.batch, &mut sc.blocked);
    for (d, &v) in sh.shaded.iter().zip(&sc.level) {
        sc.local[v as usize] = d.finish(scene, &sh.terms, &sc.blocked);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera_sample::camera_sample;
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
    fn the_wavefront_is_the_one_ray_tracer_bit_for_bit() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
        // Soft shadows from an area light, a mirror, a gaussian floor, and
        // meshes: every kind of term the wave holds back. Nine samples of
        // 576 pixels make two waves, one pixel's samples split between
        // them.
        for name in [
            "cornell_studded_shadows.toml",
            "cornell_stud_reflection.toml",
            "cornell_gaussian.toml",
            "gpu_meshes.toml",
        ] {
            let opts = SceneOptions {
                size: Some([24, 24]),
                spp: Some(9),
                ..SceneOptions::default()
            };
            let scene = Scene::load(&dir.join(name), &opts).unwrap();
            let pixels: Vec<(u32, u32)> =
                (0..24).flat_map(|y| (0..24).map(move |x| (x, y))).collect();
            assert!(pixels.len() as u64 * 9 > WAVE_SAMPLES);
            let mut out = Vec::new();
            tile(&scene, &pixels, &mut WaveScratch::default(), &mut out);
            let mut lit = 0;
            for (&(x, y), &waved) in pixels.iter().zip(&out) {
                assert_eq!(waved, pixel_one_ray(&scene, x, y), "{name} ({x}, {y})");
                lit += usize::from(waved != Vec3::ZERO);
            }
            assert!(lit > 100, "{name}: only {lit} pixels lit");
        }
    }
}
