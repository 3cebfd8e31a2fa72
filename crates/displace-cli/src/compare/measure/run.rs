//! Tracing a plan's techniques on one elevation's rays: the exact hits, and
//! each technique's hits, fetches and time per ray, scored into rows.

use super::{score, CompareError, Plan, Row};
use displace_core::random::rays::{tile_rays, Elevation, Start};
use displace_core::techniques::{Maps, Technique};
use displace_core::{MapRay, Method, TraceOptions};
use glam::Vec2;
use std::time::Instant;

/// The seed of the rays of map `map_index` at `elevation` degrees, from the
/// comparison's `seed`: every map and elevation gets its own rays, and the
/// same ones on every run.
pub fn ray_seed(seed: u64, map_index: usize, elevation: f32) -> u64 {
    seed ^ ((map_index as u64) << 32) ^ (elevation.to_bits() as u64)
}

/// `n` rays entering the top of the face at uniform random points,
/// `elevation` degrees above it, uniform random azimuth: the views a
/// rasterised shell polygon starts, grazing to straight down.
pub fn elevation_rays(aspect: [f32; 2], elevation: f32, n: usize, seed: u64) -> Vec<MapRay> {
    tile_rays(
        aspect,
        n,
        seed,
        Start::Above(1.0),
        Elevation::Fixed(elevation),
    )
}

/// The exact hit's texture coordinate, per ray: the reference every
/// technique is scored against (the baked map's [`Method::Exact`]).
///
/// # Panics
///
/// If `maps` has no distance map ([`super::prepare`] always bakes one).
pub fn exact_hits(maps: &Maps, rays: &[MapRay]) -> Vec<Option<Vec2>> {
    let map = maps.displacement.as_ref().expect("always baked");
    let opts = TraceOptions {
        method: Method::Exact,
        ..TraceOptions::default()
    };
    rays.iter()
        .map(|r| map.trace(r, &opts).map(|h| h.uv))
        .collect()
}

/// Rays per timed chunk of [`measure`].
const CHUNK: usize = 100;

/// What one technique at one budget did on a set of rays.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    /// The hit's texture coordinate per ray.
    pub hits: Vec<Option<Vec2>>,
    /// Mean texture fetches per ray.
    pub fetches: f64,
    /// Time per ray, nanoseconds: the median over chunks of 100 rays,
    /// so that a chunk preempted by another process on a shared machine
    /// does not move the figure.
    pub ns_per_ray: f64,
}

/// Runs `tech` at `budget` on `rays` on this thread.
pub fn measure(
    maps: &Maps,
    tech: Technique,
    budget: u32,
    rays: &[MapRay],
) -> Result<Measured, CompareError> {
    let mut hits = Vec::with_capacity(rays.len());
    let mut fetches = 0u64;
    let mut per_ray = Vec::new();
    for chunk in rays.chunks(CHUNK) {
        let start = Instant::now();
        for ray in chunk {
            let t = tech
                .trace(maps, ray, budget)
                .map_err(|source| CompareError::Trace {
                    technique: tech.name(),
                    budget,
                    source,
                })?;
            fetches += t.fetches as u64;
            hits.push(t.hit.map(|h| h.uv));
        }
        per_ray.push(start.elapsed().as_nanos() as f64 / chunk.len() as f64);
    }
    per_ray.sort_by(f64::total_cmp);
    Ok(Measured {
        hits,
        fetches: fetches as f64 / rays.len() as f64,
        ns_per_ray: per_ray[per_ray.len() / 2],
    })
}

/// Every technique of `plan` at each of its budgets on `rays` (of map `map`
/// seen at `elevation` degrees), scored against the exact hits: the rows in
/// the plan's order of techniques, then budgets.
pub fn measure_elevation(
    maps: &Maps,
    map: &str,
    plan: &Plan,
    elevation: f32,
    rays: &[MapRay],
) -> Result<Vec<Row>, CompareError> {
    let size = [maps.height.width(), maps.height.height()];
    let exact = exact_hits(maps, rays);
    let mut rows = Vec::new();
    for &technique in &plan.techniques {
        for &budget in plan.budgets_for(technique) {
            let m = measure(maps, technique, budget, rays)?;
            let s = score(size, &exact, &m.hits);
            rows.push(Row {
                map: map.to_string(),
                elevation,
                technique,
                budget,
                rays: rays.len(),
                wrong: s.wrong,
                mean_error: s.mean,
                p99_error: s.p99,
                fetches: m.fetches,
                ns_per_ray: m.ns_per_ray,
                gpu_ns_per_ray: None,
            });
        }
    }
    Ok(rows)
}
