//! `displace compare`: every technique of [`displace_core::techniques`]
//! against the exact reference on seeded rays, over height maps, view
//! elevations and budgets (BENCHMARKS.md), measured by
//! [`measure`]; this command reads the maps, times on the
//! GPU when asked and writes the files. Writes `compare.csv` (one row per map,
//! elevation, technique and budget), `precompute.csv` (time and memory of
//! each technique's precomputation per map), one plot of error against cost
//! per map, and an image grid of one view rendered by each technique at
//! equal cost beside the exact render and error heat maps.

#[cfg(feature = "gpu")]
mod gpu_costs;
mod grid;
mod measure;
mod plot;

use crate::args::{load_height, parse_extent, HeightArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use displace_core::convention::parse_size;
use displace_core::io::atomic::{write_atomic, Batch};
use displace_core::io::height::{self, HeightOptions};
use displace_core::techniques::Technique;
use displace_core::{generators, Address, Extent, HeightMap};
use measure::{csv, elevation_rays, measure_elevation, peak, prepare, ray_seed, Plan};
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// Output directory (created if missing): compare.csv, precompute.csv,
    /// plot_MAP.png per map, grid.png
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// More height maps to compare on (PNG, EXR or gen:...), beside every
    /// built-in generator; repeat the flag for several
    #[arg(long = "height", value_name = "HEIGHT")]
    pub heights: Vec<String>,
    /// Only these height maps (no built-in generators unless --height names
    /// them)
    #[arg(long)]
    pub only_given: bool,
    /// Texels of generated maps, WxH [default: 128x128; --quick: 32x32]
    #[arg(long, value_name = "WxH")]
    pub height_size: Option<String>,
    /// Physical width, height and displacement depth of the face
    #[arg(long, default_value = "1,1,0.1", value_name = "SX,SY,SZ", value_parser = parse_extent, allow_hyphen_values = true)]
    pub extent: Extent,
    /// Depth slices of the distance map (its W x H is the height map's)
    #[arg(long, default_value_t = 16)]
    pub depth: usize,
    /// Techniques, comma-separated [default: all]
    #[arg(long, value_delimiter = ',')]
    pub techniques: Option<Vec<String>>,
    /// Budgets (layers, steps or node visits), comma-separated
    /// [default: 4,8,16,32,64,128; --quick: 4,16]
    #[arg(long)]
    pub budgets: Option<String>,
    /// View elevations in degrees above the face, comma-separated
    /// [default: 5,10,20,45,90; --quick: 10,60]
    #[arg(long)]
    pub elevations: Option<String>,
    /// Rays per map and elevation [default: 2000; --quick: 64]
    #[arg(long)]
    pub rays: Option<usize>,
    /// Seed of the ray sets
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Fetches per ray the image grid's techniques may spend (each gets its
    /// largest budget within it)
    #[arg(long, default_value_t = 32.0)]
    pub grid_fetches: f64,
    /// Also time every technique and budget on the GPU (compute shader,
    /// `displace_gpu::technique_costs`): the `gpu_ns_per_ray` column. Fails
    /// when no GPU adapter is found
    #[arg(long)]
    pub gpu: bool,
    /// Rays per GPU dispatch: the measured rays repeated to this many, so
    /// the time is the GPU's and not the dispatch overhead's
    /// [default: 262144; --quick: 4096]
    #[arg(long, value_name = "N")]
    pub gpu_rays: Option<usize>,
    /// Timed GPU dispatches per technique and budget (after one warm-up)
    #[arg(long, default_value_t = 5)]
    pub gpu_frames: u32,
    /// Small sizes, for tests
    #[arg(long)]
    pub quick: bool,
}

fn parse_list<T: std::str::FromStr>(s: &str, what: &str) -> Result<Vec<T>> {
    let v: Result<Vec<T>> = s
        .split(',')
        .map(|p| {
            p.trim()
                .parse::<T>()
                .map_err(|_| anyhow::anyhow!("--{what} {s}: `{p}` is not a number"))
        })
        .collect();
    let v = v?;
    if v.is_empty() {
        bail!("--{what}: empty list");
    }
    Ok(v)
}

/// The settings after defaults and `--quick`: what to measure, and the
/// texels of generated maps.
fn plan(args: &CompareArgs) -> Result<(Plan, [usize; 2])> {
    let techniques = match &args.techniques {
        None => Technique::ALL.to_vec(),
        Some(names) => names
            .iter()
            .map(|n| n.trim().parse::<Technique>().context("--techniques"))
            .collect::<Result<_>>()?,
    };
    let budgets: Vec<u32> = parse_list(
        args.budgets.as_deref().unwrap_or(if args.quick {
            "4,16"
        } else {
            "4,8,16,32,64,128"
        }),
        "budgets",
    )?;
    if let Some(b) = budgets.iter().find(|&&b| b == 0 || b > 1 << 16) {
        bail!("--budgets: {b} is out of range (1 to 65536)");
    }
    let elevations: Vec<f32> = parse_list(
        args.elevations
            .as_deref()
            .unwrap_or(if args.quick { "10,60" } else { "5,10,20,45,90" }),
        "elevations",
    )?;
    if let Some(e) = elevations.iter().find(|e| !(**e > 0.0 && **e <= 90.0)) {
        bail!("--elevations: {e} is not in (0, 90] degrees");
    }
    let rays = args.rays.unwrap_or(if args.quick { 64 } else { 2000 });
    if rays == 0 {
        bail!("--rays must be positive");
    }
    let size = match &args.height_size {
        Some(s) => parse_size::<2>(s).with_context(|| format!("--height-size {s}"))?,
        None if args.quick => [32, 32],
        None => [128, 128],
    };
    if args.depth < 2 {
        bail!("--depth must be at least 2");
    }
    let plan = Plan {
        techniques,
        budgets,
        elevations,
        rays,
    };
    Ok((plan, size))
}

/// Short name of a height source for the CSV and file names.
fn map_name(spec: &str) -> String {
    let base = spec
        .strip_prefix(generators::PREFIX)
        .map(str::to_string)
        .unwrap_or_else(|| {
            Path::new(spec)
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_else(|| spec.to_string())
        });
    base.chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '-' {
                c
            } else {
                '_'
            }
        })
        .collect()
}

/// Refuses a comparison whose estimated peak ([`peak::peak_bytes`])
/// exceeds the memory limit ([`displace_core::memory`]), from the height
/// maps' headers alone, before any map is decoded or generated.
fn check_memory(
    args: &CompareArgs,
    plan: &Plan,
    sources: &[String],
    opts: &HeightOptions,
) -> Result<()> {
    let sizes = sources
        .iter()
        .map(|s| {
            let [w, h] =
                height::dimensions(s, opts).with_context(|| format!("loading height map `{s}`"))?;
            // One buffer too large says so first; then the whole job.
            HeightMap::check_size(w, h).with_context(|| format!("height map `{s}`"))?;
            Ok([w, h])
        })
        .collect::<Result<Vec<_>>>()?;
    let largest = sizes
        .iter()
        .max_by_key(|s| s[0] as u128 * s[1] as u128)
        .expect("at least one map");
    let gpu_rays = args.gpu.then(|| gpu_rays(args));
    displace_core::memory::check(
        &format!(
            "compare on {} height maps (the largest {}x{}) with {} depth slices and {} rays",
            sizes.len(),
            largest[0],
            largest[1],
            args.depth,
            plan.rays
        ),
        peak::peak_bytes(&sizes, args.depth, &plan.techniques, plan.rays, gpu_rays),
    )?;
    Ok(())
}

/// Rays per GPU dispatch: `--gpu-rays`, or its default.
fn gpu_rays(args: &CompareArgs) -> usize {
    args.gpu_rays
        .unwrap_or(if args.quick { 4096 } else { 1 << 18 })
}

/// The output directory, created before the work so that a path that
/// cannot be one fails first, and removed again (with any parents this run
/// made) when the command fails, as every output of a failed command is:
/// the outputs themselves land only at the end ([`Batch`]).
struct OutputDir {
    /// The directories this run created, deepest first.
    created: Vec<PathBuf>,
}

impl OutputDir {
    fn create(dir: &Path) -> Result<Self> {
        let ancestors = || dir.ancestors().filter(|a| !a.as_os_str().is_empty());
        if let Some(not_dir) = ancestors().find(|a| a.exists() && !a.is_dir()) {
            bail!(
                "--out {}: {} is a file, not a directory (compare writes its CSVs, plots and grid into a directory)",
                dir.display(),
                not_dir.display()
            );
        }
        let created: Vec<PathBuf> = ancestors()
            .take_while(|a| !a.exists())
            .map(Path::to_path_buf)
            .collect();
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating the output directory {}", dir.display()))?;
        Ok(Self { created })
    }

    /// The command succeeded: the directories stay.
    fn keep(mut self) {
        self.created.clear();
    }
}

impl Drop for OutputDir {
    fn drop(&mut self) {
        // `remove_dir` removes only empty directories: nothing but what
        // this run made and left empty goes.
        for d in &self.created {
            let _ = std::fs::remove_dir(d);
        }
    }
}

pub fn run(args: CompareArgs) -> Result<()> {
    // Installed before anything is created: an interrupt stops the work at
    // the next map, elevation or precomputation and leaves nothing behind
    // (the output directory this run made is removed again).
    let cancel = crate::progress::cancel_flag();
    let result = compare(args, &cancel);
    if cancel.load(std::sync::atomic::Ordering::SeqCst) {
        bail!("interrupted: nothing was written");
    }
    result
}

fn compare(args: CompareArgs, cancel: &Arc<AtomicBool>) -> Result<()> {
    let interrupted = || {
        if cancel.load(std::sync::atomic::Ordering::SeqCst) {
            bail!("interrupted: nothing was written");
        }
        Ok(())
    };
    let (plan, size) = plan(&args)?;
    let mut sources: Vec<String> = if args.only_given {
        Vec::new()
    } else {
        generators::NAMES
            .iter()
            .map(|n| format!("{}{n}", generators::PREFIX))
            .collect()
    };
    sources.extend(args.heights.iter().cloned());
    if sources.is_empty() {
        bail!("--only-given with no --height: nothing to compare");
    }
    // The generators' size is passed to `load_height` as its default; a
    // file keeps its own.
    let height_args = HeightArgs {
        height_size: None,
        channel: None,
        address: Address::Clamp,
        height_range: None,
    };
    let opts = height_args.options(size);
    check_memory(&args, &plan, &sources, &opts)?;
    let out_dir = OutputDir::create(&args.out)?;
    // Read every map first: a bad file fails before minutes of work.
    let heights = sources
        .iter()
        .map(|s| load_height(s, &height_args, size).map(|h| (map_name(s), h)))
        .collect::<Result<Vec<_>>>()?;

    #[cfg(not(feature = "gpu"))]
    if args.gpu {
        bail!("--gpu: {}", crate::NO_GPU);
    }
    #[cfg(feature = "gpu")]
    let gpu = if args.gpu {
        if args.gpu_frames == 0 {
            bail!("--gpu-frames must be positive");
        }
        let n = gpu_rays(&args);
        if n == 0 {
            bail!("--gpu-rays must be positive");
        }
        let ctx = displace_gpu::GpuContext::new_headless().context(
            "--gpu: no usable GPU adapter (install a Vulkan driver, e.g. mesa-vulkan-drivers)",
        )?;
        let info = ctx.adapter.get_info();
        println!("GPU: {} ({:?})", info.name, info.backend);
        Some((ctx, n))
    } else {
        None
    };

    let started = Instant::now();
    let mut rows = Vec::new();
    let mut precompute = Vec::new();
    let mut grid_maps = None;
    for (k, (name, height)) in heights.into_iter().enumerate() {
        interrupted()?;
        let (maps, report) = prepare(height, args.extent, args.depth, &plan.techniques, cancel)?;
        for p in report {
            precompute.push((name.clone(), p));
        }
        for &elevation in &plan.elevations {
            let seed = ray_seed(args.seed, k, elevation);
            let rays = elevation_rays(maps.aspect, elevation, plan.rays, seed);
            #[cfg_attr(not(feature = "gpu"), allow(unused_mut))]
            let mut measured = measure_elevation(&maps, &name, &plan, elevation, &rays)?;
            interrupted()?;
            #[cfg(feature = "gpu")]
            if let Some((ctx, n)) = &gpu {
                gpu_costs::time_on_gpu(ctx, &maps, &rays, *n, args.gpu_frames, &mut measured)?;
            }
            rows.extend(measured);
        }
        // The grid shows the first map the user gave, else the text map.
        let wanted = if args.heights.is_empty() {
            "text".to_string()
        } else {
            map_name(&args.heights[0])
        };
        if name == wanted || (grid_maps.is_none() && k == 0) {
            grid_maps = Some((name.clone(), maps));
        }
    }

    // The CSVs, plots and grid land together: a failure (a full disk) in
    // the last leaves none of them.
    let batch = Batch::new();
    let csv = args.out.join("compare.csv");
    write_atomic(&csv, |w| csv::write_rows(w, &rows))
        .with_context(|| format!("writing {}", csv.display()))?;
    let pre = args.out.join("precompute.csv");
    write_atomic(&pre, |w| csv::write_precompute(w, &precompute))
        .with_context(|| format!("writing {}", pre.display()))?;
    let equal = args.out.join("equal_error.csv");
    write_atomic(&equal, |w| csv::write_equal_error(w, &rows))
        .with_context(|| format!("writing {}", equal.display()))?;

    let plots = plot::write_all(&args.out, &rows, &plan.techniques)?;
    let (grid_name, grid_maps) = grid_maps.expect("at least one map");
    let grid_path = args.out.join("grid.png");
    let picked = grid::write(
        &grid_path,
        &grid_maps,
        &plan.techniques,
        &plan.budgets,
        args.grid_fetches,
        if args.quick { 48 } else { 128 },
    )?;
    batch.commit().context("moving the outputs into place")?;
    out_dir.keep();

    println!(
        "compared {} techniques on {} maps x {} elevations x {} rays in {:.1} s",
        plan.techniques.len(),
        rows.iter()
            .map(|r| &r.map)
            .collect::<std::collections::BTreeSet<_>>()
            .len(),
        plan.elevations.len(),
        plan.rays,
        started.elapsed().as_secs_f64()
    );
    for (map, p) in &precompute {
        println!(
            "  precompute {map:>10} {:<17} {:>8.3} s {:>8} KiB",
            p.name,
            p.seconds,
            p.bytes / 1024
        );
    }
    println!("-> {}", csv.display());
    println!("-> {}", pre.display());
    println!("-> {}", equal.display());
    for p in plots {
        println!("-> {}", p.display());
    }
    println!(
        "-> {} ({grid_name}; at about {} fetches per ray: {})",
        grid_path.display(),
        args.grid_fetches,
        picked
            .iter()
            .map(|(t, b)| format!("{} {b}", t.name()))
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}
