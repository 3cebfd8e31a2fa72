//! `[[lights]]`: point and area lights, each visible area light's quad
//! added to the scene's primitives so camera and bounce rays see its
//! radiance (as pbrt-v4 attaches a `DiffuseAreaLight` to its shape).

use super::super::spec::LightSpec;
use super::ctx::Ctx;
use super::shapes::{quad, Geometry};
use crate::error::Result;
use crate::light::Light;
use crate::placed::Placed;

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
