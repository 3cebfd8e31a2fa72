//! The diffuse vertices of eight paths at once, as columns in vector lanes.
//!
//! Most vertices of most scenes are Lambertian surfaces lit by area lights,
//! and one at a time each costs a long dependent chain of square roots and
//! divisions: the light's direction and distance, the shadow ray's direction
//! and reciprocals, the cosine-weighted bounce's frame and its ray (pbrt-v4's
//! wavefront integrator runs each of these stages over all the paths at
//! once for the same reason; Laine, Karras and Aila 2013, "Megakernels
//! considered harmful"). Here a round's diffuse vertices are gathered eight
//! at a time into columns ([`Diffuse`]), each path's numbers drawn from its
//! own stream in [`super::BOUNCE_DIMENSIONS`]' order as the one-vertex code
//! draws them (Sobol points put off and drawn for the eight lanes at once,
//! [`draw_2d8`]), and next-event estimation (one quad light by power, its
//! point by area, the power heuristic: Veach 1997, section 9.2.4) and the
//! cosine-weighted bounce (Malley's method through Shirley and Chiu's
//! concentric map, pbrt-v4 section A.5.3; the frame of Duff et al. 2017)
//! run as one loop over the lanes, which the compiler turns into vector
//! instructions.
//!
//! A path's last bounce (its next vertex would be past `max_depth`, where
//! only the light it hits would count) takes its direct light from light
//! sampling alone, with weight 1, and the path ends there: where every
//! emitting surface is in the light list ([`Emitters::complete`]), light
//! sampling alone is unbiased (Veach 1997, section 9.2), and for a diffuse
//! surface the power heuristic gave it nearly all the weight anyway, so the
//! ray that BSDF sampling would trace to look for that light is saved.
//!
//! [`Emitters::complete`]: crate::shading::emitters::Emitters::complete
//!
//! Which vertices go here ([`lambert_albedo`]): a material that reflects by
//! its diffuse colour alone, under multiple importance sampling, in a scene
//! whose lights are all quads. Every other vertex is shaded one at a time by
//! `Path::scatter`. A path's vertex is shaded the same way whatever else is in
//! its lanes (each lane's arithmetic is its own), and the one-path estimator
//! goes through the same code, so the wavefront's image stays the one-path
//! estimator's bit for bit.

use super::{
    power_heuristic, Bounce, LightSample, Path, Step, BOUNCE_DIMENSIONS, CAMERA_DIMENSIONS,
};
use crate::geometry::{Ray, PACKET};
use crate::scene::{Interaction, Scene};
use crate::settings::Sampling;
use crate::shading::sampler::{draw_2d8, Deferred2d, SampleStream};
use glam::Vec3;
use std::f32::consts::{FRAC_1_PI, FRAC_PI_4};

/// One value per lane.
type Col = [f32; PACKET];
/// A vector per lane, one column per component.
type Col3 = [Col; 3];

/// The albedo of the surface at `hit` where its vertex can be shaded in
/// lanes: its material reflects by its (textured) diffuse colour alone, a
/// colour that is finite, not negative and not black; the scene samples by
/// multiple importance; and every light is a quad. `None` sends the vertex
/// to the one-vertex code, which handles every case.
pub(super) fn lambert_albedo(scene: &Scene, hit: &Interaction) -> Option<Vec3> {
    if scene.sampling != Sampling::Mis || !scene.emitters.quads_only() {
        return None;
    }
    let mat = &scene.materials[hit.material as usize];
    let diffuse_only =
        (mat.shininess <= 0.0 || mat.specular == Vec3::ZERO) && mat.reflect == Vec3::ZERO;
    if !diffuse_only {
        return None;
    }
    let albedo = mat.albedo(hit.uv, hit.tint);
    (albedo.is_finite() && albedo.min_element() >= 0.0 && albedo.element_sum() > 0.0)
        .then_some(albedo)
}

/// Up to eight diffuse vertices waiting as columns, with their paths'
/// numbers already drawn.
#[derive(Default)]
pub(super) struct Diffuse {
    /// Lanes in use.
    n: usize,
    /// Each lane's path: an index into the caller's paths.
    owner: [u32; PACKET],
    /// The hit's world position, its normals as the shape gives them, the
    /// ray's direction, the albedo and the path's throughput.
    position: Col3,
    ng: Col3,
    ns: Col3,
    dir: Col3,
    albedo: Col3,
    beta: Col3,
    /// The chosen light: its corner, edges, normal, area, radiance, whether
    /// it emits from both sides and whether rays can hit it, and the
    /// probability it was chosen with (0: no light sample).
    corner: Col3,
    edge_u: Col3,
    edge_v: Col3,
    normal: Col3,
    area: Col,
    radiance: Col3,
    two_sided: [bool; PACKET],
    /// Whether the light sample is weighted against BSDF sampling (the
    /// light is one rays can hit, and the path goes on to look for it).
    weighed: [bool; PACKET],
    /// The path's last bounce: its next vertex could only add the light
    /// it hits, so it takes that light from light sampling alone.
    last: [bool; PACKET],
    pmf: Col,
    /// The light's point and the bounce's direction, each a 2D sample.
    u_light: [Col; 2],
    u_bounce: [Col; 2],
    /// Where those are Sobol points, their draws put off to be made for
    /// all the lanes at once ([`draw_2d8`]).
    sobol: [bool; PACKET],
    light_draw: [Deferred2d; PACKET],
    bounce_draw: [Deferred2d; PACKET],
}

/// What the lanes work out for each vertex.
#[derive(Default)]
struct Shaded {
    /// The shadow ray (origin, unit direction, reciprocals), its range and
    /// the light it brings; `lit` false where no ray is cast.
    lit: [bool; PACKET],
    origin: Col3,
    to_light: Col3,
    to_light_inv: Col3,
    t_max: Col,
    contribution: Col3,
    /// The bounce: taken (above both the shading and the geometric
    /// surface, the throughput not black), its direction and reciprocals,
    /// its density and the path's new throughput.
    bounces: [bool; PACKET],
    wi: Col3,
    wi_inv: Col3,
    pdf: Col,
    beta: Col3,
}

impl Diffuse {
    /// Whether a lane is free.
    pub(super) fn is_full(&self) -> bool {
        self.n == PACKET
    }

    /// Takes the vertex of path `owner` at `hit`, whose surface reflects
    /// `albedo` ([`lambert_albedo`]), drawing its numbers from `rng` in the
    /// order of the one-vertex code (the light's choice and point, the
    /// lobe's choice, which a single lobe spends without drawing, and the
    /// direction; Russian roulette's comes after the lanes).
    pub(super) fn push(
        &mut self,
        scene: &Scene,
        owner: u32,
        path: &mut Path,
        rng: &mut SampleStream,
        hit: &Interaction,
        albedo: Vec3,
    ) {
        let l = self.n;
        self.n += 1;
        let dimensions = CAMERA_DIMENSIONS + path.depth * BOUNCE_DIMENSIONS;
        rng.set_dimension(dimensions);
        path.depth += 1;
        let last = path.depth == scene.max_depth && scene.emitters.complete();
        self.last[l] = last;
        // Sobol draws are put off for the lanes to make together; a stream
        // of independent numbers draws in its turn.
        let pick = rng.next_choice(scene.emitters.len() > 1);
        let light = rng.defer_2d().ok_or_else(|| rng.next_2d());
        rng.set_dimension(dimensions + 2);
        rng.next_choice(false);
        let bounce = rng.defer_2d().ok_or_else(|| rng.next_2d());
        self.sobol[l] = light.is_ok();
        for (draw, put_off, u) in [
            (light, &mut self.light_draw, &mut self.u_light),
            (bounce, &mut self.bounce_draw, &mut self.u_bounce),
        ] {
            match draw {
                Ok(d) => put_off[l] = d,
                Err(v) => [u[0][l], u[1][l]] = [v.x, v.y],
            }
        }

        self.owner[l] = owner;
        set(&mut self.position, l, hit.position);
        set(&mut self.ng, l, hit.geometric_normal);
        set(&mut self.ns, l, hit.shading_normal);
        set(&mut self.dir, l, path.ray.dir);
        set(&mut self.albedo, l, albedo);
        set(&mut self.beta, l, path.beta);
        match scene.emitters.pick_quad(pick) {
            Some((light, pmf)) => {
                set(&mut self.corner, l, light.quad.origin);
                set(&mut self.edge_u, l, light.quad.edge_u);
                set(&mut self.edge_v, l, light.quad.edge_v);
                set(&mut self.normal, l, light.quad.normal);
                self.area[l] = light.quad.area();
                set(&mut self.radiance, l, light.radiance);
                self.two_sided[l] = light.two_sided;
                self.weighed[l] = light.visible && !last;
                self.pmf[l] = pmf;
            }
            None => {
                // No light sample; finite values keep the lane quiet.
                set(&mut self.corner, l, hit.position + Vec3::Y);
                set(&mut self.normal, l, Vec3::Y);
                set(&mut self.edge_u, l, Vec3::ZERO);
                set(&mut self.edge_v, l, Vec3::ZERO);
                self.area[l] = 1.0;
                set(&mut self.radiance, l, Vec3::ZERO);
                self.pmf[l] = 0.0;
            }
        }
    }

    /// Shades the waiting vertices and hands each path's [`Step`] to
    /// `done` (the paths updated in `paths`, Russian roulette drawn), then
    /// frees the lanes.
    pub(super) fn flush(
        &mut self,
        scene: &Scene,
        paths: &mut [(Path, SampleStream)],
        done: &mut impl FnMut(u32, Step),
    ) {
        if self.n == 0 {
            return;
        }
        // Lanes past `n` hold an earlier vertex or zeros: whatever they
        // compute is not read.
        if self.sobol[..self.n].contains(&true) {
            let (light, bounce) = (draw_2d8(&self.light_draw), draw_2d8(&self.bounce_draw));
            for l in (0..self.n).filter(|&l| self.sobol[l]) {
                for c in 0..2 {
                    self.u_light[c][l] = light[c][l];
                    self.u_bounce[c][l] = bounce[c][l];
                }
            }
        }
        let s = shade(self, scene.epsilon);
        for l in 0..self.n {
            let i = self.owner[l];
            let (path, rng) = &mut paths[i as usize];
            let light = s.lit[l].then(|| LightSample {
                ray: Ray {
                    origin: get(&s.origin, l),
                    dir: get(&s.to_light, l),
                    inv_dir: get(&s.to_light_inv, l),
                },
                t_max: s.t_max[l],
                contribution: get(&s.contribution, l),
            });
            let goes_on = !self.last[l] && s.bounces[l] && {
                path.beta = get(&s.beta, l);
                path.prev = Some(Bounce {
                    position: get(&self.position, l),
                    pdf: s.pdf[l],
                    delta: false,
                });
                path.ray = Ray {
                    origin: get(&s.origin, l),
                    dir: get(&s.wi, l),
                    inv_dir: get(&s.wi_inv, l),
                };
                path.survives(rng)
            };
            done(i, Step { light, goes_on });
        }
        self.n = 0;
    }
}

/// Lane `l` of a column vector.
#[inline]
fn get(c: &Col3, l: usize) -> Vec3 {
    Vec3::new(c[0][l], c[1][l], c[2][l])
}

/// Sets lane `l` of a column vector.
#[inline]
fn set(c: &mut Col3, l: usize, v: Vec3) {
    [c[0][l], c[1][l], c[2][l]] = [v.x, v.y, v.z];
}

/// `sin` and `cos` of `phi` in `[-pi/4, pi/4]` by their Taylor series to
/// the ninth and tenth power (the first term left out is under 3.5e-7 of
/// the result there, a few single-precision rounding steps): branch-free,
/// so that eight lanes take it together where the C library's `sincosf`
/// is a call per lane.
#[inline(always)]
fn sin_cos_quarter(phi: f32) -> (f32, f32) {
    let p2 = phi * phi;
    let s = phi
        * (1.0
            + p2 * (-1.0 / 6.0
                + p2 * (1.0 / 120.0 + p2 * (-1.0 / 5040.0 + p2 * (1.0 / 362_880.0)))));
    let c = 1.0
        + p2 * (-0.5
            + p2 * (1.0 / 24.0
                + p2 * (-1.0 / 720.0 + p2 * (1.0 / 40_320.0 + p2 * (-1.0 / 3_628_800.0)))));
    (s, c)
}

/// The lanes' arithmetic: every branch a select, so that the loop runs in
/// vector instructions.
fn shade(d: &Diffuse, epsilon: f32) -> Shaded {
    let mut s = Shaded::default();
    for l in 0..PACKET {
        let v = |c: &Col3| Vec3::new(c[0][l], c[1][l], c[2][l]);
        let (position, dir) = (v(&d.position), v(&d.dir));
        // The normals on the viewer's side: the geometric one and the
        // shading one with it, then the shading one by its own plane
        // (`whitted::facing`, `bsdf::viewer_side`).
        let flip = if d.ng[0][l] * dir.x + d.ng[1][l] * dir.y + d.ng[2][l] * dir.z > 0.0 {
            -1.0
        } else {
            1.0
        };
        let ng = v(&d.ng) * flip;
        let ns = v(&d.ns) * flip;
        let ns = if ns.dot(-dir) < 0.0 { -ns } else { ns };
        let p = position + ng * epsilon;
        let f = v(&d.albedo) * FRAC_1_PI;
        let beta = v(&d.beta);

        // Next-event estimation: the light's point, chosen by area.
        let point = v(&d.corner) + d.u_light[0][l] * v(&d.edge_u) + d.u_light[1][l] * v(&d.edge_v);
        let to = point - position;
        let r2 = to.length_squared();
        let wi = to / r2.sqrt();
        let cos_at_light = v(&d.normal).dot(wi);
        let cos_l = if d.two_sided[l] {
            cos_at_light.abs()
        } else {
            -cos_at_light
        };
        let light_pdf = d.pmf[l] * r2 / (cos_l * d.area[l]);
        let cos = ns.dot(wi);
        let ray = point - p;
        let dist = ray.length();
        let to_light = ray / dist;
        let w = if d.weighed[l] {
            power_heuristic(light_pdf, cos * FRAC_1_PI)
        } else {
            1.0
        };
        let contribution = beta * (f * v(&d.radiance) * (cos * w / light_pdf));
        s.lit[l] = d.pmf[l] > 0.0
            && r2.is_finite()
            && r2 > 0.0
            && cos_l > 0.0
            && cos > 0.0
            && ng.dot(wi) > 0.0;
        let inv = Vec3::ONE / to_light;
        let t_max = dist * (1.0 - 1e-4) - epsilon;
        for c in 0..3 {
            s.origin[c][l] = p[c];
            s.to_light[c][l] = to_light[c];
            s.to_light_inv[c][l] = inv[c];
            s.contribution[c][l] = contribution[c];
        }
        s.t_max[l] = t_max;

        // The bounce: a cosine-weighted direction about the shading
        // normal, by the concentric map of the square onto the disk.
        let (ox, oy) = (2.0 * d.u_bounce[0][l] - 1.0, 2.0 * d.u_bounce[1][l] - 1.0);
        let x_wider = ox.abs() > oy.abs();
        let (r, num, den) = if x_wider { (ox, oy, ox) } else { (oy, ox, oy) };
        let den = if den == 0.0 { 1.0 } else { den };
        let (sin, cos_phi) = sin_cos_quarter(FRAC_PI_4 * (num / den));
        // Where y is wider the angle is pi/2 - phi: cos and sin swap.
        let (dx, dy) = if x_wider {
            (r * cos_phi, r * sin)
        } else {
            (r * sin, r * cos_phi)
        };
        let dz = (1.0 - dx * dx - dy * dy).max(0.0).sqrt();
        let sign = 1.0f32.copysign(ns.z);
        let a = -1.0 / (sign + ns.z);
        let b = ns.x * ns.y * a;
        let t = Vec3::new(1.0 + sign * ns.x * ns.x * a, sign * b, -sign * ns.x);
        let bt = Vec3::new(b, sign + ns.y * ns.y * a, -ns.y);
        let w = t * dx + bt * dy + ns * dz;
        let wi = w / w.length();
        let cos = ns.dot(wi);
        let pdf = cos * FRAC_1_PI;
        // f cos / pdf of the cosine-weighted Lambert lobe is its albedo.
        let beta = beta * v(&d.albedo);
        s.bounces[l] = cos > 0.0 && ng.dot(wi) > 0.0 && pdf > 0.0 && beta != Vec3::ZERO;
        let inv = Vec3::ONE / wi;
        for c in 0..3 {
            s.wi[c][l] = wi[c];
            s.wi_inv[c][l] = inv[c];
            s.beta[c][l] = beta[c];
        }
        s.pdf[l] = pdf;
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::material::Material;
    use crate::shading::bsdf::Bsdf;
    use displace_core::random::SplitMix64;
    use glam::Vec2;

    #[test]
    fn sin_cos_quarter_is_within_rounding() {
        for k in 0..=20_000 {
            let phi = -FRAC_PI_4 + FRAC_PI_4 * 2.0 * k as f32 / 20_000.0;
            let (s, c) = sin_cos_quarter(phi);
            let x = phi as f64;
            assert!((s as f64 - x.sin()).abs() < 2.5e-7, "sin {phi}");
            assert!((c as f64 - x.cos()).abs() < 2.5e-7, "cos {phi}");
        }
    }

    fn unit(rng: &mut SplitMix64) -> Vec3 {
        loop {
            let v = Vec3::new(
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
                rng.range(-1.0, 1.0),
            );
            if (0.01..1.0).contains(&v.length_squared()) {
                return v.normalize();
            }
        }
    }

    fn close(a: Vec3, b: Vec3, tol: f32) -> bool {
        (a - b).abs().max_element() <= tol * (1.0 + b.abs().max_element())
    }

    /// Each lane against the one-vertex code: the bounce against
    /// [`Bsdf::sample`] of a Lambert material, next-event estimation against
    /// its formulas in double precision (pbrt-v4 `SampleLd` with an area
    /// light sampled by area), on random hits, normals, rays and lights:
    /// the suite's fixed seed (`PROPTEST_RNG_SEED`), or `scripts/explore.sh`'s
    /// fresh one and more packets.
    #[test]
    fn lanes_are_the_one_vertex_shading() {
        let seed = std::env::var("PROPTEST_RNG_SEED")
            .ok()
            .and_then(|s| s.parse().ok())
            .unwrap_or(7);
        let mut rng = SplitMix64::new(seed);
        let epsilon = 1e-3;
        let (mut bounces, mut lit) = (0, 0);
        let packets = displace_core::random::property_cases(2000);
        for _ in 0..packets {
            let mut d = Diffuse {
                n: PACKET,
                ..Diffuse::default()
            };
            for l in 0..PACKET {
                let ng = unit(&mut rng);
                // A shading normal within about 35 degrees of the geometric one.
                let ns = (ng + 0.4 * unit(&mut rng)).normalize();
                let position = Vec3::new(
                    rng.range(-5.0, 5.0),
                    rng.range(-5.0, 5.0),
                    rng.range(-5.0, 5.0),
                );
                set(&mut d.position, l, position);
                set(&mut d.ng, l, ng);
                set(&mut d.ns, l, ns);
                set(&mut d.dir, l, unit(&mut rng));
                set(
                    &mut d.albedo,
                    l,
                    Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * 0.9 + 0.05,
                );
                set(&mut d.beta, l, Vec3::splat(rng.range(0.1, 2.0)));
                set(&mut d.corner, l, position + 6.0 * unit(&mut rng));
                set(&mut d.edge_u, l, 2.0 * unit(&mut rng));
                let v = unit(&mut rng);
                set(&mut d.edge_v, l, 1.5 * v);
                let n = get(&d.edge_u, l).cross(get(&d.edge_v, l));
                set(&mut d.normal, l, n.normalize());
                d.area[l] = n.length();
                set(&mut d.radiance, l, Vec3::new(3.0, 2.0, 1.0));
                d.two_sided[l] = rng.next_f32() < 0.5;
                d.weighed[l] = rng.next_f32() < 0.7;
                d.pmf[l] = if rng.next_f32() < 0.1 {
                    0.0
                } else {
                    rng.range(0.2, 1.0)
                };
                d.u_light = d.u_light.map(|mut c| {
                    c[l] = rng.next_f32();
                    c
                });
                d.u_bounce = d.u_bounce.map(|mut c| {
                    c[l] = rng.next_f32();
                    c
                });
            }
            let s = shade(&d, epsilon);
            for l in 0..PACKET {
                let dir = get(&d.dir, l);
                let (mut ng, mut ns) = (get(&d.ng, l), get(&d.ns, l));
                if ng.dot(dir) > 0.0 {
                    (ng, ns) = (-ng, -ns);
                }
                let albedo = get(&d.albedo, l);
                let mat = Material {
                    diffuse: albedo,
                    ..Material::default()
                };
                let bsdf = Bsdf::new(&mat, albedo, ng, ns, -dir);
                let ns = bsdf.shading_normal();
                let p = get(&d.position, l) + ng * epsilon;
                let u = Vec2::new(d.u_bounce[0][l], d.u_bounce[1][l]);
                let want = bsdf.sample(0.0, u);
                let wi = get(&s.wi, l);
                // Rounding decides directions within a hair of either surface.
                if ns.dot(wi).abs() > 1e-4 && ng.dot(wi).abs() > 1e-4 {
                    assert_eq!(s.bounces[l], want.is_some(), "bounce taken");
                }
                if let (true, Some(want)) = (s.bounces[l], want) {
                    bounces += 1;
                    // Near the disk's rim the lift `sqrt(1 - r^2)` scales
                    // rounding in `r` by `1 / cos`: both codes' grazing
                    // directions are that far apart (found at cos 0.0099).
                    let tol = 2e-6 + 2e-7 / ns.dot(wi).max(1e-6);
                    assert!(close(wi, want.wi, tol), "{wi} {} u {u}", want.wi);
                    assert!((s.pdf[l] - want.pdf).abs() <= tol * (1.0 + want.pdf));
                    let beta = get(&d.beta, l) * want.weight;
                    assert!(close(get(&s.beta, l), beta, 2e-6));
                    assert!(close(get(&s.origin, l), p, 1e-6));
                    assert!(close(get(&s.wi_inv, l) * wi, Vec3::ONE, 1e-6));
                }

                // Next-event estimation in double precision.
                let f64v = |v: Vec3| v.as_dvec3();
                let (eu, ev) = (f64v(get(&d.edge_u, l)), f64v(get(&d.edge_v, l)));
                let point = f64v(get(&d.corner, l))
                    + d.u_light[0][l] as f64 * eu
                    + d.u_light[1][l] as f64 * ev;
                let to = point - f64v(get(&d.position, l));
                let r2 = to.length_squared();
                let wi = to / r2.sqrt();
                let cq = f64v(get(&d.normal, l)).dot(wi);
                let cos_l = if d.two_sided[l] { cq.abs() } else { -cq };
                let cos = f64v(ns).dot(wi);
                let on_edge =
                    cos_l.abs() < 1e-4 || cos.abs() < 1e-4 || f64v(ng).dot(wi).abs() < 1e-4;
                let want_lit = d.pmf[l] > 0.0 && cos_l > 0.0 && cos > 0.0 && f64v(ng).dot(wi) > 0.0;
                if !on_edge {
                    assert_eq!(s.lit[l], want_lit, "lit");
                }
                if !(s.lit[l] && want_lit) || on_edge {
                    continue;
                }
                lit += 1;
                let light_pdf = d.pmf[l] as f64 * r2 / (cos_l * d.area[l] as f64);
                let bsdf_pdf = cos / std::f64::consts::PI;
                let w = if d.weighed[l] {
                    light_pdf * light_pdf / (light_pdf * light_pdf + bsdf_pdf * bsdf_pdf)
                } else {
                    1.0
                };
                let c = f64v(get(&d.beta, l))
                    * f64v(albedo / std::f32::consts::PI)
                    * f64v(get(&d.radiance, l))
                    * (cos * w / light_pdf);
                let got = f64v(get(&s.contribution, l));
                assert!((got - c).abs().max_element() <= 1e-4 * (1.0 + c.abs().max_element()));
                let ray = point - f64v(p);
                let to_light = ray / ray.length();
                assert!((f64v(get(&s.to_light, l)) - to_light).abs().max_element() < 1e-5);
                let t_max = ray.length() * (1.0 - 1e-4) - epsilon as f64;
                assert!((s.t_max[l] as f64 - t_max).abs() < 1e-4 * (1.0 + t_max));
            }
        }
        // Both halves were exercised on most lanes.
        let lanes = packets as usize * PACKET;
        assert!(
            bounces > lanes * 3 / 8 && lit > lanes / 5,
            "{bounces} bounces, {lit} lit of {lanes}"
        );
    }
}
