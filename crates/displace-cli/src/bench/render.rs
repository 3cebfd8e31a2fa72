//! `displace bench render`: primary and shadow rays per second on displaced
//! surfaces, per scene, on one core and on all (BENCHMARKS.md).
//!
//! The rays are the render's own ([`displace_render::probe`]): every camera
//! ray whose nearest hit is on a displaced face, and the shadow rays shading
//! casts from those hits. They are generated once, then traced alone (no
//! shading), in a one-thread rayon pool and in an all-core pool of the same
//! process, so both columns time the same work. Each figure is the best of
//! `--repeat` runs after one warm-up run, the usual way to read throughput
//! on a machine other work shares. Setup is the scene build including the
//! bake, with the disk cache off so it is timed every time.

use super::probe::{displaced_rays, DisplacedRays};
use anyhow::{bail, Context, Result};
use displace_render::{Scene, SceneOptions};
use rayon::prelude::*;
use rayon::ThreadPool;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The seed scenes with displaced faces, each stressing something else:
/// sharp studs under a point light, a tall gaussian under an area light,
/// three crossing instances, noise.
const DEFAULT_SCENES: [&str; 4] = [
    "cornell_studded",
    "cornell_gaussian",
    "cornell_crossing",
    "stone",
];

#[derive(clap::Args, Debug)]
pub struct BenchRenderArgs {
    /// Scene files [default: scenes/{cornell_studded, cornell_gaussian,
    /// cornell_crossing, stone}.toml]
    pub scenes: Vec<PathBuf>,
    /// Image size WxH (overrides the scenes')
    #[arg(long, value_name = "WxH", default_value = "256x256")]
    pub size: String,
    /// Samples per pixel (overrides the scenes')
    #[arg(long, default_value_t = 4)]
    pub spp: u32,
    /// Threads of the "all cores" pool [default: all cores]
    #[arg(long)]
    pub threads: Option<usize>,
    /// Timed runs per figure; the best is reported
    #[arg(long, default_value_t = 3)]
    pub repeat: u32,
    /// Tab-separated values instead of the table (for scripts)
    #[arg(long)]
    pub tsv: bool,
}

/// One scene's measurements.
struct Row {
    name: String,
    setup_s: f64,
    rays: DisplacedRays,
    /// Best seconds for (primary, shadow) on one thread and on all.
    one: (f64, f64),
    all: (f64, f64),
    occluded: usize,
}

pub fn run(args: BenchRenderArgs) -> Result<()> {
    let size = displace_core::convention::parse_size::<2>(&args.size)
        .map(|[w, h]| [w as u32, h as u32])
        .with_context(|| format!("--size {}", args.size))?;
    if args.spp == 0 {
        bail!("--spp must be at least 1");
    }
    if args.repeat == 0 {
        bail!("--repeat must be at least 1");
    }
    let scenes = if args.scenes.is_empty() {
        DEFAULT_SCENES
            .iter()
            .map(|n| default_scene_path(n))
            .collect::<Result<Vec<_>>>()?
    } else {
        args.scenes.clone()
    };
    for s in &scenes {
        if !s.is_file() {
            bail!("scene {}: no such file", s.display());
        }
    }
    let one = crate::threads::pool(Some(1))?;
    let all = crate::threads::pool(args.threads)?;
    let opts = SceneOptions {
        spp: Some(args.spp),
        size: Some(size),
        ..SceneOptions::default()
    };

    let mut rows = Vec::new();
    for path in &scenes {
        let start = Instant::now();
        let scene = all
            .install(|| Scene::load(path, &opts))
            .with_context(|| format!("loading scene {}", path.display()))?;
        let setup_s = start.elapsed().as_secs_f64();
        let rays = all
            .install(|| displaced_rays(&scene))
            .with_context(|| format!("generating the rays of {}", path.display()))?;
        if rays.camera.is_empty() {
            bail!(
                "scene {}: no camera ray meets a displaced surface at {}x{}",
                path.display(),
                size[0],
                size[1]
            );
        }
        let (p1, s1, occluded) = time_pool(&one, &scene, &rays, args.repeat);
        let (pn, sn, _) = time_pool(&all, &scene, &rays, args.repeat);
        rows.push(Row {
            name: path.file_stem().map_or_else(
                || path.display().to_string(),
                |s| s.to_string_lossy().into(),
            ),
            setup_s,
            rays,
            one: (p1, s1),
            all: (pn, sn),
            occluded,
        });
    }
    if args.tsv {
        print_tsv(&rows, all.current_num_threads());
    } else {
        print_table(&rows, size, args.spp, all.current_num_threads());
    }
    Ok(())
}

/// `scenes/NAME.toml` under the working directory, else in the source tree
/// this binary was built from.
fn default_scene_path(name: &str) -> Result<PathBuf> {
    let file = format!("{name}.toml");
    let here = Path::new("scenes").join(&file);
    if here.is_file() {
        return Ok(here);
    }
    let built = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenes")
        .join(&file);
    if built.is_file() {
        return Ok(built);
    }
    bail!(
        "default scene {file}: not in ./scenes or {}; name scene files on the command line",
        built.display()
    )
}

/// Best seconds of (primary, shadow) in `pool`, and how many shadow rays
/// were blocked (a check that the work was done, and a figure of its own).
fn time_pool(
    pool: &ThreadPool,
    scene: &Scene,
    rays: &DisplacedRays,
    repeat: u32,
) -> (f64, f64, usize) {
    pool.install(|| {
        let primary = best_of(repeat, || {
            rays.camera
                .par_chunks(256)
                .map(|c| {
                    c.iter()
                        .filter(|r| scene.intersect(r, 0.0, f32::INFINITY).is_some())
                        .count()
                })
                .sum::<usize>()
        });
        let mut occluded = 0;
        let shadow = best_of(repeat, || {
            occluded = rays
                .shadow
                .par_chunks(256)
                .map(|c| {
                    c.iter()
                        .filter(|s| scene.occluded(&s.ray, 0.0, s.t_max))
                        .count()
                })
                .sum::<usize>();
        });
        (primary, shadow, occluded)
    })
}

/// Best wall time of `repeat` runs of `f` after one untimed warm-up.
fn best_of<T>(repeat: u32, mut f: impl FnMut() -> T) -> f64 {
    std::hint::black_box(f());
    (0..repeat)
        .map(|_| {
            let t = Instant::now();
            std::hint::black_box(f());
            t.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn mrays(n: usize, s: f64) -> f64 {
    n as f64 / s.max(1e-12) / 1e6
}

fn print_table(rows: &[Row], size: [u32; 2], spp: u32, threads: usize) {
    println!(
        "rays on displaced surfaces, {}x{} at {spp} spp; Mrays/s on 1 thread and on {threads} \
         (best of runs); prim xN: primary speed-up on {threads} threads",
        size[0], size[1]
    );
    println!(
        "{:<20} {:>8} {:>10} {:>10} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9}",
        "scene",
        "setup s",
        "primary",
        "shadow",
        "blocked",
        "prim 1t",
        "prim Nt",
        "shad 1t",
        "shad Nt",
        "prim xN"
    );
    for r in rows {
        let (np, ns) = (r.rays.camera.len(), r.rays.shadow.len());
        println!(
            "{:<20} {:>8.2} {:>10} {:>10} {:>8.1}% {:>9.2} {:>9.2} {:>9.2} {:>9.2} {:>8.2}x",
            r.name,
            r.setup_s,
            np,
            ns,
            100.0 * r.occluded as f64 / ns.max(1) as f64,
            mrays(np, r.one.0),
            mrays(np, r.all.0),
            mrays(ns, r.one.1),
            mrays(ns, r.all.1),
            r.one.0 / r.all.0.max(1e-12),
        );
    }
}

fn print_tsv(rows: &[Row], threads: usize) {
    println!(
        "scene\tsetup_s\tcamera_rays\tprimary_rays\tshadow_rays\toccluded\tprimary_mrays_1t\tprimary_mrays_{threads}t\tshadow_mrays_1t\tshadow_mrays_{threads}t"
    );
    for r in rows {
        let (np, ns) = (r.rays.camera.len(), r.rays.shadow.len());
        println!(
            "{}\t{:.4}\t{}\t{np}\t{ns}\t{}\t{:.4}\t{:.4}\t{:.4}\t{:.4}",
            r.name,
            r.setup_s,
            r.rays.camera_total,
            r.occluded,
            mrays(np, r.one.0),
            mrays(np, r.all.0),
            mrays(ns, r.one.1),
            mrays(ns, r.all.1),
        );
    }
}
