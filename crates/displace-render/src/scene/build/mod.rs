//! Validation and construction: from a parsed [`SceneSpec`] to a [`Scene`],
//! one constructor per part of the file: the film and camera (`film`),
//! materials, lights, and each kind of shape (`shapes`, with `triangles`
//! for triangles and meshes and `displacement` for the bakes of displaced
//! faces). Every error names the scene file and the key at fault; what the
//! constructors share (the bake cache, loaded inputs, the memory estimate)
//! is the build's context (`ctx`).
//!
//! The built scene is pbrt-v4's `BasicScene` and aggregate in one: the
//! primitives under a BVH for the CPU, and the triangles and meshes as
//! placed in the world ([`super::SceneMesh`]), from which a rasteriser
//! derives its own draws.

mod ctx;
mod displacement;
mod film;
mod lights;
mod material;
mod shapes;
mod triangles;

pub use ctx::MAX_COORDINATE;
pub use film::{MAX_DEPTH, MAX_SAMPLES, MAX_SHADOW_SAMPLES, MAX_SPP};

use super::spec::SceneSpec;
use super::world::Primitive;
use super::{Scene, SceneOptions};
use crate::bvh::Bvh;
use crate::emitters::Emitters;
use crate::error::Result;
use crate::geometry::Aabb;
use ctx::Ctx;
use shapes::Geometry;
use std::path::Path;

/// Builds the scene `spec` (named `name` in errors, its relative paths
/// under `base`), `opts` overriding what the command line may.
pub fn build(spec: SceneSpec, name: &Path, base: &Path, opts: &SceneOptions) -> Result<Scene> {
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
    let bounds: Vec<Aabb> = prims.iter().map(Primitive::bounds).collect();
    let costs: Vec<f32> = prims.iter().map(Primitive::test_cost).collect();
    let bvh = Bvh::build_weighted(&bounds, &costs);
    let world = bvh.bounds();
    let diag = if world.is_empty() {
        1.0
    } else {
        (world.max - world.min).length()
    };
    let emitters = Emitters::new(
        &lights,
        &fill,
        &prims,
        &materials,
        &film.environment,
        0.5 * diag,
    );
    Ok(Scene {
        camera,
        width: film.width,
        height: film.height,
        spp: film.spp,
        max_depth: film.max_depth,
        seed: film.seed,
        shadow_samples: film.shadow_samples,
        background: film.background,
        environment: film.environment,
        integrator: film.integrator,
        sampling: film.sampling,
        sampler: film.sampler,
        emitters,
        prims,
        attrs,
        bvh,
        materials,
        lights,
        epsilon: 5e-5 * diag.max(1e-3),
        meshes,
        cache_stats: cx.cache.stats(),
        sources: cx.sources,
        content_hash: 0,
        warnings: cx.cache.warnings(),
    })
}
