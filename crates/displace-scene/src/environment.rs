//! The light of rays that escape the scene: a constant `background`, or an
//! equirectangular, linear HDR map (`image.environment`, OpenEXR), each an
//! infinite light that escaping paths see and that next-event estimation
//! samples (pbrt-v4 section 12.5, `UniformInfiniteLight` and
//! `ImageInfiniteLight`). The map is importance sampled by its luminance
//! times `sin(theta)` through a piecewise-constant 2D distribution in
//! `(u, v)` (pbrt-v3 section 14.2.4), so the solid-angle density is
//! `p(u, v) / (2 pi^2 sin(theta))`.
//!
//! Directions map to the image as the sphere's texture coordinate does
//! (`shapes::Sphere::uv`): `u = 0.5 + atan2(z, x) / 2 pi` along a row,
//! `v = acos(y) / pi` down the columns, so row 0 is straight up (+y) and
//! the image's centre column looks along -x.

use crate::distribution::Distribution2D;
use crate::error::Result;
use glam::{Vec2, Vec3};
use std::f32::consts::{PI, TAU};
use std::path::Path;
use std::sync::Arc;

/// Luminance of linear Rec. 709 RGB (ITU-R BT.709 weights).
pub fn luminance(c: Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

/// An equirectangular environment map with its sampling distribution.
#[derive(Clone, Debug)]
pub struct EnvironmentMap {
    width: usize,
    height: usize,
    /// Row-major, row 0 at `v = 0` (straight up).
    texels: Vec<Vec3>,
    distribution: Distribution2D,
    /// `integral of L over the sphere`, per channel (W/m^2 per unit area of
    /// a receiving disc, before the `pi r^2` of [`Environment::power`]).
    integral: Vec3,
}

impl EnvironmentMap {
    /// Bytes a map holds per texel while it loads: the decoded float image
    /// and the texels kept (a `Vec3` each), and the sampling distribution's
    /// weights and tables (12 bytes).
    pub const BYTES_PER_TEXEL: u128 = std::mem::size_of::<Vec3>() as u128 * 3;

    /// The one format an environment map is read from, and what a file of
    /// another is told.
    const FORMAT: (image::ImageFormat, &'static str) = (
        image::ImageFormat::OpenExr,
        "not an OpenEXR file: an environment map is linear HDR radiance (.exr)",
    );

    /// The texel size [`EnvironmentMap::load`] would give, from the file's
    /// header alone (with the same checks), for memory estimates.
    pub fn dimensions(path: &Path) -> Result<[usize; 2]> {
        crate::texture::image_dimensions(
            path,
            "environment map",
            Self::BYTES_PER_TEXEL,
            Some(Self::FORMAT),
        )
    }

    /// Loads an OpenEXR file. Refuses anything else (a PNG is 8-bit sRGB,
    /// not radiance), an image whose decoded size is too big, and texels
    /// that are negative or not finite (radiance is neither), each error
    /// naming the file.
    pub fn load(path: &Path) -> Result<Self> {
        let rgb = crate::texture::read_rgb32f(
            path,
            "environment map",
            Self::BYTES_PER_TEXEL,
            Some(Self::FORMAT),
        )?;
        let (w, h) = (rgb.width() as usize, rgb.height() as usize);
        let range = [0.0, crate::build::MAX_RADIANCE];
        let texels = crate::texture::checked_texels(path, &rgb, range, "radiance")
            .collect::<Result<Vec<_>>>()?;
        Ok(Self::from_texels(w, h, texels))
    }

    /// A map from linear texels (row-major, row 0 straight up); every
    /// texel finite and >= 0.
    pub fn from_texels(width: usize, height: usize, texels: Vec<Vec3>) -> Self {
        assert_eq!(texels.len(), width * height);
        let mut weights = Vec::with_capacity(texels.len());
        let mut integral = Vec3::ZERO;
        // Solid angle of a texel of row j: (2 pi / w) (pi / h) sin(theta_j).
        let cell = TAU / width as f32 * (PI / height as f32);
        for j in 0..height {
            let sin = (PI * (j as f32 + 0.5) / height as f32).sin();
            for i in 0..width {
                let c = texels[j * width + i];
                weights.push(luminance(c) * sin);
                integral += c * (sin * cell);
            }
        }
        Self {
            width,
            height,
            distribution: Distribution2D::new(&weights, width, height),
            texels,
            integral,
        }
    }

    fn texel(&self, uv: Vec2) -> Vec3 {
        let i = ((uv.x * self.width as f32) as usize).min(self.width - 1);
        let j = ((uv.y * self.height as f32) as usize).min(self.height - 1);
        self.texels[j * self.width + i]
    }
}

/// `(u, v)` of unit direction `d` (see the module's convention).
pub fn direction_uv(d: Vec3) -> Vec2 {
    let u = 0.5 + d.z.atan2(d.x) / TAU;
    Vec2::new(
        u.rem_euclid(1.0).min(1.0 - f32::EPSILON),
        d.y.clamp(-1.0, 1.0).acos() / PI,
    )
}

/// The unit direction of `(u, v)` and `sin(theta)`.
pub fn uv_direction(uv: Vec2) -> (Vec3, f32) {
    let theta = uv.y * PI;
    let phi = (uv.x - 0.5) * TAU;
    let (sin_t, cos_t) = theta.sin_cos();
    (
        Vec3::new(sin_t * phi.cos(), cos_t, sin_t * phi.sin()),
        sin_t,
    )
}

/// What escaping rays see.
#[derive(Clone, Debug)]
pub enum Environment {
    /// The same radiance from every direction (`image.background`).
    Constant(Vec3),
    /// An environment map (`image.environment`).
    Map(Arc<EnvironmentMap>),
}

/// A direction sampled towards the environment.
#[derive(Clone, Copy, Debug)]
pub struct EnvironmentSample {
    /// Unit direction towards the environment.
    pub wi: Vec3,
    /// Radiance arriving from it.
    pub radiance: Vec3,
    /// Solid-angle density of `wi`.
    pub pdf: f32,
}

impl Environment {
    /// Radiance arriving along a ray that escapes in unit direction `d`.
    #[inline]
    pub fn radiance(&self, d: Vec3) -> Vec3 {
        match self {
            Environment::Constant(c) => *c,
            Environment::Map(m) => m.texel(direction_uv(d)),
        }
    }

    /// Whether no light comes from the environment at all.
    pub fn is_black(&self) -> bool {
        match self {
            Environment::Constant(c) => *c == Vec3::ZERO,
            Environment::Map(m) => m.distribution.integral() <= 0.0,
        }
    }

    /// The power it sends into a scene of bounding radius `r`:
    /// `pi r^2 integral L d(omega)` (pbrt-v4 section 12.5.1, `Phi`), per
    /// channel; light selection by power weighs it against the others.
    pub fn power(&self, r: f32) -> Vec3 {
        let integral = match self {
            Environment::Constant(c) => *c * (4.0 * PI),
            Environment::Map(m) => m.integral,
        };
        integral * (PI * r * r)
    }

    /// Samples a direction: uniform over the sphere for a constant
    /// environment, by luminance and `sin(theta)` for a map. `None` where
    /// the sample has no density (a pole of the map).
    pub fn sample(&self, u: Vec2) -> Option<EnvironmentSample> {
        match self {
            Environment::Constant(c) => {
                let z = 1.0 - 2.0 * u.x;
                let r = (1.0 - z * z).max(0.0).sqrt();
                let phi = TAU * u.y;
                Some(EnvironmentSample {
                    wi: Vec3::new(r * phi.cos(), z, r * phi.sin()),
                    radiance: *c,
                    pdf: 1.0 / (4.0 * PI),
                })
            }
            Environment::Map(m) => {
                let (uv, pdf_uv) = m.distribution.sample(u);
                let (wi, sin_t) = uv_direction(uv);
                if pdf_uv <= 0.0 || sin_t <= 0.0 {
                    return None;
                }
                // Radiance and density from the direction itself, as an
                // escaping ray along it finds them (the two agree but for
                // rounding on a texel's border).
                let pdf = self.pdf(wi);
                (pdf > 0.0).then(|| EnvironmentSample {
                    wi,
                    radiance: self.radiance(wi),
                    pdf,
                })
            }
        }
    }

    /// Solid-angle density of [`Environment::sample`] at unit direction `d`.
    pub fn pdf(&self, d: Vec3) -> f32 {
        match self {
            Environment::Constant(_) => 1.0 / (4.0 * PI),
            Environment::Map(m) => {
                let uv = direction_uv(d);
                let sin_t = (uv.y * PI).sin();
                if sin_t <= 0.0 {
                    return 0.0;
                }
                m.distribution.pdf(uv) / (2.0 * PI * PI * sin_t)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sampler::Rng;

    #[test]
    fn directions_and_coordinates_round_trip() {
        for k in 0..200 {
            let uv = Vec2::new(
                (k as f32 * 0.618_034).fract(),
                0.01 + 0.98 * (k as f32 / 200.0),
            );
            let (d, _) = uv_direction(uv);
            let back = direction_uv(d);
            assert!(
                (back - uv).abs().max_element() < 1e-4,
                "{uv} -> {d} -> {back}"
            );
        }
        assert!(direction_uv(Vec3::Y).y < 1e-6);
    }

    /// The density integrates to 1 over the sphere and a sample's stated
    /// density is the density at its direction.
    #[test]
    fn map_sampling_density_is_consistent() {
        let (w, h) = (16, 8);
        let texels = (0..w * h)
            .map(|i| {
                if i == 3 * w + 5 {
                    Vec3::splat(500.0)
                } else {
                    Vec3::new(0.2, 0.3, 0.4) * (1 + i % 3) as f32
                }
            })
            .collect();
        let env = Environment::Map(Arc::new(EnvironmentMap::from_texels(w, h, texels)));
        let mut rng = Rng::new(5, 1);
        let n = 200_000;
        // Uniform directions: E[pdf / (1 / 4 pi)] = 1 (within 2%: the
        // estimate's standard error is under 0.5% here).
        let mut sum = 0.0f64;
        for _ in 0..n {
            let s = Environment::Constant(Vec3::ONE)
                .sample(rng.next_2d())
                .unwrap();
            sum += (env.pdf(s.wi) * 4.0 * PI) as f64;
        }
        let mean = sum / n as f64;
        assert!((mean - 1.0).abs() < 0.02, "{mean}");
        // Samples are distributed by the density they state: E[1 / pdf]
        // over them is the sphere's solid angle, 4 pi (every texel has
        // light, so the density is nowhere 0).
        let mut inv = 0.0f64;
        let mut m = 0;
        for _ in 0..n {
            if let Some(s) = env.sample(rng.next_2d()) {
                assert_eq!(env.pdf(s.wi), s.pdf);
                assert_eq!(s.radiance, env.radiance(s.wi));
                inv += 1.0 / s.pdf as f64;
                m += 1;
            }
        }
        let sphere = inv / m as f64;
        assert!((sphere / (4.0 * PI as f64) - 1.0).abs() < 0.02, "{sphere}");
    }
}
