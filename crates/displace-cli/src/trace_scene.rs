//! `displace trace --scene`: batch ray queries against a whole scene, the
//! interface Embree's users know (`rtcIntersect` for the first hit,
//! `rtcOccluded` for shadow rays), so that external tools can check and
//! time our surfaces, displaced or not, against theirs on the same rays.
//!
//! Rays are in the scene's world frame: float32 `(N, 6)` (origin, direction)
//! or `(N, 7)` (origin, direction, `t_max`), with `t` measured along the
//! direction *as given* (`hit = origin + t dir`), as `displace trace`
//! reports it for a lone face; a missing `t_max` is unbounded.
//!
//! First hits are `(N, 8)`: `t` (inf on a miss), the hit position xyz, the
//! geometric normal xyz (unit, as the shape defines it, not turned towards
//! the ray) and the index of the shape in the file's `[[shapes]]` list (-1
//! on a miss, -2 on a visible area light's quad). Any-hit queries are
//! `(N, 1)`: 1 where something lies on the ray within `(0, t_max)`, else 0.

use crate::trace::read_rays_with_length;
use anyhow::{Context, Result};
use displace_render::geometry::Ray;
use displace_render::{Scene, SceneOptions};
use glam::Vec3;
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// What a miss reports in the shape column.
const MISS: f32 = -1.0;
/// What a hit on a visible area light's quad reports in the shape column.
const LIGHT: f32 = -2.0;

/// The first hit of one world ray: `[t, x, y, z, nx, ny, nz, shape]`.
pub fn first_hit(scene: &Scene, r: &[f32; 7]) -> [f32; 8] {
    let dir = Vec3::new(r[3], r[4], r[5]);
    let len = dir.length();
    let ray = Ray::new(Vec3::new(r[0], r[1], r[2]), dir);
    match scene.intersect_primitive(&ray, 0.0, r[6] * len) {
        Some((prim, hit)) => {
            let (p, n) = (hit.position, hit.geometric_normal);
            let shape = scene.shape_of(prim).map_or(LIGHT, |k| k as f32);
            [hit.t / len, p.x, p.y, p.z, n.x, n.y, n.z, shape]
        }
        None => [
            f32::INFINITY,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            f32::NAN,
            MISS,
        ],
    }
}

/// Whether anything blocks one world ray within `(0, t_max)`: 1 or 0.
pub fn blocked(scene: &Scene, r: &[f32; 7]) -> f32 {
    let dir = Vec3::new(r[3], r[4], r[5]);
    let ray = Ray::new(Vec3::new(r[0], r[1], r[2]), dir);
    f32::from(u8::from(scene.occluded(&ray, 0.0, r[6] * dir.length())))
}

/// Loads `scene`, traces every ray of `rays` and writes `output`.
pub fn run(scene: &Path, rays: &Path, output: &Path, any_hit: bool, cache: bool) -> Result<()> {
    crate::bake::check_npy_output(output)?;
    let rays = read_rays_with_length(rays)?;
    let opts = SceneOptions {
        cache_dir: if cache {
            displace_render::default_cache_dir()
        } else {
            None
        },
        ..SceneOptions::default()
    };
    let start = Instant::now();
    let scene =
        Scene::load(scene, &opts).with_context(|| format!("loading scene {}", scene.display()))?;
    println!(
        "loaded the scene in {:.3} s (displacement maps {:.1} MB)",
        start.elapsed().as_secs_f64(),
        scene.map_bytes() as f64 / 1e6
    );
    // The output is allocated and touched before the clock starts, so the
    // rate is that of the queries, not of the kernel handing out pages.
    let columns = if any_hit { 1 } else { 8 };
    let mut flat = vec![f32::NAN; rays.len() * columns];
    let start = Instant::now();
    if any_hit {
        flat.par_iter_mut()
            .zip(&rays)
            .for_each(|(o, r)| *o = blocked(&scene, r));
    } else {
        flat.par_chunks_mut(8)
            .zip(&rays)
            .for_each(|(o, r)| o.copy_from_slice(&first_hit(&scene, r)));
    }
    let seconds = start.elapsed().as_secs_f64();
    let found = if any_hit {
        flat.iter().filter(|&&b| b > 0.0).count()
    } else {
        flat.chunks(8).filter(|h| h[0].is_finite()).count()
    };
    displace_core::io::npy::write_file(output, &[rays.len(), columns], &flat)
        .with_context(|| format!("writing {}", output.display()))?;
    println!(
        "traced {} rays ({} {}) in {:.3} s ({:.2} Mrays/s on {} threads) -> {}",
        rays.len(),
        found,
        if any_hit { "blocked" } else { "hits" },
        seconds,
        rays.len() as f64 / seconds.max(1e-9) / 1e6,
        rayon::current_num_threads(),
        output.display()
    );
    Ok(())
}
