//! Validation and construction: from a parsed [`SceneSpec`] to a [`World`],
//! one constructor per part of the file: the film and camera (`film`),
//! materials, lights, and each kind of shape (`shapes`, with `triangles`
//! for triangles and meshes and `displacement` for the bakes of displaced
//! faces). Every error names the scene file and the key at fault; what the
//! constructors share (the bake cache, loaded inputs, the memory estimate)
//! is the build's context (`ctx`).
//!
//! The built world is pbrt-v4's `BasicScene`: the shapes as placed, and
//! the triangles and meshes as placed ([`crate::placed::SceneMesh`]), from
//! which the CPU builds its primitives and BVH and a rasteriser its draws.

mod ctx;
mod displacement;
mod film;
mod lights;
mod material;
mod shapes;
mod triangles;

pub use ctx::{MAX_COORDINATE, MAX_RADIANCE};
pub use film::{MAX_DEPTH, MAX_SAMPLES, MAX_SHADOW_SAMPLES, MAX_SPP};

use crate::error::Result;
use crate::spec::SceneSpec;
use crate::world::{RenderSettings, SceneOptions, World};
use ctx::Ctx;
use shapes::Geometry;
use std::path::Path;

/// Builds the scene `spec` (named `name` in errors, its relative paths
/// under `base`), `opts` overriding what the command line may.
pub fn build(spec: SceneSpec, name: &Path, base: &Path, opts: &SceneOptions) -> Result<World> {
    let mut cx = Ctx::new(name, base, opts);
    let film = film::film(&mut cx, &spec.image, opts)?;
    let camera = film::camera(&cx, &spec.camera, film.width, film.height)?;
    let (materials, light_material, material_index) =
        material::materials(&mut cx, &spec.materials)?;
    let mut geo = Geometry::default();
    let (lights, fill) = lights::lights(&cx, &spec.lights, light_material, &mut geo)?;
    for (k, s) in spec.shapes.iter().enumerate() {
        shapes::shape(&mut cx, k, s, &material_index, &mut geo)?;
    }
    let Geometry {
        prims,
        attrs,
        meshes,
    } = geo;
    let mut warnings = cx.cache.warnings();
    warnings.extend(lights::facing_away(&lights, &prims));
    Ok(World {
        camera,
        width: film.width,
        height: film.height,
        settings: RenderSettings {
            integrator: film.integrator,
            sampling: film.sampling,
            sampler: film.sampler,
            spp: film.spp,
            seed: film.seed,
            max_depth: film.max_depth,
            shadow_samples: film.shadow_samples,
        },
        background: film.background,
        environment: film.environment,
        materials,
        lights,
        fill,
        shapes: prims,
        attrs,
        meshes,
        cache_stats: cx.cache.stats(),
        sources: cx.sources,
        content_hash: 0,
        warnings,
    })
}
