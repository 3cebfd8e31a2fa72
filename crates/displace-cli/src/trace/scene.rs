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
use anyhow::{bail, Context, Result};
use displace_render::scene::queries::{blocked_all, first_hits_all};
use displace_render::{Scene, SceneOptions};
use std::path::Path;
use std::time::Instant;

/// Refuses a ray file whose queries would not fit in memory
/// ([`displace_core::memory`]), from its size alone, before it is read: the
/// file's bytes and their floats, the rays as the tracer takes them (seven
/// floats each), and the answers (one pass's, and a second buffer that
/// repeated passes are checked against), at six floats a row, the
/// narrowest rays. (The scene's own bakes are checked as it loads.)
fn check_memory(rays: &Path, any_hit: bool, repeat: u32) -> Result<()> {
    let Ok(meta) = std::fs::metadata(rays) else {
        // Reading it names the problem.
        return Ok(());
    };
    let bytes = meta.len() as u128;
    let rows = bytes / 24;
    let columns: u128 = if any_hit { 1 } else { 8 };
    let answers = if repeat > 0 { 2 } else { 1 };
    displace_core::memory::check(
        &format!("trace --scene of {} (up to {rows} rays)", rays.display()),
        2 * bytes + rows * 28 + answers * rows * columns * 4,
    )?;
    Ok(())
}

/// Loads `scene`, traces every ray of `rays` and writes `output`. With
/// `repeat` above 0 the queries run that many more times after the first
/// pass, and the rate printed is the best of those passes: a peer timed
/// after an untimed first call (the render benchmark's Embree) is then
/// compared with our warm passes, not with a first pass that also pays for
/// waking the thread pool and faulting in its buffers. The first pass's
/// rate is printed too.
pub fn run(
    scene: &Path,
    rays: &Path,
    output: &Path,
    any_hit: bool,
    cache: bool,
    repeat: u32,
) -> Result<()> {
    crate::outputs::check_npy_output(output)?;
    crate::outputs::check_not_inputs(&[("-o", output)], &[("--rays", rays), ("--scene", scene)])?;
    check_memory(rays, any_hit, repeat)?;
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
    let pass = |out: &mut [f32]| {
        let start = Instant::now();
        if any_hit {
            blocked_all(&scene, &rays, out);
        } else {
            first_hits_all(&scene, &rays, out);
        }
        start.elapsed().as_secs_f64()
    };
    let first = pass(&mut flat);
    let mut seconds = first;
    if repeat > 0 {
        let mut again = vec![f32::NAN; flat.len()];
        seconds = f64::INFINITY;
        for _ in 0..repeat {
            seconds = seconds.min(pass(&mut again));
            // The queries are deterministic: a pass that answers otherwise
            // is a defect to report, not a timing to print.
            if again
                .iter()
                .zip(&flat)
                .any(|(a, b)| a.to_bits() != b.to_bits())
            {
                bail!("a repeated pass over the rays gave different answers than the first");
            }
        }
    }
    let found = if any_hit {
        flat.iter().filter(|&&b| b > 0.0).count()
    } else {
        flat.chunks(8).filter(|h| h[0].is_finite()).count()
    };
    displace_core::io::npy::write_file(output, &[rays.len(), columns], &flat)
        .with_context(|| format!("writing {}", output.display()))?;
    let rate = |s: f64| rays.len() as f64 / s.max(1e-9) / 1e6;
    let passes = if repeat > 0 {
        format!(
            ", the best of {repeat} passes after the first; the first {:.2} Mrays/s",
            rate(first)
        )
    } else {
        String::new()
    };
    println!(
        "traced {} rays ({} {}) in {:.3} s ({:.2} Mrays/s on {} threads{passes}) -> {}",
        rays.len(),
        found,
        if any_hit { "blocked" } else { "hits" },
        seconds,
        rate(seconds),
        rayon::current_num_threads(),
        output.display()
    );
    Ok(())
}
