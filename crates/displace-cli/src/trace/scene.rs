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
use displace_render::scene::queries::{blocked_all, first_hits_all};
use displace_render::{Scene, SceneOptions};
use std::path::Path;
use std::time::Instant;

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
        cancel: Some(crate::progress::cancel_flag()),
        no_image: true,
        ..SceneOptions::default()
    };
    let start = Instant::now();
    let scene = crate::progress::loaded(Scene::load(scene, &opts))
        .with_context(|| format!("loading scene {}", scene.display()))?;
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
    if any_hit {
        blocked_all(&scene, &rays, &mut flat);
    } else {
        first_hits_all(&scene, &rays, &mut flat);
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
