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

use super::rays::read_rays_with_length;
use anyhow::{Context, Result};
use displace_render::geometry::Ray;
use displace_render::scene::batch::{Batch, GeometryHit};
use displace_render::{Scene, SceneOptions};
use glam::Vec3;
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// What a miss reports in the shape column.
const MISS: f32 = -1.0;
/// What a hit on a visible area light's quad reports in the shape column.
const LIGHT: f32 = -2.0;

/// Rays per batch query: enough for the packets of each face to fill.
const BATCH: usize = 64;

/// One world ray of a rays file: the unit ray and its length limit in world
/// units (the file's `t_max` is in units of the direction's length).
fn world_ray(r: &[f32; 7]) -> (Ray, f32, f32) {
    let dir = Vec3::new(r[3], r[4], r[5]);
    let len = dir.length();
    (
        Ray::from_unit(Vec3::new(r[0], r[1], r[2]), dir / len),
        r[6] * len,
        len,
    )
}

/// What one thread's batches reuse: the batch queries' buffers, the world
/// rays of a batch ([`world_ray`]: rays, limits, directions' lengths) and
/// their answers, so a batch allocates nothing after the first.
#[derive(Default)]
pub struct Scratch {
    batch: Batch,
    rays: Vec<Ray>,
    limits: Vec<f32>,
    lens: Vec<f32>,
    hits: Vec<Option<GeometryHit>>,
    blocked: Vec<bool>,
}

impl Scratch {
    fn load(&mut self, rays: &[[f32; 7]]) {
        self.rays.clear();
        self.limits.clear();
        self.lens.clear();
        for r in rays {
            let (ray, t_max, len) = world_ray(r);
            self.rays.push(ray);
            self.limits.push(t_max);
            self.lens.push(len);
        }
    }
}

/// The first hits of a batch of world rays, each `[t, x, y, z, nx, ny,
/// nz, shape]`, into `out` (8 values a ray).
pub fn first_hits(scene: &Scene, rays: &[[f32; 7]], sc: &mut Scratch, out: &mut [f32]) {
    sc.load(rays);
    scene.intersect_geometry_many(&sc.rays, 0.0, &sc.limits, &mut sc.batch, &mut sc.hits);
    // Rows as arrays: a slice copy of eight values is a call to `memcpy`.
    for ((o, hit), &len) in out.chunks_exact_mut(8).zip(&sc.hits).zip(&sc.lens) {
        let o: &mut [f32; 8] = o.try_into().expect("rows of eight values");
        *o = row(scene, hit, len);
    }
}

/// Whether anything blocks each of a batch of world rays within `(0,
/// t_max)`: 1 or 0 each, into `out`.
pub fn blocked_many(scene: &Scene, rays: &[[f32; 7]], sc: &mut Scratch, out: &mut [f32]) {
    sc.load(rays);
    scene.occluded_many(&sc.rays, 0.0, &sc.limits, &mut sc.batch, &mut sc.blocked);
    for (o, &b) in out.iter_mut().zip(&sc.blocked) {
        *o = f32::from(u8::from(b));
    }
}

/// A hit as a row of the hits file.
fn row(scene: &Scene, hit: &Option<GeometryHit>, len: f32) -> [f32; 8] {
    match hit {
        Some(hit) => {
            let (p, n) = (hit.position, hit.normal);
            let shape = scene.shape_of(hit.prim).map_or(LIGHT, |k| k as f32);
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

/// Loads `scene`, traces every ray of `rays` and writes `output`.
pub fn run(scene: &Path, rays: &Path, output: &Path, any_hit: bool, cache: bool) -> Result<()> {
    crate::outputs::check_npy_output(output)?;
    crate::outputs::check_not_inputs(&[("-o", output)], &[("--rays", rays), ("--scene", scene)])?;
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
    let written = [("-o".to_string(), output.to_path_buf())];
    crate::outputs::check_not_scene_inputs(&written, scene.sources(), None)?;
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
    // Batches of rays in file order, each traced eight at a time through
    // the displaced faces; a ray's answer is the one-ray query's whatever
    // its batch, so the output does not depend on the thread count.
    if any_hit {
        flat.par_chunks_mut(BATCH)
            .zip(rays.par_chunks(BATCH))
            .for_each_init(Scratch::default, |b, (o, r)| blocked_many(&scene, r, b, o));
    } else {
        flat.par_chunks_mut(8 * BATCH)
            .zip(rays.par_chunks(BATCH))
            .for_each_init(Scratch::default, |b, (o, r)| first_hits(&scene, r, b, o));
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
