//! `[[lights]]`: point and area lights, each visible area light's quad
//! added to the scene's primitives so camera and bounce rays see its
//! radiance (as pbrt-v4 attaches a `DiffuseAreaLight` to its shape).

use super::super::spec::LightSpec;
use super::ctx::Ctx;
use super::shapes::{quad, Geometry};
use crate::error::Result;
use crate::geometry::Aabb;
use crate::light::Light;
use crate::placed::{Placed, PlacedShape, Shape};
use glam::Vec3;

/// The scene's lights in file order, and which are fill lights (the path
/// integrator leaves those out); a visible area light's quad is pushed onto
/// `geo` with `light_material` and the light as its emitter.
pub(super) fn lights(
    cx: &Ctx,
    specs: &[LightSpec],
    light_material: u32,
    geo: &mut Geometry,
) -> Result<(Vec<Light>, Vec<bool>)> {
    let mut lights = Vec::new();
    let mut fill = Vec::new();
    for (k, l) in specs.iter().enumerate() {
        let what = format!("lights[{k}]");
        match l {
            LightSpec::Point {
                position,
                intensity,
                fill: f,
            } => {
                lights.push(Light::Point {
                    position: cx.vec(*position, &format!("{what}.position"))?,
                    intensity: cx.color(*intensity, &format!("{what}.intensity"))?,
                });
                fill.push(*f);
            }
            LightSpec::Area {
                origin,
                edge_u,
                edge_v,
                radiance,
                visible,
                fill: f,
            } => {
                if *f && *visible {
                    return Err(cx.err(format!(
                        "{what}: a fill light needs visible = false (the path integrator leaves it out, and its quad would still block rays)"
                    )));
                }
                fill.push(*f);
                let quad = quad(cx, *origin, *edge_u, *edge_v, &what)?;
                let radiance = cx.color(*radiance, &format!("{what}.radiance"))?;
                if *visible {
                    geo.push(
                        Placed::Quad(quad),
                        light_material,
                        Some(lights.len() as u32),
                        None,
                    );
                }
                lights.push(Light::Area { quad, radiance });
            }
        }
    }
    Ok((lights, fill))
}

/// A warning for each area light whose lit side faces away from the scene:
/// the centre of the bounds of every shape (the lights' own quads aside)
/// lies behind its plane, so it lights little or nothing of what the camera
/// sees and shows its dark back to rays from below. An area light emits on
/// the side of `edge_u x edge_v`; swapping its edges turns it round.
pub(super) fn facing_away(lights: &[Light], shapes: &[PlacedShape]) -> Vec<String> {
    let points = shapes
        .iter()
        .filter(|s| s.emitter.is_none())
        .flat_map(|s| shape_points(&s.shape));
    let bounds = points.fold(None, |b: Option<Aabb>, p| {
        Some(b.map_or(Aabb::from_points([p]), |b| b.grow(p)))
    });
    let Some(bounds) = bounds else {
        return Vec::new();
    };
    let centre = bounds.centroid();
    let mut warnings = Vec::new();
    for (k, light) in lights.iter().enumerate() {
        let Light::Area { quad, .. } = light else {
            continue;
        };
        let middle = quad.origin + 0.5 * (quad.edge_u + quad.edge_v);
        if (centre - middle).dot(quad.normal) < 0.0 {
            warnings.push(format!(
                "lights[{k}]: the area light faces away from the scene (it emits towards \
                 edge_u x edge_v = {:?}, and the scene's centre {:?} is behind it); swap \
                 edge_u and edge_v to turn it round",
                quad.normal.to_array(),
                centre.to_array(),
            ));
        }
    }
    warnings
}

/// Points whose hull holds `shape` (a displaced face's whole shell).
fn shape_points(shape: &Placed) -> Vec<Vec3> {
    let corners = |b: Aabb| {
        (0..8)
            .map(|i| {
                Vec3::select(
                    glam::BVec3::new(i & 1 != 0, i & 2 != 0, i & 4 != 0),
                    b.max,
                    b.min,
                )
            })
            .collect()
    };
    match shape {
        Shape::Quad(q) => corners(q.bounds()),
        Shape::Triangle { tri, .. } => corners(tri.bounds()),
        Shape::Sphere(s) => corners(s.bounds()),
        Shape::Displaced(f) => f.shell_corners(),
        Shape::Curved(c) => c.shell().corners().iter().map(|p| p.as_vec3()).collect(),
    }
}
