//! `[materials]`: each named material checked and built, textures loaded
//! once through the context.

use super::super::spec::MaterialSpec;
use super::ctx::Ctx;
use crate::error::Result;
use crate::material::Material;
use std::collections::{BTreeMap, HashMap};

/// The scene's materials in file order, then the plain material of visible
/// area-light quads (its index is returned, the light's radiance being
/// their emission), and each name's index.
pub(super) fn materials(
    cx: &mut Ctx,
    specs: &BTreeMap<String, MaterialSpec>,
) -> Result<(Vec<Material>, u32, HashMap<String, u32>)> {
    let mut materials = Vec::new();
    let mut index = HashMap::new();
    for (key, m) in specs {
        index.insert(key.clone(), materials.len() as u32);
        materials.push(material(cx, key, m)?);
    }
    let light_material = materials.len() as u32;
    materials.push(Material::default());
    Ok((materials, light_material, index))
}

fn material(cx: &mut Ctx, key: &str, m: &MaterialSpec) -> Result<Material> {
    let what = format!("materials.{key}");
    let key = format!("{what}.texture");
    let tex = |cx: &mut Ctx, t: &Option<String>| {
        t.as_ref().map(|f| cx.texture(f, true, &key)).transpose()
    };
    let emission = match m {
        MaterialSpec::Lambert { emission, .. }
        | MaterialSpec::Phong { emission, .. }
        | MaterialSpec::Mirror { emission, .. }
        | MaterialSpec::Glossy { emission, .. } => {
            cx.color(*emission, &format!("{what}.emission"))?
        }
    };
    let material = match m {
        MaterialSpec::Lambert { color, texture, .. } => Material {
            diffuse: cx.reflectance(*color, &format!("{what}.color"))?,
            texture: tex(cx, texture)?,
            ..Material::default()
        },
        MaterialSpec::Phong {
            color,
            texture,
            specular,
            shininess,
            ..
        } => {
            if !(*shininess > 0.0 && shininess.is_finite()) {
                return Err(cx.err(format!(
                    "{what}.shininess must be positive, got {shininess}"
                )));
            }
            Material {
                diffuse: cx.reflectance(*color, &format!("{what}.color"))?,
                texture: tex(cx, texture)?,
                specular: cx.reflectance(*specular, &format!("{what}.specular"))?,
                shininess: *shininess,
                ..Material::default()
            }
        }
        MaterialSpec::Mirror { color, diffuse, .. } => Material {
            diffuse: cx.reflectance(*diffuse, &format!("{what}.diffuse"))?,
            reflect: cx.reflectance(*color, &format!("{what}.color"))?,
            ..Material::default()
        },
        MaterialSpec::Glossy {
            color,
            roughness,
            diffuse,
            ..
        } => {
            if !(*roughness > 0.0 && *roughness <= 1.0) {
                return Err(cx.err(format!(
                    "{what}.roughness must be in (0, 1], got {roughness}"
                )));
            }
            Material {
                diffuse: cx.reflectance(*diffuse, &format!("{what}.diffuse"))?,
                reflect: cx.reflectance(*color, &format!("{what}.color"))?,
                roughness: *roughness,
                ..Material::default()
            }
        }
    };
    Ok(Material {
        emission,
        ..material
    })
}
