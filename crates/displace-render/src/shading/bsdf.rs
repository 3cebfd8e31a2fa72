//! The scattering functions of the path integrator: every [`Material`] as a
//! sum of lobes, each importance sampled with a density that
//! [`Bsdf::pdf`] evaluates, so that light sampling and BSDF sampling can
//! be combined by multiple importance sampling (Veach 1997, ch. 9; pbrt-v4
//! sections 9.1-9.3).
//!
//! The lobes, each weighted by its material colour:
//!
//! - **Lambert** (`color`, `diffuse`): `f = albedo / pi`, sampled by the
//!   cosine (Malley's method, pbrt-v4 section A.5.3).
//! - **Blinn-Phong** (`phong`'s `specular`, `shininess` `n`): `f = specular
//!   c(n) cos^n(theta_h)`, sampled by the half vector with density
//!   `(n + 1) / (2 pi) cos^n(theta_h)` and the `1 / (4 wo.h)` change of
//!   variables (Walter et al. 2007, eq. 14; pbrt-v3 section 14.1.1). The
//!   normalisation `c(n) = (n + 2)(n + 4) / (8 pi (2^(-n/2) + n))` is the
//!   exact one of the lobe with its cosine (Akenine-Möller et al., RTR4
//!   section 9.8; Sloan and Hoffman): straight on, the lobe reflects
//!   `specular` exactly and less at any other angle. The Whitted integrator
//!   keeps the ray-tracer paper's approximate `(n + 8) / (8 pi)`, which reflects up to
//!   6.7% more than it receives (at `n = 16`), so a `phong` highlight is up
//!   to that much dimmer under `path`.
//! - **Glossy** (`glossy`'s `color`, `roughness`): the BRDF that the ray-tracer paper's
//!   distributed reflection ray estimates (Cook et al. 1984): the Phong lobe
//!   of exponent `e = 2 / roughness^2 - 2` about the mirror direction `r`,
//!   `f cos(theta_i) = color (e + 1) / (2 pi) cos^e(r.wi)`, sampled exactly by
//!   its density, so a sample's weight is `color`. It reflects at most
//!   `color` (all of it straight on, less where the lobe dips under the
//!   surface), and both integrators render a glossy surface alike.
//! - **Mirror** (`mirror`'s `color`): a delta lobe, `f = color delta(wi -
//!   r) / cos(theta_i)`, never found by light sampling.
//!
//! [`Bsdf::sample`] picks one lobe in proportion to the mean of its colour
//! and reports the density of the whole non-delta mixture, as pbrt-v3's
//! `BSDF::Sample_f` does (section 14.1.6).
//!
//! Shading and geometric normals (pbrt-v3 section 9.1, Veach 1997 section
//! 5.3): the geometric normal is turned to the viewer's side of the
//! surface, and the shading normal to the viewer's side of its own plane
//! ([`viewer_side`]); a direction counts as reflected only when it lies on
//! the viewer's side of both (no light from under a bump leaks through its
//! interpolated normal, and none from behind the shading plane reaches a
//! viewer in front of it), and the cosine is the shading one.

use crate::geometry::{basis, reflect};
use crate::material::Material;
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI, TAU};

/// Exact normalisation of the Blinn-Phong lobe `cos^n(theta_h)` with the
/// receiver's cosine: its directional albedo straight on is 1
/// (RTR4 section 9.8).
pub fn blinn_phong_norm(n: f32) -> f32 {
    (n + 2.0) * (n + 4.0) / (8.0 * PI * ((-n / 2.0).exp2() + n))
}

/// The Phong exponent of a glossy roughness (Walter et al. 2007's
/// Beckmann-Phong correspondence, as the Whitted integrator uses it).
pub fn glossy_exponent(roughness: f32) -> f32 {
    (2.0 / (roughness * roughness) - 2.0).max(0.0)
}

/// The shading normal `ns` turned to the side of its plane that `wo` (the
/// unit direction to the viewer) lies on.
///
/// Why: reflection happens in the shading frame, so the viewer and the
/// light must lie on one side of the shading plane (pbrt-v4 section 9.1.2,
/// `SameHemisphere`; Mitsuba 3's `twosided` adapter decides the side by
/// the shading frame too). Turning `ns` by the geometric side alone lit a
/// viewer at a grazing angle below a steeply interpolated normal (the far
/// edge of a bump's top, its normal tilted away) from lights behind that
/// plane, a rim of light neither renderer shows.
#[inline]
pub fn viewer_side(ns: Vec3, wo: Vec3) -> Vec3 {
    if ns.dot(wo) < 0.0 {
        -ns
    } else {
        ns
    }
}

/// The scattering function at one hit, in world space.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    /// Shading normal, on the side of `wo`.
    ns: Vec3,
    /// Geometric normal, on the side of `wo`.
    ng: Vec3,
    /// Unit direction towards the viewer.
    wo: Vec3,
    diffuse: Vec3,
    specular: Vec3,
    shininess: f32,
    reflect: Vec3,
    /// Phong exponent of the glossy lobe; `None` for a perfect mirror.
    exponent: Option<f32>,
    /// The mirror direction of `wo` about `ns`.
    r: Vec3,
    /// Lobe selection probabilities: diffuse, Blinn-Phong, reflection.
    p: [f32; 3],
}

/// A sampled direction.
#[derive(Clone, Copy, Debug)]
pub struct BsdfSample {
    /// Unit direction the light arrives from.
    pub wi: Vec3,
    /// `f cos(theta_i) / pdf`: what the path's throughput is multiplied by.
    pub weight: Vec3,
    /// Solid-angle density of the non-delta mixture at `wi` (for a delta
    /// lobe, the probability of choosing it).
    pub pdf: f32,
    /// Whether the mirror's delta lobe produced it.
    pub delta: bool,
}

impl Bsdf {
    /// The material `mat` at a hit with the given albedo (colour times
    /// textures), geometric normal `ng` turned towards the viewer, shading
    /// normal `ns` (turned here by [`viewer_side`]) and `wo` the unit
    /// direction to the viewer.
    pub fn new(mat: &Material, albedo: Vec3, ng: Vec3, ns: Vec3, wo: Vec3) -> Self {
        let ns = viewer_side(ns, wo);
        let specular = if mat.shininess > 0.0 {
            mat.specular
        } else {
            Vec3::ZERO
        };
        let weights = [
            albedo.element_sum(),
            specular.element_sum(),
            mat.reflect.element_sum(),
        ];
        let total: f32 = weights.iter().sum();
        let p = if total > 0.0 {
            weights.map(|w| w / total)
        } else {
            [0.0; 3]
        };
        Self {
            ns,
            ng,
            wo,
            diffuse: albedo,
            specular,
            shininess: mat.shininess,
            reflect: mat.reflect,
            exponent: (mat.roughness > 0.0).then(|| glossy_exponent(mat.roughness)),
            r: reflect(-wo, ns),
            p,
        }
    }

    /// The shading normal on the viewer's side of its plane: the normal
    /// whose cosine light sampling must use to agree with [`Bsdf::f`].
    pub fn shading_normal(&self) -> Vec3 {
        self.ns
    }

    /// Whether it reflects nothing (the path ends here).
    pub fn is_black(&self) -> bool {
        self.p == [0.0; 3]
    }

    /// Whether [`Bsdf::sample`] has a lobe to choose (more than one lobe
    /// with a positive probability); where not, its `pick` is unused.
    pub fn chooses_lobe(&self) -> bool {
        self.p.iter().filter(|&&p| p > 0.0).count() > 1
    }

    /// Whether light sampling can find any of its lobes (it is not a pure
    /// mirror).
    pub fn has_non_delta(&self) -> bool {
        self.p[0] > 0.0 || self.p[1] > 0.0 || (self.p[2] > 0.0 && self.exponent.is_some())
    }

    /// `ns . wi` where `wi` lies above both the shading and the geometric
    /// surface, else `None`.
    #[inline]
    fn cosine(&self, wi: Vec3) -> Option<f32> {
        let c = self.ns.dot(wi);
        (c > 0.0 && self.ng.dot(wi) > 0.0).then_some(c)
    }

    fn glossy_pdf(&self, e: f32, wi: Vec3) -> f32 {
        let c = self.r.dot(wi);
        if c <= 0.0 {
            0.0
        } else {
            (e + 1.0) / TAU * c.powf(e)
        }
    }

    fn blinn_pdf(&self, wi: Vec3) -> f32 {
        let h = (self.wo + wi).normalize_or_zero();
        let (nh, oh) = (self.ns.dot(h), self.wo.dot(h));
        if nh <= 0.0 || oh <= 0.0 {
            return 0.0;
        }
        (self.shininess + 1.0) / TAU * nh.powf(self.shininess) / (4.0 * oh)
    }

    /// [`Bsdf::f`] and [`Bsdf::pdf`] at `wi` together, bit for bit each
    /// one's own answer: the cosine, the Blinn-Phong half vector and its
    /// power, and the glossy lobe's power are worked out once for both
    /// (next-event estimation's multiple importance weight needs both at
    /// the light's direction, pbrt-v4 `PathIntegrator::SampleLd`; BSDF
    /// sampling needs both at the sampled one).
    pub fn f_pdf(&self, wi: Vec3) -> (Vec3, f32) {
        match self.cosine(wi) {
            Some(cos) => self.f_pdf_at(wi, cos),
            None => (Vec3::ZERO, 0.0),
        }
    }

    /// [`Bsdf::f_pdf`] at a `wi` whose [`Bsdf::cosine`] is `cos`: the sums
    /// of [`Bsdf::f`] and [`Bsdf::pdf`], term by term in their order.
    #[inline]
    fn f_pdf_at(&self, wi: Vec3, cos: f32) -> (Vec3, f32) {
        let mut f = self.diffuse * FRAC_1_PI;
        let mut pdf = self.p[0] * cos * FRAC_1_PI;
        if self.p[1] > 0.0 {
            let h = (self.wo + wi).normalize_or_zero();
            let nh = self.ns.dot(h);
            // `nh.max(0)` to the power is `nh`'s own power wherever the
            // density uses it (`nh > 0`).
            let power = nh.max(0.0).powf(self.shininess);
            f += self.specular * (blinn_phong_norm(self.shininess) * power);
            let oh = self.wo.dot(h);
            let blinn = if nh <= 0.0 || oh <= 0.0 {
                0.0
            } else {
                (self.shininess + 1.0) / TAU * power / (4.0 * oh)
            };
            pdf += self.p[1] * blinn;
        }
        if let (Some(e), true) = (self.exponent, self.p[2] > 0.0) {
            let g = self.glossy_pdf(e, wi);
            f += self.reflect * (g / cos);
            pdf += self.p[2] * g;
        }
        (f, pdf)
    }

    /// `f(wo, wi)` of the non-delta lobes (the mirror's delta lobe is 0 at
    /// every direction it can be asked about).
    pub fn f(&self, wi: Vec3) -> Vec3 {
        let Some(cos) = self.cosine(wi) else {
            return Vec3::ZERO;
        };
        let mut f = self.diffuse * FRAC_1_PI;
        if self.p[1] > 0.0 {
            let h = (self.wo + wi).normalize_or_zero();
            let nh = self.ns.dot(h).max(0.0);
            f += self.specular * (blinn_phong_norm(self.shininess) * nh.powf(self.shininess));
        }
        if let (Some(e), true) = (self.exponent, self.p[2] > 0.0) {
            f += self.reflect * (self.glossy_pdf(e, wi) / cos);
        }
        f
    }

    /// Solid-angle density of [`Bsdf::sample`] at `wi` over its non-delta
    /// lobes; 0 where `f` is 0 for being under the surface.
    pub fn pdf(&self, wi: Vec3) -> f32 {
        let Some(cos) = self.cosine(wi) else {
            return 0.0;
        };
        let mut pdf = self.p[0] * cos * FRAC_1_PI;
        if self.p[1] > 0.0 {
            pdf += self.p[1] * self.blinn_pdf(wi);
        }
        if let (Some(e), true) = (self.exponent, self.p[2] > 0.0) {
            pdf += self.p[2] * self.glossy_pdf(e, wi);
        }
        pdf
    }

    /// Samples an incident direction from three uniform numbers: `pick`
    /// chooses the lobe, `u` the direction within it; `None` when the
    /// sample falls under the surface (it carries no light).
    pub fn sample(&self, pick: f32, u: Vec2) -> Option<BsdfSample> {
        let wi = if pick < self.p[0] {
            around(self.ns, cosine_hemisphere(u))
        } else if pick < self.p[0] + self.p[1] {
            let n = self.shininess;
            let cos_t = u.x.powf(1.0 / (n + 1.0));
            let h = around(self.ns, spherical(cos_t, TAU * u.y));
            let oh = self.wo.dot(h);
            if oh <= 0.0 {
                return None;
            }
            2.0 * oh * h - self.wo
        } else if self.p[2] > 0.0 {
            match self.exponent {
                None => {
                    // The mirror: only the geometric side matters, as for
                    // the Whitted integrator's reflection ray.
                    if self.ng.dot(self.r) <= 0.0 {
                        return None;
                    }
                    return Some(BsdfSample {
                        wi: self.r,
                        weight: self.reflect / self.p[2],
                        pdf: self.p[2],
                        delta: true,
                    });
                }
                Some(e) => {
                    let cos_t = u.x.powf(1.0 / (e + 1.0));
                    around(self.r, spherical(cos_t, TAU * u.y))
                }
            }
        } else {
            return None;
        };
        let cos = self.cosine(wi)?;
        let (f, pdf) = self.f_pdf_at(wi, cos);
        if pdf <= 0.0 {
            return None;
        }
        let weight = f * (cos / pdf);
        Some(BsdfSample {
            wi,
            weight,
            pdf,
            delta: false,
        })
    }
}

/// A unit vector at polar cosine `cos_t` and azimuth `phi` about +z.
#[inline]
fn spherical(cos_t: f32, phi: f32) -> Vec3 {
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    Vec3::new(sin_t * phi.cos(), sin_t * phi.sin(), cos_t)
}

/// Cosine-distributed direction about +z (Malley's method: a concentric
/// disk point lifted to the hemisphere).
#[inline]
fn cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = crate::shading::sampler::concentric_disk(u);
    Vec3::new(d.x, d.y, (1.0 - d.length_squared()).max(0.0).sqrt())
}

/// `local` (about +z) in the frame of unit `n`.
#[inline]
fn around(n: Vec3, local: Vec3) -> Vec3 {
    let (t, b) = basis(n);
    (t * local.x + b * local.y + n * local.z).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shading::sampler::Rng;

    fn material(kind: &str) -> Material {
        match kind {
            "lambert" => Material {
                diffuse: Vec3::splat(0.8),
                ..Material::default()
            },
            "phong" => Material {
                diffuse: Vec3::splat(0.3),
                specular: Vec3::splat(0.6),
                shininess: 40.0,
                ..Material::default()
            },
            "glossy" => Material {
                diffuse: Vec3::splat(0.2),
                reflect: Vec3::splat(0.7),
                roughness: 0.3,
                ..Material::default()
            },
            "rough" => Material {
                reflect: Vec3::splat(0.9),
                roughness: 1.0,
                ..Material::default()
            },
            _ => unreachable!(),
        }
    }

    fn bsdf(kind: &str, theta_deg: f32) -> Bsdf {
        let t = theta_deg.to_radians();
        let wo = Vec3::new(t.sin(), 0.0, t.cos());
        let m = material(kind);
        Bsdf::new(&m, m.diffuse, Vec3::Z, Vec3::Z, wo)
    }

    /// `f_pdf` is `f` and `pdf` bit for bit, every material at many
    /// viewing angles and directions over the whole sphere (under the
    /// surface and at grazing angles included), so the estimators that
    /// ask for both at once are the ones that asked for each.
    #[test]
    fn f_and_pdf_together_are_each_alone() {
        let mut rng = Rng::new(20261207, 3);
        for kind in ["lambert", "phong", "glossy", "rough"] {
            for theta in [0.0, 30.0, 60.0, 89.0] {
                let b = bsdf(kind, theta);
                for _ in 0..2000 {
                    let (u, v) = (rng.next_f32(), rng.next_f32());
                    let z = 2.0 * u - 1.0;
                    let r = (1.0 - z * z).max(0.0).sqrt();
                    let wi = Vec3::new(r * (TAU * v).cos(), r * (TAU * v).sin(), z);
                    let (f, pdf) = b.f_pdf(wi);
                    let want = (b.f(wi), b.pdf(wi));
                    assert_eq!(
                        (f.to_array().map(f32::to_bits), pdf.to_bits()),
                        (want.0.to_array().map(f32::to_bits), want.1.to_bits()),
                        "{kind} at {theta} degrees, wi {wi}"
                    );
                }
            }
        }
    }

    /// The albedo by importance sampling (`E[weight]`) against the albedo
    /// by uniform hemisphere sampling of `f cos` (which knows nothing of
    /// the sampling routine), and the density integrating to at most 1:
    /// a wrong pdf, a wrong Jacobian or a missing cosine would each make
    /// the two estimates differ by far more than the 1.5% allowed (the
    /// uniform estimate's standard error is at most 0.35% here, for the
    /// peaked glossy lobe; the sampled one's is smaller).
    #[test]
    fn sampling_matches_evaluation() {
        let n = 1_000_000;
        for kind in ["lambert", "phong", "glossy", "rough"] {
            for theta in [0.0f32, 35.0, 70.0] {
                let b = bsdf(kind, theta);
                let mut rng = Rng::new(11, theta as u64);
                // Sums in f64: a million float32 additions drift by 0.4% and more.
                let mut sampled = 0.0f64;
                for _ in 0..n {
                    if let Some(s) = b.sample(rng.next_f32(), rng.next_2d()) {
                        sampled += s.weight.x as f64;
                    }
                }
                sampled /= n as f64;
                let (mut uniform, mut mass) = (0.0f64, 0.0f64);
                for _ in 0..n {
                    let u = rng.next_2d();
                    let wi = spherical(u.x, TAU * u.y);
                    uniform += (b.f(wi).x * wi.z * TAU) as f64;
                    mass += (b.pdf(wi) * TAU) as f64;
                }
                uniform /= n as f64;
                mass /= n as f64;
                let rel = (sampled - uniform).abs() / uniform;
                assert!(rel < 0.015, "{kind} at {theta}: {sampled} vs {uniform}");
                assert!(mass < 1.01, "{kind} at {theta}: density mass {mass}");
                // Energy: no lobe reflects more than its colours sum to.
                let colour = material(kind);
                let bound = (colour.diffuse + colour.specular + colour.reflect).x as f64;
                assert!(sampled <= bound * 1.001, "{kind} at {theta}: {sampled}");
            }
        }
    }

    /// Straight on, the Blinn-Phong lobe and the glossy lobe reflect their
    /// colour exactly (their normalisations), the quantity the furnace
    /// tests of the path integrator rely on.
    #[test]
    fn lobes_reflect_their_colour_straight_on() {
        for (m, want) in [
            (
                Material {
                    specular: Vec3::ONE,
                    shininess: 16.0,
                    ..Material::default()
                },
                1.0,
            ),
            (
                Material {
                    reflect: Vec3::splat(0.6),
                    roughness: 0.5,
                    ..Material::default()
                },
                0.6,
            ),
        ] {
            let b = Bsdf::new(&m, Vec3::ZERO, Vec3::Z, Vec3::Z, Vec3::Z);
            let mut rng = Rng::new(3, 4);
            let n = 400_000;
            let mut sum = 0.0f64;
            for _ in 0..n {
                if let Some(s) = b.sample(rng.next_f32(), rng.next_2d()) {
                    sum += s.weight.x as f64;
                }
            }
            let albedo = sum / n as f64;
            assert!((albedo - want).abs() < 0.01 * want, "{albedo} vs {want}");
        }
        // The closed form at n = 16 against the ray-tracer paper's (n + 8) / (8 pi):
        // 6.7% more than it receives.
        let ratio = (16.0 + 8.0) / (8.0 * PI) / blinn_phong_norm(16.0);
        assert!((ratio - 1.0667).abs() < 1e-3, "{ratio}");
    }

    #[test]
    fn nothing_is_reflected_from_under_the_geometric_surface() {
        // Shading normal tilted 30 degrees from the geometric one.
        let ns = Vec3::new(0.5, 0.0, 0.75f32.sqrt());
        let m = material("lambert");
        let b = Bsdf::new(&m, m.diffuse, Vec3::Z, ns, Vec3::new(0.0, 0.6, 0.8));
        // Above the shading normal, under the geometric surface.
        let wi = Vec3::new(0.9, 0.0, -0.1).normalize();
        assert!(ns.dot(wi) > 0.0);
        assert_eq!(b.f(wi), Vec3::ZERO);
        assert_eq!(b.pdf(wi), 0.0);
        samples_stay_above(&b, ns, Rng::new(1, 2));
    }

    /// Every direction `b` samples lies above both the geometric surface
    /// (`z > 0`) and the shading plane of normal `n`.
    fn samples_stay_above(b: &Bsdf, n: Vec3, mut rng: Rng) {
        for _ in 0..10_000 {
            if let Some(s) = b.sample(rng.next_f32(), rng.next_2d()) {
                assert!(s.wi.z > 0.0 && n.dot(s.wi) > 0.0, "{:?}", s.wi);
            }
        }
    }

    #[test]
    fn nothing_reaches_a_viewer_from_behind_the_shading_plane() {
        // Shading normal tilted 80 degrees towards +x (the far edge of a
        // bump's top); the viewer grazes in from -x, above the geometric
        // surface but behind the shading plane.
        let t = 80f32.to_radians();
        let ns = Vec3::new(t.sin(), 0.0, t.cos());
        let wo = Vec3::new(-0.9, 0.0, 0.1).normalize();
        assert!(ns.dot(wo) < 0.0 && wo.z > 0.0);
        let turned = viewer_side(ns, wo);
        assert_eq!(turned, -ns);
        assert_eq!(viewer_side(turned, wo), turned);
        let m = material("lambert");
        let b = Bsdf::new(&m, m.diffuse, Vec3::Z, ns, wo);
        assert_eq!(b.shading_normal(), turned);
        // Straight above: in front of the shading plane as its normal
        // faces, behind it as the viewer sees it.
        assert!(ns.dot(Vec3::Z) > 0.0);
        assert_eq!(b.f(Vec3::Z), Vec3::ZERO);
        assert_eq!(b.pdf(Vec3::Z), 0.0);
        // Low on the viewer's side: above both planes as the viewer sees
        // them, lit with the shading cosine.
        let wi = Vec3::new(-0.9, 0.0, 0.3).normalize();
        assert!(turned.dot(wi) > 0.0 && wi.z > 0.0);
        assert_eq!(b.f(wi), m.diffuse * FRAC_1_PI);
        samples_stay_above(&b, turned, Rng::new(3, 4));
    }

    #[test]
    fn the_mirror_is_a_delta_lobe() {
        let m = Material {
            reflect: Vec3::splat(0.9),
            ..Material::default()
        };
        let wo = Vec3::new(0.6, 0.0, 0.8);
        let b = Bsdf::new(&m, Vec3::ZERO, Vec3::Z, Vec3::Z, wo);
        assert!(!b.has_non_delta());
        let s = {
            let mut rng = Rng::new(1, 1);
            b.sample(rng.next_f32(), rng.next_2d())
        }
        .unwrap();
        assert!(s.delta);
        assert!((s.wi - Vec3::new(-0.6, 0.0, 0.8)).length() < 1e-6);
        assert_eq!(s.weight, Vec3::splat(0.9));
        assert_eq!(b.f(s.wi), Vec3::ZERO);
        assert_eq!(b.pdf(s.wi), 0.0);
    }
}
