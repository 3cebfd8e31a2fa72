//! `displace compare`: every technique of [`displace_core::techniques`]
//! against the exact reference on seeded rays, over height maps, view
//! elevations and budgets (BENCHMARKS.md). Writes `compare.csv` (one row per map,
//! elevation, technique and budget), `precompute.csv` (time and memory of
//! each technique's precomputation per map), one plot of error against cost
//! per map, and an image grid of one view rendered by each technique at
//! equal cost beside the exact render and error heat maps.

mod grid;
mod plot;

use crate::bake::{load_height, parse_extent, HeightArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use displace_core::convention::parse_size;
use displace_core::io::atomic::{write_atomic, Batch};
use displace_core::io::height::{self, HeightOptions};
use displace_core::random::rays::{tile_rays, Elevation, Start};
use displace_core::techniques::{ConeKind, ConeMap, Maps, MaxPyramid, Technique};
use displace_core::{
    bake, generators, Address, BakeOptions, Extent, HeightMap, MapRay, Method, TraceOptions,
};
use glam::Vec2;
use std::path::{Path, PathBuf};
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

/// One row of compare.csv.
#[derive(Clone, Debug)]
pub struct Row {
    pub map: String,
    pub elevation: f32,
    pub technique: Technique,
    pub budget: u32,
    pub rays: usize,
    pub wrong: f64,
    pub mean_error: f64,
    pub p99_error: f64,
    pub fetches: f64,
    pub ns_per_ray: f64,
    /// With `--gpu`: GPU time per ray (compute path), nanoseconds.
    pub gpu_ns_per_ray: Option<f64>,
}

pub const CSV_HEADER: &str = "map,elevation_deg,technique,budget,rays,wrong_fraction,mean_error_texels,p99_error_texels,fetches_per_ray,ns_per_ray,gpu_ns_per_ray";

/// The settings after defaults and `--quick`.
struct Plan {
    techniques: Vec<Technique>,
    budgets: Vec<u32>,
    elevations: Vec<f32>,
    rays: usize,
    size: [usize; 2],
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

fn plan(args: &CompareArgs) -> Result<Plan> {
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
    Ok(Plan {
        techniques,
        budgets,
        elevations,
        rays,
        size,
    })
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

/// Time and memory of one precomputation.
struct Precompute {
    name: &'static str,
    seconds: f64,
    bytes: usize,
}

/// Builds every precomputation the plan's techniques need, timed.
fn prepare(
    height: displace_core::HeightMap,
    extent: Extent,
    depth: usize,
    techniques: &[Technique],
) -> Result<(Maps, Vec<Precompute>)> {
    use displace_core::techniques::Needs;
    let aspect = extent.aspect();
    let mut maps = Maps::new(height.clone(), aspect);
    let mut report = Vec::new();
    let needs = |n: Needs| techniques.iter().any(|t| t.needs() == n);
    if needs(Needs::ConservativeCones) {
        let build = || ConeMap::build(&height, aspect, ConeKind::Conservative);
        maps.cones = Some(timed(&mut report, "cone map", build, ConeMap::bytes));
    }
    if needs(Needs::RelaxedCones) {
        let build = || ConeMap::build(&height, aspect, ConeKind::Relaxed);
        maps.relaxed = Some(timed(
            &mut report,
            "relaxed cone map",
            build,
            ConeMap::bytes,
        ));
    }
    if needs(Needs::Pyramid) {
        let build = || MaxPyramid::build(&height);
        maps.pyramid = Some(timed(&mut report, "max pyramid", build, MaxPyramid::bytes));
    }
    // The exact reference traces through the baked map's `Method::Exact`,
    // so the distance map is always built; it is reported only when a
    // distance technique is compared.
    let opts = BakeOptions::new([height.width(), height.height(), depth], extent);
    let start = Instant::now();
    let baked = bake(&height, &opts).context("baking the distance map")?;
    let seconds = start.elapsed().as_secs_f64();
    if needs(Needs::DistanceMap) {
        report.push(Precompute {
            name: "distance map",
            seconds,
            bytes: baked.distance.data().len() * 4,
        });
    }
    maps.displacement = Some(baked);
    Ok((maps, report))
}

/// Builds one precomputation and reports the time it took and its size.
fn timed<T>(
    report: &mut Vec<Precompute>,
    name: &'static str,
    build: impl FnOnce() -> T,
    bytes: impl Fn(&T) -> usize,
) -> T {
    let start = Instant::now();
    let built = build();
    let seconds = start.elapsed().as_secs_f64();
    report.push(Precompute {
        name,
        seconds,
        bytes: bytes(&built),
    });
    built
}

/// `n` rays entering the top of the face at uniform random points,
/// `elevation` degrees above it, uniform random azimuth.
fn rays(aspect: [f32; 2], elevation: f32, n: usize, seed: u64) -> Vec<MapRay> {
    tile_rays(
        aspect,
        n,
        seed,
        Start::Above(1.0),
        Elevation::Fixed(elevation),
    )
}

/// The exact hit's texture coordinate, per ray.
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

/// Hit error in texels (`None`: wrong hit/miss; `Some(0)` for agreeing
/// misses is not counted as a hit error).
pub fn texel_error(
    height: [usize; 2],
    want: Option<Vec2>,
    got: Option<Vec2>,
) -> Option<Option<f32>> {
    match (want, got) {
        (Some(w), Some(g)) => Some(Some(
            ((g - w) * Vec2::new(height[0] as f32, height[1] as f32)).length(),
        )),
        (None, None) => Some(None),
        _ => None,
    }
}

/// Rays per timed chunk of [`measure`].
const CHUNK: usize = 100;

/// Runs `tech` at `budget` on `rays` on this thread. Returns the hits, the
/// mean fetches per ray and the time per ray: the median over chunks of
/// [`CHUNK`] rays, so that a chunk preempted by another process on a
/// shared machine does not move the figure.
fn measure(
    maps: &Maps,
    tech: Technique,
    budget: u32,
    rays: &[MapRay],
) -> Result<(Vec<Option<Vec2>>, f64, f64)> {
    let mut got = Vec::with_capacity(rays.len());
    let mut fetches = 0u64;
    let mut per_ray = Vec::new();
    for chunk in rays.chunks(CHUNK) {
        let start = Instant::now();
        for ray in chunk {
            let t = tech.trace(maps, ray, budget)?;
            fetches += t.fetches as u64;
            got.push(t.hit.map(|h| h.uv));
        }
        per_ray.push(start.elapsed().as_nanos() as f64 / chunk.len() as f64);
    }
    per_ray.sort_by(f64::total_cmp);
    Ok((
        got,
        fetches as f64 / rays.len() as f64,
        per_ray[per_ray.len() / 2],
    ))
}

fn score(size: [usize; 2], exact: &[Option<Vec2>], got: &[Option<Vec2>]) -> (f64, f64, f64) {
    let mut wrong = 0usize;
    let mut errors = Vec::new();
    for (w, g) in exact.iter().zip(got) {
        match texel_error(size, *w, *g) {
            None => wrong += 1,
            Some(Some(e)) => errors.push(e as f64),
            Some(None) => {}
        }
    }
    errors.sort_by(f64::total_cmp);
    let mean = if errors.is_empty() {
        0.0
    } else {
        errors.iter().sum::<f64>() / errors.len() as f64
    };
    let p99 = if errors.is_empty() {
        0.0
    } else {
        errors[((errors.len() as f64 * 0.99) as usize).min(errors.len() - 1)]
    };
    (wrong as f64 / exact.len() as f64, mean, p99)
}

/// Rows one elevation of one map adds to compare.csv.
fn runs_per_elevation(plan: &Plan) -> usize {
    plan.techniques
        .iter()
        .map(|t| {
            if t.uses_budget() {
                plan.budgets.len()
            } else {
                1
            }
        })
        .sum()
}

/// Fills `gpu_ns_per_ray` of `rows` (one elevation of one map): the rays
/// repeated to `n` per dispatch, every technique and budget timed on the
/// GPU's compute path.
fn time_on_gpu(
    ctx: &displace_gpu::GpuContext,
    maps: &Maps,
    rays: &[MapRay],
    n: usize,
    frames: u32,
    rows: &mut [Row],
) -> Result<()> {
    let batch: Vec<MapRay> = rays.iter().copied().cycle().take(n).collect();
    let runs: Vec<(Technique, u32)> = rows.iter().map(|r| (r.technique, r.budget)).collect();
    let costs = displace_gpu::technique_costs(ctx, maps, &batch, &runs, frames)
        .context("timing the techniques on the GPU")?;
    for (row, cost) in rows.iter_mut().zip(costs) {
        // Milliseconds per million rays are nanoseconds per ray.
        row.gpu_ns_per_ray = Some(cost.ms_per_mray());
    }
    Ok(())
}

/// Error bound of the equal-error table: a 99th percentile below
/// half a texel, with at most 1% of rays getting hit/miss wrong.
pub const EQUAL_ERROR_TEXELS: f64 = 0.5;

/// For every map, elevation and technique (first row of each group), the
/// cheapest row (fewest fetches) within [`EQUAL_ERROR_TEXELS`], if any.
fn equal_error(rows: &[Row]) -> Vec<(&Row, Option<&Row>)> {
    let mut out: Vec<(&Row, Option<&Row>)> = Vec::new();
    for r in rows {
        let ok = r.p99_error < EQUAL_ERROR_TEXELS && r.wrong <= 0.01;
        let same =
            |o: &Row| o.map == r.map && o.elevation == r.elevation && o.technique == r.technique;
        match out.iter_mut().find(|(g, _)| same(g)) {
            Some((_, best)) => {
                if ok && best.is_none_or(|b| r.fetches < b.fetches) {
                    *best = Some(r);
                }
            }
            None => out.push((r, ok.then_some(r))),
        }
    }
    out
}

/// Bytes per height texel every map holds from the start (the maps are
/// all read before any work, so a bad file fails first): its heights.
const LOADED_BYTES_PER_TEXEL: u128 = 4;

/// Bytes per height texel of the map being compared, beyond its bake
/// ([`displace_core::memory::bake_peak_bytes`] counts that): the heights
/// the techniques sample (4) and, when the techniques need them, each cone
/// map (4), the max pyramid (about 4/3 of 4, counted 6) and the scratch of
/// a cone build (the footprints' height ranges and slopes, or the relaxed
/// build's block maxima: 12).
fn prepare_bytes_per_texel(techniques: &[Technique]) -> u128 {
    use displace_core::techniques::Needs;
    let needs = |n: Needs| techniques.iter().any(|t| t.needs() == n);
    let cones = needs(Needs::ConservativeCones) as u128 + needs(Needs::RelaxedCones) as u128;
    4 + 4 * cones + if needs(Needs::Pyramid) { 6 } else { 0 } + if cones > 0 { 12 } else { 0 }
}

/// Estimated peak bytes of the whole comparison: every map's heights, read
/// first; the map being compared with its precomputations and bake; the
/// grid's map, kept from an earlier one when there are several; the rays
/// of one elevation with their exact and measured hits; and with `--gpu`
/// the repeated rays of a dispatch (the batch and its upload).
fn compare_peak_bytes(
    sizes: &[[usize; 2]],
    depth: usize,
    techniques: &[Technique],
    rays: usize,
    gpu_rays: Option<usize>,
) -> u128 {
    let texels = |s: &[usize; 2]| s[0] as u128 * s[1] as u128;
    let loaded: u128 = sizes
        .iter()
        .map(|s| texels(s) * LOADED_BYTES_PER_TEXEL)
        .sum();
    let per_texel = prepare_bytes_per_texel(techniques);
    let working = sizes
        .iter()
        .map(|s| {
            texels(s) * per_texel
                + displace_core::memory::bake_peak_bytes(*s, [s[0], s[1], depth], false)
        })
        .max()
        .unwrap_or(0);
    let grid = if sizes.len() > 1 { working } else { 0 };
    let ray = std::mem::size_of::<MapRay>() as u128;
    let hit = std::mem::size_of::<Option<Vec2>>() as u128;
    let rays = rays as u128 * (ray + 2 * hit) + gpu_rays.map_or(0, |n| 2 * n as u128 * ray);
    loaded + working + grid + rays
}

/// Refuses a comparison whose estimated peak ([`compare_peak_bytes`])
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
        compare_peak_bytes(&sizes, args.depth, &plan.techniques, plan.rays, gpu_rays),
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
        let created: Vec<PathBuf> = dir
            .ancestors()
            .filter(|a| !a.as_os_str().is_empty())
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
    let plan = plan(&args)?;
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
    let height_args = HeightArgs {
        height_size: Some(format!("{}x{}", plan.size[0], plan.size[1])),
        channel: None,
        address: Address::Clamp,
    };
    let opts = HeightOptions {
        channel: height_args.channel,
        size: plan.size,
        address: height_args.address,
    };
    check_memory(&args, &plan, &sources, &opts)?;
    let out_dir = OutputDir::create(&args.out)?;
    // Read every map first: a bad file fails before minutes of work.
    let heights = sources
        .iter()
        .map(|s| load_height(s, &height_args, plan.size).map(|h| (map_name(s), h)))
        .collect::<Result<Vec<_>>>()?;

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
        let size = [height.width(), height.height()];
        let (maps, report) = prepare(height, args.extent, args.depth, &plan.techniques)?;
        for p in report {
            precompute.push((name.clone(), p));
        }
        for &elevation in &plan.elevations {
            let seed = args.seed ^ ((k as u64) << 32) ^ (elevation.to_bits() as u64);
            let rays = rays(maps.aspect, elevation, plan.rays, seed);
            let exact = exact_hits(&maps, &rays);
            for &tech in &plan.techniques {
                let budgets: &[u32] = if tech.uses_budget() {
                    &plan.budgets
                } else {
                    &[1]
                };
                for &budget in budgets {
                    let (got, fetches, ns) = measure(&maps, tech, budget, &rays)?;
                    let (wrong, mean_error, p99_error) = score(size, &exact, &got);
                    rows.push(Row {
                        map: name.clone(),
                        elevation,
                        technique: tech,
                        budget,
                        rays: rays.len(),
                        wrong,
                        mean_error,
                        p99_error,
                        fetches,
                        ns_per_ray: ns,
                        gpu_ns_per_ray: None,
                    });
                }
            }
            if let Some((ctx, n)) = &gpu {
                let first = rows.len() - runs_per_elevation(&plan);
                time_on_gpu(ctx, &maps, &rays, *n, args.gpu_frames, &mut rows[first..])?;
            }
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
    write_atomic(&csv, |w| {
        writeln!(w, "{CSV_HEADER}")?;
        for r in &rows {
            writeln!(
                w,
                "{},{},{},{},{},{:.6},{:.6},{:.6},{:.3},{:.1},{}",
                r.map,
                r.elevation,
                r.technique.name(),
                r.budget,
                r.rays,
                r.wrong,
                r.mean_error,
                r.p99_error,
                r.fetches,
                r.ns_per_ray,
                r.gpu_ns_per_ray
                    .map(|g| format!("{g:.3}"))
                    .unwrap_or_default()
            )?;
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", csv.display()))?;
    let pre = args.out.join("precompute.csv");
    write_atomic(&pre, |w| {
        writeln!(w, "map,precomputation,seconds,bytes")?;
        for (map, p) in &precompute {
            writeln!(w, "{map},{},{:.4},{}", p.name, p.seconds, p.bytes)?;
        }
        Ok(())
    })
    .with_context(|| format!("writing {}", pre.display()))?;

    let equal = args.out.join("equal_error.csv");
    write_atomic(&equal, |w| {
        writeln!(
            w,
            "map,elevation_deg,technique,budget,fetches_per_ray,ns_per_ray"
        )?;
        for (r, cheapest) in equal_error(&rows) {
            match cheapest {
                Some(c) => writeln!(
                    w,
                    "{},{},{},{},{:.3},{:.1}",
                    r.map,
                    r.elevation,
                    r.technique.name(),
                    c.budget,
                    c.fetches,
                    c.ns_per_ray
                )?,
                None => writeln!(w, "{},{},{},,,", r.map, r.elevation, r.technique.name())?,
            }
        }
        Ok(())
    })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// One map, a height-only technique: the heights read first, their
    /// copy beside the bake's peak, and the rays with their two hit lists.
    #[test]
    fn the_peak_counts_heights_bake_and_rays() {
        let ray = std::mem::size_of::<MapRay>() as u128;
        let hit = std::mem::size_of::<Option<Vec2>>() as u128;
        let bake = displace_core::memory::bake_peak_bytes([10, 10], [10, 10, 4], false);
        assert_eq!(
            compare_peak_bytes(&[[10, 10]], 4, &[Technique::Pom], 3, None),
            100 * 4 + 100 * 4 + bake + 3 * (ray + 2 * hit)
        );
        // Cones, pyramid and a second map (the grid's, kept) add to it.
        let one = compare_peak_bytes(&[[10, 10]], 4, &Technique::ALL, 3, None);
        assert_eq!(
            one,
            100 * 4 + 100 * (4 + 8 + 6 + 12) + bake + 3 * (ray + 2 * hit)
        );
        let two = compare_peak_bytes(&[[10, 10], [10, 10]], 4, &Technique::ALL, 3, None);
        assert_eq!(two - one, 100 * 4 + 100 * (4 + 8 + 6 + 12) + bake);
        // The GPU's repeated rays: the batch and its upload.
        let gpu = compare_peak_bytes(&[[10, 10]], 4, &Technique::ALL, 3, Some(1000));
        assert_eq!(gpu - one, 2 * 1000 * ray);
    }

    /// The size: a 46000x46000 map needs tens of gigabytes (every
    /// buffer of which passes the one-buffer check).
    #[test]
    fn a_46000_texel_map_needs_tens_of_gigabytes() {
        let b = compare_peak_bytes(&[[46000, 46000]], 16, &Technique::ALL, 2000, None);
        assert!(b > 300_000_000_000 && b < 500_000_000_000, "{b}");
    }
}
