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
//!
//! A render runs the estimator as a wavefront ([`tile`]): every sample of
//! a tile's pixels is a path whose state waits between stages, and each
//! stage runs over all the paths still alive (Laine, Karras and Aila 2013,
//! "Megakernels considered harmful"; pbrt-v4's `WavefrontPathIntegrator`):
//! their rays are traced as one batch ([`Scene::intersect_many`]), each is
//! shaded, and the shadow rays of next-event estimation are traced as
//! another batch ([`Scene::occluded_many`]) before their light is added.
//! Each path draws the same numbers in the same order and sums its terms
//! in the same order as the one-sample estimator ([`radiance`], kept as the
//! reference), so the image is the same bit for bit.

use super::whitted::{emitted, facing, shadow_query};
use crate::camera_sample::{camera_ray, camera_rays8, camera_sample, camera_samples8};
use crate::geometry::{Ray, PACKET};
use crate::scene::batch::Batch;
use crate::scene::{Interaction, Scene};
use crate::settings::Sampling;
use crate::shading::bsdf::Bsdf;
use crate::shading::sampler::SamplerKind;
use crate::shading::sampler::{draw_2d8, Deferred2d, SampleStream};
use glam::{Vec2, Vec3};

mod lanes;

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

/// The path of `ray` on its own, through the batch queries with one ray
/// each: the rays of [`tile`]'s wavefront meet the same surfaces whatever
/// else is in their batch, so each query answers as it does there (where a
/// displaced face and a plain shape meet a ray at exactly the same
/// distance, the one-ray walk's answer would hang on the order it visits
/// them in).
fn trace(scene: &Scene, ray: Ray, rng: &mut SampleStream) -> Vec3 {
    let mut paths = [(Path::new(ray), rng.clone())];
    let mut lanes = lanes::Diffuse::default();
    let (mut batch, mut hits, mut blocked) = (Batch::default(), Vec::new(), Vec::new());
    loop {
        scene.intersect_many(
            &[paths[0].0.ray],
            0.0,
            &[f32::INFINITY],
            &mut batch,
            &mut hits,
        );
        let mut step = Step::ENDS;
        vertices(scene, &mut paths, &[0], &hits, &mut lanes, &mut |_, s| {
            step = s
        });
        if let Some(light) = step.light {
            scene.occluded_many(&[light.ray], 0.0, &[light.t_max], &mut batch, &mut blocked);
            if !blocked[0] {
                paths[0].0.l += light.contribution;
            }
        }
        if !step.goes_on {
            *rng = paths[0].1.clone();
            return paths[0].0.l;
        }
    }
}

/// The vertices of the paths `alive` (indices into `paths`) at their
/// nearest hits `hits`: the light each finds there, then its light sample
/// and bounce, eight at a time in vector lanes where the surface is diffuse
/// ([`lanes`]) and one at a time elsewhere; `done(i, step)` for each, in no
/// fixed order. The one-path estimator and the wavefront both come through
/// here, so a vertex is shaded by the same code in both.
fn vertices(
    scene: &Scene,
    paths: &mut [(Path, SampleStream)],
    alive: &[u32],
    hits: &[Option<(u32, Interaction)>],
    lanes: &mut lanes::Diffuse,
    done: &mut impl FnMut(u32, Step),
) {
    for (&i, hit) in alive.iter().zip(hits) {
        let (path, rng) = &mut paths[i as usize];
        let Some(hit) = path.arrive(scene, hit.as_ref()) else {
            done(i, Step::ENDS);
            continue;
        };
        match lanes::lambert_albedo(scene, hit) {
            Some(albedo) => {
                lanes.push(scene, i, path, rng, hit, albedo);
                if lanes.is_full() {
                    lanes.flush(scene, paths, done);
                }
            }
            None => {
                let step = path.scatter(scene, hit, rng);
                done(i, step);
            }
        }
    }
    lanes.flush(scene, paths, done);
}

/// One path between two traces: the ray it is about to trace and what it
/// has gathered so far.
#[derive(Clone, Copy, Debug)]
struct Path {
    ray: Ray,
    /// Radiance gathered so far.
    l: Vec3,
    /// Throughput: what light arriving along `ray` is worth at the camera.
    beta: Vec3,
    prev: Option<Bounce>,
    depth: u32,
}

/// Light a vertex sampled, if nothing blocks the shadow ray.
#[derive(Clone, Copy, Debug)]
struct LightSample {
    ray: Ray,
    t_max: f32,
    /// What it adds to the path's radiance when unblocked (throughput
    /// included).
    contribution: Vec3,
}

/// What one vertex of a path did.
#[derive(Clone, Copy, Debug)]
struct Step {
    /// The light it sampled, waiting for its shadow ray.
    light: Option<LightSample>,
    /// Whether the path goes on along its new `ray`.
    goes_on: bool,
}

impl Step {
    /// The path ends here, with no light sample waiting.
    const ENDS: Step = Step {
        light: None,
        goes_on: false,
    };
}

impl Path {
    fn new(ray: Ray) -> Self {
        Self {
            ray,
            l: Vec3::ZERO,
            beta: Vec3::ONE,
            prev: None,
            depth: 0,
        }
    }

    /// The light the path finds at `hit` (an emitter it hits, or the
    /// environment it escapes to), weighted against light sampling; the
    /// hit, where the path goes on to scatter there (it does not after
    /// `max_depth` bounces or an escape).
    fn arrive<'h>(
        &mut self,
        scene: &Scene,
        hit: Option<&'h (u32, Interaction)>,
    ) -> Option<&'h Interaction> {
        let ray = self.ray;
        let Some((prim, hit)) = hit else {
            let le = scene.environment.radiance(ray.dir);
            if le != Vec3::ZERO {
                let pdf = scene.emitters.pdf_environment(&scene.environment, ray.dir);
                self.l += self.beta * le * hit_weight(scene, self.prev, pdf);
            }
            return None;
        };
        let le = emitted(scene, &ray, hit);
        if le != Vec3::ZERO {
            let pdf = self.prev.map_or(0.0, |b| {
                scene
                    .emitters
                    .pdf_hit(*prim, b.position, hit.position, hit.geometric_normal)
            });
            self.l += self.beta * le * hit_weight(scene, self.prev, pdf);
        }
        (self.depth < scene.max_depth).then_some(hit)
    }

    /// Next-event estimation and the bounce at `hit`, any material, one
    /// path at a time (the vertices that [`lanes`] does not take).
    fn scatter(&mut self, scene: &Scene, hit: &Interaction, rng: &mut SampleStream) -> Step {
        let ray = self.ray;
        let ends = Step::ENDS;
        let dimensions = CAMERA_DIMENSIONS + self.depth * BOUNCE_DIMENSIONS;
        rng.set_dimension(dimensions);
        self.depth += 1;

        let mat = &scene.materials[hit.material as usize];
        let wo = -ray.dir;
        let (ng, ns, p) = facing(scene, &ray, hit);
        let bsdf = Bsdf::new(mat, mat.albedo(hit.uv, hit.tint), ng, ns, wo);
        if bsdf.is_black() {
            return ends;
        }
        let light = if bsdf.has_non_delta() {
            direct(scene, hit, &bsdf, ng, p, rng).map(|(ray, t_max, d)| LightSample {
                ray,
                t_max,
                contribution: self.beta * d,
            })
        } else {
            None
        };
        let stop = Step {
            light,
            goes_on: false,
        };
        rng.set_dimension(dimensions + 2);
        let pick = rng.next_choice(bsdf.chooses_lobe());
        let Some(s) = bsdf.sample(pick, rng.next_2d()) else {
            return stop;
        };
        self.beta *= s.weight;
        if self.beta == Vec3::ZERO {
            return stop;
        }
        self.prev = Some(Bounce {
            position: hit.position,
            pdf: s.pdf,
            delta: s.delta,
        });
        self.ray = Ray::new(p, s.wi);
        Step {
            light,
            goes_on: self.survives(rng),
        }
    }

    /// Russian roulette after [`RR_DEPTH`] bounces (pbrt-v4 section
    /// 13.4.3): whether the path goes on, its throughput reweighted by the
    /// chance it had; drawn last of a bounce's numbers.
    fn survives(&mut self, rng: &mut SampleStream) -> bool {
        if self.depth >= RR_DEPTH {
            let m = self.beta.max_element();
            if m < 1.0 {
                let q = (1.0 - m).max(0.0);
                if rng.next_1d() < q {
                    return false;
                }
                self.beta /= 1.0 - q;
            }
        }
        true
    }
}

/// Next-event estimation at `hit`: one light sample, weighted against BSDF
/// sampling by the power heuristic (pbrt-v4 `PathIntegrator::SampleLd`).
/// Returns the shadow ray, the distance within which a blocker counts and
/// the light it brings if nothing blocks it; the caller traces the ray
/// (one at a time, or a batch of them).
fn direct(
    scene: &Scene,
    hit: &Interaction,
    bsdf: &Bsdf,
    ng: Vec3,
    p: Vec3,
    rng: &mut SampleStream,
) -> Option<(Ray, f32, Vec3)> {
    if scene.emitters.is_empty() {
        return None;
    }
    // The cosine that agrees with `bsdf.f` (see `Bsdf::shading_normal`).
    let ns = bsdf.shading_normal();
    let pick = rng.next_choice(scene.emitters.len() > 1);
    let u = rng.next_2d();
    let ls = scene
        .emitters
        .sample(&scene.environment, hit.position, pick, u)?;
    if scene.sampling == Sampling::Bsdf && ls.hittable {
        // BSDF sampling finds this light by itself.
        return None;
    }
    let (ray, t_max, cos) = match ls.point {
        Some(point) => {
            let q = shadow_query(scene, hit.position, p, ng, ns, point)?;
            (q.ray, q.t_max, q.cos)
        }
        None => {
            let cos = ns.dot(ls.wi);
            if cos <= 0.0 || ng.dot(ls.wi) <= 0.0 {
                return None;
            }
            (Ray::new(p, ls.wi), f32::INFINITY, cos)
        }
    };
    let (f, pdf) = bsdf.f_pdf(ls.wi);
    if f == Vec3::ZERO {
        return None;
    }
    let w = if ls.hittable && scene.sampling == Sampling::Mis {
        power_heuristic(ls.pdf, pdf)
    } else {
        1.0
    };
    Some((ray, t_max, f * ls.radiance * (cos * w / ls.pdf)))
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
            let (st, jitter, lens) = sobol_camera_stream(scene, x, y, s);
            (camera_ray(scene, x, y, jitter, lens), st)
        }
    }
}

/// Sample `s` of pixel `(x, y)`'s Sobol stream with its film offset and
/// lens point drawn, its first two dimensions (the order both the one-sample
/// and the eight-sample camera rays keep).
fn sobol_camera_stream(scene: &Scene, x: u32, y: u32, s: u32) -> (SampleStream, Vec2, Vec2) {
    let mut st = SampleStream::sobol(scene.seed, x, y, s);
    let jitter = st.next_2d();
    let lens = st.next_2d();
    (st, jitter, lens)
}

/// [`path_camera_sample`] of eight samples `(x, y, s)` at once, the rays
/// made together ([`camera_samples8`], [`camera_rays8`]): lane `l` is
/// `path_camera_sample(scene, x, y, s)` of `samples[l]` bit for bit.
fn path_camera_samples8(
    scene: &Scene,
    samples: &[(u32, u32, u32); PACKET],
) -> ([Ray; PACKET], [SampleStream; PACKET]) {
    match scene.sampler {
        SamplerKind::Independent => {
            let (rays, rngs) = camera_samples8(scene, samples);
            (rays, rngs.map(SampleStream::independent))
        }
        SamplerKind::Sobol => {
            // The film and lens draws of the eight streams made together
            // (`draw_2d8`), each what `sobol_camera_stream` draws.
            let mut film_draws = [Deferred2d::default(); PACKET];
            let mut lens_draws = [Deferred2d::default(); PACKET];
            let streams = std::array::from_fn(|l| {
                let (x, y, s) = samples[l];
                let mut st = SampleStream::sobol(scene.seed, x, y, s);
                film_draws[l] = st.defer_2d().expect("a Sobol stream");
                lens_draws[l] = st.defer_2d().expect("a Sobol stream");
                st
            });
            let columns =
                |d: [[f32; PACKET]; 2]| std::array::from_fn(|l| Vec2::new(d[0][l], d[1][l]));
            let jitter: [Vec2; PACKET] = columns(draw_2d8(&film_draws));
            let lens: [Vec2; PACKET] = columns(draw_2d8(&lens_draws));
            let pixels = samples.map(|(x, y, _)| (x, y));
            (camera_rays8(scene, &pixels, &jitter, &lens), streams)
        }
    }
}

/// The mean of the pixel's samples under the path integrator, each
/// sample's path traced on its own from its `path_camera_sample`: the
/// one-sample estimator, which [`tile`] equals bit for bit.
pub fn pixel(scene: &Scene, x: u32, y: u32) -> Vec3 {
    let mut sum = Vec3::ZERO;
    for s in 0..scene.spp {
        let (ray, mut rng) = path_camera_sample(scene, x, y, s);
        sum += radiance(scene, &ray, &mut rng);
    }
    sum / scene.spp as f32
}

/// Paths a wavefront holds at once: enough for full packets through the
/// batch queries, few enough that their states (about 100 bytes each)
/// stay in the core's caches between stages.
const WAVE: usize = 2048;

/// The buffers of [`tile`], reused from tile to tile of a thread.
#[derive(Default)]
pub struct WaveScratch {
    batch: Batch,
    paths: Vec<(Path, SampleStream)>,
    /// Indices into `paths` of the paths still alive (the queue stays in
    /// place: paths are not moved between stages).
    alive: Vec<u32>,
    next: Vec<u32>,
    rays: Vec<Ray>,
    t_max: Vec<f32>,
    hits: Vec<Option<(u32, Interaction)>>,
    /// Shadow rays of the stage, their ranges, owners and light.
    shadow_rays: Vec<Ray>,
    shadow_t_max: Vec<f32>,
    shadow_owner: Vec<(u32, Vec3)>,
    blocked: Vec<bool>,
    /// Each sample's radiance, pixel-major.
    samples: Vec<Vec3>,
    /// Diffuse vertices waiting for their lanes.
    lanes: lanes::Diffuse,
}

/// The path-traced estimate of each pixel of `pixels` (in that order, onto
/// `out`), every sample of them traced as one wavefront (the module docs):
/// the same values, bit for bit, as [`pixel`] for each.
pub fn tile(scene: &Scene, pixels: &[(u32, u32)], w: &mut WaveScratch, out: &mut Vec<Vec3>) {
    let spp = scene.spp as usize;
    let total = pixels.len() * spp;
    w.samples.clear();
    w.samples.resize(total, Vec3::ZERO);
    for first in (0..total).step_by(WAVE) {
        let ids = first..(first + WAVE).min(total);
        w.paths.clear();
        // The camera rays eight at a time; a last short packet repeats its
        // last sample and keeps only its own.
        for k0 in ids.clone().step_by(PACKET) {
            let n = (ids.end - k0).min(PACKET);
            let (rays, streams) = path_camera_samples8(
                scene,
                &std::array::from_fn(|l| {
                    let id = k0 + l.min(n - 1);
                    let (x, y) = pixels[id / spp];
                    (x, y, (id % spp) as u32)
                }),
            );
            for (ray, st) in rays.into_iter().zip(streams).take(n) {
                w.paths.push((Path::new(ray), st));
            }
        }
        w.alive.clear();
        w.alive.extend(0..w.paths.len() as u32);
        while !w.alive.is_empty() {
            w.rays.clear();
            w.rays
                .extend(w.alive.iter().map(|&i| w.paths[i as usize].0.ray));
            w.t_max.clear();
            w.t_max.resize(w.rays.len(), f32::INFINITY);
            scene.intersect_many(&w.rays, 0.0, &w.t_max, &mut w.batch, &mut w.hits);
            w.shadow_rays.clear();
            w.shadow_t_max.clear();
            w.shadow_owner.clear();
            w.next.clear();
            let (shadow_rays, shadow_t_max, shadow_owner, next) = (
                &mut w.shadow_rays,
                &mut w.shadow_t_max,
                &mut w.shadow_owner,
                &mut w.next,
            );
            vertices(
                scene,
                &mut w.paths,
                &w.alive,
                &w.hits,
                &mut w.lanes,
                &mut |i, step| {
                    if let Some(light) = step.light {
                        shadow_rays.push(light.ray);
                        shadow_t_max.push(light.t_max);
                        shadow_owner.push((i, light.contribution));
                    }
                    if step.goes_on {
                        next.push(i);
                    }
                },
            );
            scene.occluded_many(
                &w.shadow_rays,
                0.0,
                &w.shadow_t_max,
                &mut w.batch,
                &mut w.blocked,
            );
            for (&(i, light), &blocked) in w.shadow_owner.iter().zip(&w.blocked) {
                if !blocked {
                    w.paths[i as usize].0.l += light;
                }
            }
            std::mem::swap(&mut w.alive, &mut w.next);
        }
        for (id, (path, _)) in ids.zip(&w.paths) {
            w.samples[id] = if path.l.is_finite() {
                path.l
            } else {
                Vec3::ZERO
            };
        }
    }
    for samples in w.samples.chunks_exact(spp) {
        let sum = samples.iter().fold(Vec3::ZERO, |sum, &l| sum + l);
        out.push(sum / scene.spp as f32);
    }
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
