//! The camera and the one light every draw of a scene shares: the CPU's
//! pinhole camera as the raster path's view, and the scene's strongest light
//! as its point light.

use crate::{Draw, DrawShape, Error, Result, Shadows, View};
use displace_core::Method;
use displace_scene::light::Light;
use displace_scene::World;
use glam::Vec3;

use super::shading::Shading;

/// The camera and light every draw shares.
pub(super) struct Stage {
    size: [u32; 2],
    eye: Vec3,
    forward: Vec3,
    up: Vec3,
    fov_y_degrees: f32,
    light: Vec3,
    /// The light's radiant intensity (RGB), which the materials' shading
    /// is split against.
    pub(super) intensity: Vec3,
    shadows: Shadows,
}

impl Stage {
    /// The stage of `scene`; what of its camera and lights is not drawn is
    /// added to `left_out` (depth of field, every light but the strongest).
    pub(super) fn of(scene: &World, shadows: Shadows, left_out: &mut Vec<String>) -> Result<Self> {
        let camera = &scene.camera;
        let (forward, _, up, tan_half) = camera.basis();
        if camera.lens_radius() > 0.0 {
            left_out.push("depth of field (drawn as a pinhole)".to_string());
        }
        let Some((light, intensity)) = pick_light(&scene.lights) else {
            return Err(Error::Scene(
                "the scene has no light; gpu-render lights with its strongest point or area light"
                    .into(),
            ));
        };
        if scene.lights.len() > 1 {
            left_out.push(format!(
                "{} lights besides the strongest",
                scene.lights.len() - 1
            ));
        }
        Ok(Self {
            size: [scene.width, scene.height],
            eye: camera.position(),
            forward,
            up,
            fov_y_degrees: 2.0 * tan_half.atan().to_degrees(),
            light,
            intensity,
            shadows,
        })
    }

    /// The frame's view: this stage's camera and light, which every draw
    /// shares, lit with the inverse-square falloff the CPU renderer's point
    /// lights have; its depth range is set once every draw is known.
    pub(super) fn view(&self) -> View {
        View {
            size: self.size,
            eye: self.eye,
            target: self.eye + self.forward,
            up: self.up,
            fov_y_degrees: self.fov_y_degrees,
            depth_range: None,
            light: self.light,
            // Each material's shading is split against `intensity` into
            // its draw's albedo and `albedo_scale`: the light itself is of
            // unit strength.
            light_intensity: 1.0,
            falloff: true,
        }
    }

    /// A draw of `shape` with this stage's shadows and `shading`'s terms;
    /// the caller sets its depth and trace.
    pub(super) fn draw(&self, shape: DrawShape, shading: &Shading) -> Draw {
        Draw {
            shape,
            depth: 1.0,
            method: Method::Sphere,
            iterations: 64,
            shadows: self.shadows,
            penumbra_k: 8.0,
            ambient: 0.0,
            albedo_scale: shading.strength,
            specular: shading.specular,
            shininess: shading.shininess,
        }
    }
}

/// The light the GPU path uses: position and radiant intensity (RGB) of
/// the strongest of `lights`. An area light becomes a point at its centre
/// with its on-axis intensity `L A` (radiance times area), so an area-lit
/// scene with a dim point fill (the Cornell boxes of `scenes/`) is lit by
/// its area light, not by the fill.
fn pick_light(lights: &[Light]) -> Option<(Vec3, Vec3)> {
    lights
        .iter()
        .map(|l| match l {
            Light::Point {
                position,
                intensity,
            } => (*position, *intensity),
            Light::Area { quad, radiance } => (
                quad.origin + 0.5 * (quad.edge_u + quad.edge_v),
                *radiance * quad.edge_u.cross(quad.edge_v).length(),
            ),
        })
        .fold(None, |best: Option<(Vec3, Vec3)>, l| match best {
            Some(b) if b.1.element_sum() >= l.1.element_sum() => Some(b),
            _ => Some(l),
        })
}

#[cfg(test)]
mod tests {
    use super::*;
    use displace_scene::SceneOptions;
    use std::path::Path;

    fn lights(toml: &str) -> Option<(Vec3, Vec3)> {
        let text = format!(
            "[image]\nwidth = 8\nheight = 8\n\n[camera]\nposition = [0, 0, -5]\nlook_at = [0, 0, 0]\n\n\
             [materials.m]\ntype = \"lambert\"\ncolor = [0.5, 0.5, 0.5]\n\n\
             [[shapes]]\ntype = \"sphere\"\ncenter = [0, 0, 0]\nradius = 1\nmaterial = \"m\"\n\n{toml}"
        );
        let scene = World::from_toml(
            &text,
            Path::new("t.toml"),
            Path::new("."),
            &SceneOptions::default(),
        )
        .expect("scene");
        pick_light(&scene.lights)
    }

    /// The strongest light wins, an area light counting as `L A` at its
    /// centre: the Cornell boxes' area light beats their dim point fill, and a
    /// bright point beats a small area light, whatever their order.
    #[test]
    fn the_strongest_light_is_the_one_drawn() {
        let area = "[[lights]]\ntype = \"area\"\norigin = [0, 4, 0]\nedge_u = [2, 0, 0]\nedge_v = [0, 0, 1]\nradiance = [10, 10, 10]\n";
        let dim = "[[lights]]\ntype = \"point\"\nposition = [1, 2, 3]\nintensity = [5, 5, 5]\n";
        let bright =
            "[[lights]]\ntype = \"point\"\nposition = [1, 2, 3]\nintensity = [50, 50, 50]\n";
        let area_wins = (Vec3::new(1.0, 4.0, 0.5), Vec3::splat(20.0));
        let bright_wins = (Vec3::new(1.0, 2.0, 3.0), Vec3::splat(50.0));
        for (point, want) in [(dim, area_wins), (bright, bright_wins)] {
            for toml in [format!("{area}{point}"), format!("{point}{area}")] {
                assert_eq!(lights(&toml), Some(want), "{toml}");
            }
        }
        assert_eq!(lights(""), None);
    }
}
