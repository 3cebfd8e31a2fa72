//! Materials of a Whitted ray tracer with Cook-style distributed reflection:
//! every material is a sum of a Lambertian term, a normalised Blinn-Phong
//! highlight and a reflection (perfect for roughness 0, a cone of distributed
//! rays otherwise).

use crate::geometry::{basis, reflect};
use crate::sampler::Rng;
use crate::texture::Texture;
use glam::{Vec2, Vec3};
use std::f32::consts::{FRAC_1_PI, PI};
use std::sync::Arc;

/// A Whitted material: Lambert plus Blinn-Phong plus a reflection lobe,
/// each term optional.
#[derive(Clone, Debug, Default)]
pub struct Material {
    /// Lambertian albedo (multiplied by `texture` when present).
    pub diffuse: Vec3,
    /// Colour map (linear RGB), sampled at the hit's texture coordinate.
    pub texture: Option<Arc<Texture>>,
    /// Blinn-Phong specular colour and exponent.
    pub specular: Vec3,
    /// Blinn-Phong exponent (0: no highlight).
    pub shininess: f32,
    /// Reflectance of the mirror/glossy lobe.
    pub reflect: Vec3,
    /// 0: perfect mirror; larger spreads reflection rays (Phong lobe of
    /// exponent `2 / roughness^2 - 2`, the Blinn/Beckmann correspondence of
    /// Walter et al. 2007).
    pub roughness: f32,
    /// Radiance the surface emits from both sides (`emission`): the camera
    /// and reflections see it; the path integrator also lights the scene
    /// with it (as an area light of every emitting quad, triangle and
    /// sphere, see [`crate::emitters`]).
    pub emission: Vec3,
}

impl Material {
    /// The Lambertian albedo at `uv`: `diffuse` times the texture times `tint`
    /// (a displaced face's own colour texture).
    pub fn albedo(&self, uv: Vec2, tint: Vec3) -> Vec3 {
        let t = self.texture.as_ref().map_or(Vec3::ONE, |t| t.sample(uv));
        self.diffuse * t * tint
    }

    /// BRDF times nothing: `f(wo, wi)` for the direct-lighting terms, with
    /// `n` the shading normal, `wo` towards the viewer, `wi` towards the
    /// light.
    pub fn brdf(&self, albedo: Vec3, n: Vec3, wo: Vec3, wi: Vec3) -> Vec3 {
        let mut f = albedo * FRAC_1_PI;
        if self.shininess > 0.0 && self.specular != Vec3::ZERO {
            let h = (wo + wi).normalize_or_zero();
            let c = n.dot(h).max(0.0);
            // Energy-normalised Blinn-Phong (Akenine-Möller et al., RTR4 eq. 9.39 family).
            f += self.specular * (self.shininess + 8.0) / (8.0 * PI) * c.powf(self.shininess);
        }
        f
    }

    /// Whether the material casts a reflection ray.
    pub fn reflects(&self) -> bool {
        self.reflect != Vec3::ZERO
    }

    /// The direction of one reflection ray about shading normal `n` for an
    /// incoming direction `d`, with the two random numbers `u`.
    pub fn reflection_dir(&self, d: Vec3, n: Vec3, rng: &mut Rng) -> Vec3 {
        let r = reflect(d, n);
        if self.roughness <= 0.0 {
            return r;
        }
        let e = (2.0 / (self.roughness * self.roughness) - 2.0).max(0.0);
        let u = rng.next_2d();
        let cos_t = u.x.powf(1.0 / (e + 1.0));
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        let (t, b) = basis(r);
        (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + r * cos_t).normalize()
    }
}
