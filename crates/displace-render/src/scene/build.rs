//! The CPU renderer's scene from the scene placed in the world: each
//! placed shape as a primitive (its displaced faces with their map-space
//! frames and shells ready to trace), all of them under one BVH (pbrt-v4
//! section 7.3) weighted by their test costs, the path tracer's emitters,
//! and the offset of secondary rays for the scene's size.

use super::world::{bounds, test_cost, Primitive};
use super::Scene;
use crate::bvh::Bvh;
use crate::faces::curved_face::CurvedFace;
use crate::faces::displaced::DisplacedFace;
use crate::geometry::Aabb;
use crate::shading::emitters::Emitters;
use displace_scene::placed::PlacedShape;
use displace_scene::World;

/// The primitive of a placed shape, in the same place of the list.
fn primitive(p: PlacedShape) -> Primitive {
    p.map_shape(|s| s.map_faces(|f| DisplacedFace::from(&f), |c| CurvedFace::from(&c)))
}

/// Builds the horizon bounds of every flat displaced face's height map
/// (once per shared map), so that its shadow rays that climb clear of the
/// surface end without a trace ([`displace_core::horizon`]); they are kept
/// where they pay (smooth fields).
fn prepare_horizons(prims: &[Primitive]) {
    for p in prims {
        if let crate::scene::world::Shape::Displaced(d) = &p.shape {
            d.map().prepare_horizon();
        }
    }
}

/// The CPU scene of `world`.
pub fn build(world: World) -> Scene {
    let World {
        camera,
        width,
        height,
        settings,
        background,
        environment,
        materials,
        lights,
        fill,
        shapes,
        attrs,
        meshes,
        cache_stats,
        sources,
        content_hash,
        warnings,
    } = world;
    let prims: Vec<Primitive> = shapes.into_iter().map(primitive).collect();
    prepare_horizons(&prims);
    let bounds: Vec<Aabb> = prims.iter().map(bounds).collect();
    let costs: Vec<f32> = prims.iter().map(test_cost).collect();
    let bvh = Bvh::build_weighted(&bounds, &costs);
    let extent = bvh.bounds();
    let diag = if extent.is_empty() {
        1.0
    } else {
        (extent.max - extent.min).length()
    };
    let emitters = Emitters::new(&lights, &fill, &prims, &materials, &environment, 0.5 * diag);
    Scene {
        camera,
        width,
        height,
        spp: settings.spp,
        max_depth: settings.max_depth,
        seed: settings.seed,
        shadow_samples: settings.shadow_samples,
        background,
        environment,
        integrator: settings.integrator,
        sampling: settings.sampling,
        sampler: settings.sampler,
        emitters,
        prims,
        attrs,
        bvh,
        materials,
        lights,
        epsilon: 5e-5 * diag.max(1e-3),
        meshes,
        cache_stats,
        sources,
        content_hash,
        warnings,
    }
}
