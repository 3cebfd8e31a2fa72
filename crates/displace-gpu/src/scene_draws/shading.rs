//! A scene material as the raster path shades it: the CPU's Lambert and
//! normalised Blinn-Phong terms (`displace_scene::material`) rewritten as
//! the GPU's albedo, light strength and specular weight (Donnelly's
//! fragment stage lights with one point light, GPU Gems 2 8.5.2).

use crate::PlainMaterial;
use displace_scene::material::Material;
use glam::Vec3;
use std::f32::consts::PI;

/// A material as the GPU shades it under a light of radiant intensity
/// `intensity`.
pub(super) struct Shading {
    pub(super) albedo: Vec3,
    pub(super) strength: f32,
    pub(super) specular: f32,
    pub(super) shininess: f32,
    textured: bool,
    reflects: bool,
}

impl Shading {
    /// The shading of a draw whose vertices carry their own weights (the
    /// plain triangles): white, at unit strength, no highlight.
    pub(super) const UNIT: Self = Self {
        albedo: Vec3::ONE,
        strength: 1.0,
        specular: 0.0,
        shininess: 1.0,
        textured: false,
        reflects: false,
    };

    /// Adds what of the material is left out to `left_out`.
    pub(super) fn note(&self, left_out: &mut Vec<String>) {
        if self.textured {
            left_out.push("material textures".to_string());
        }
        if self.reflects {
            left_out.push("reflections".to_string());
        }
    }
}

/// The GPU shading of `mat` under a light of radiant intensity `intensity`.
pub(super) fn material_shading(mat: &Material, intensity: Vec3) -> Shading {
    // The CPU's direct term is `diffuse / pi * I / r^2 * cos`: the GPU's
    // is `albedo * light_intensity * cos / r^2`, its albedo a [0, 1]
    // texture, so the largest channel of `diffuse I / pi` becomes the
    // light's strength and the rest the albedo.
    let rgb = mat.diffuse * intensity / PI;
    let strength = rgb.max_element();
    let strength = if strength > 0.0 { strength } else { 1.0 };
    // Normalised Blinn-Phong (displace_scene::material::brdf) with the
    // mean of its specular colour and the light's (the GPU highlight is
    // white).
    let mean = |v: Vec3| (v.x + v.y + v.z) / 3.0;
    let specular = if mat.shininess > 0.0 && mat.specular != Vec3::ZERO {
        mean(mat.specular) * (mat.shininess + 8.0) / (8.0 * PI) * mean(intensity) / strength
    } else {
        0.0
    };
    Shading {
        albedo: rgb / strength,
        strength,
        specular,
        shininess: mat.shininess.max(1.0),
        textured: mat.texture.is_some(),
        reflects: mat.reflects(),
    }
}

/// The plain-draw material of `mat` under a light of radiant intensity
/// `intensity`: the weights [`material_shading`] splits between albedo and
/// light strength, multiplied back together (a vertex attribute need not be
/// an 8-bit texel), and `emission` for a visible area-light quad.
pub(super) fn plain_material(
    mat: &Material,
    intensity: Vec3,
    emission: Vec3,
    left_out: &mut Vec<String>,
) -> PlainMaterial {
    let shading = material_shading(mat, intensity);
    shading.note(left_out);
    PlainMaterial {
        diffuse: shading.albedo * shading.strength,
        specular: shading.specular * shading.strength,
        shininess: shading.shininess,
        emission,
    }
}
