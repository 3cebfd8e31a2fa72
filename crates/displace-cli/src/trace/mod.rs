//! `displace trace`: batch ray queries against one displaced face, in the
//! face's physical frame, so users can check our tracer against their own
//! tools (or, with `--scene`, against a whole scene: [`scene`]).
//!
//! The frame and the units of `t` are [`displace_core::physical`]'s.

mod rays;
mod scene;

use crate::args::{load_height, parse_map_size, FaceArgs};
use anyhow::{bail, Context, Result};
use clap::Args;
use displace_core::io::{self as dio, npy};
use displace_core::physical;
use displace_core::{DisplacementMap, Method, NormalMap, TraceOptions};
#[cfg(feature = "gpu")]
use displace_gpu::{DistanceTexture, GpuContext};
use rayon::prelude::*;
use rays::read_rays;
use std::path::{Path, PathBuf};
use std::time::Instant;

#[derive(Args, Debug)]
pub struct TraceArgs {
    /// Trace against a whole scene file instead of one face: rays in world
    /// space, (N, 6) or (N, 7) with t_max; hits (N, 8): t, position xyz,
    /// geometric normal xyz, index in `[[shapes]]` (-1 miss, -2 light quad)
    #[arg(long, value_name = "SCENE.toml", conflicts_with_all = ["height", "map", "size", "backend", "method"])]
    pub scene: Option<PathBuf>,
    /// With --scene: any-hit (shadow-ray) queries, (N, 1): 1 where the ray is
    /// blocked within t_max, else 0
    #[arg(long)]
    pub any_hit: bool,
    /// With --scene: do not read or write the on-disk bake cache
    #[arg(long)]
    pub no_cache: bool,
    /// With --scene: after the first pass over the rays, run the queries N
    /// more times and report the best of those passes' rates (the first
    /// warms the caches and the thread pool, as a benchmark's untimed
    /// first call does); every pass must give the same answers
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub repeat: u32,
    /// Height map: gen:NAME[?...], a PNG, JPEG, TIFF or EXR file
    #[arg(long, value_name = "HEIGHT", required_unless_present = "scene")]
    pub height: Option<String>,
    #[command(flatten)]
    pub face: FaceArgs,
    /// Bake a distance map of this many voxels [default: 256x256x16]
    #[arg(long, value_name = "WxHxD", conflicts_with = "map")]
    pub size: Option<String>,
    /// Use a baked distance map (.ktx2; .dds and .npy take --extent and
    /// --address as they were baked) instead of baking one
    #[arg(long, value_name = "MAP")]
    pub map: Option<PathBuf>,
    /// Rays: float32 .npy of shape (N, 6), origin xyz then direction xyz
    /// (with --scene also (N, 7): then t_max)
    #[arg(long, value_name = "RAYS.npy")]
    pub rays: PathBuf,
    /// Hits: float32 .npy of shape (N, 5): t (inf on a miss), x, y, z (NaN
    /// on a miss), iterations
    #[arg(short, long, value_name = "HITS.npy")]
    pub output: PathBuf,
    #[arg(long, default_value = "sphere", value_parser = parse_method)]
    pub method: Method,
    /// sphere-fixed: the number of steps; sphere: the most steps before the
    /// rest of the ray is walked exactly
    #[arg(long, default_value_t = TraceOptions::default().iterations)]
    pub iterations: u32,
    /// cpu (rayon, all cores) or gpu (one compute invocation per ray, the
    /// same trace in WGSL; every method is supported)
    #[arg(long, value_enum, default_value_t = Backend::Cpu)]
    pub backend: Backend,
}

/// Where the rays are traced. Both answer with the same records: the GPU
/// runs `displace_core::sphere_trace` mirrored in WGSL, reading the distance
/// map as exact f32 texel loads so its samples equal the CPU's.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Backend {
    Cpu,
    Gpu,
}

fn parse_method(s: &str) -> Result<Method, String> {
    s.parse().map_err(|e: displace_core::Error| e.to_string())
}

/// A miss as `trace` writes it: `t` inf, the point NaN, no steps.
const MISS: [f32; 5] = [f32::INFINITY, f32::NAN, f32::NAN, f32::NAN, 0.0];

/// A hit as `trace` writes it: `[t, x, y, z, iterations]`.
fn record(hit: &physical::PhysicalHit) -> [f32; 5] {
    let p = hit.position;
    [hit.t, p.x, p.y, p.z, hit.iterations as f32]
}

/// Every physical-frame ray ([`displace_core::physical`]) traced: `[t, x,
/// y, z, iterations]` each, `t` inf and the point NaN on a miss. Parallel
/// tasks of a few hundred rays, each traced in packets
/// ([`physical::intersect_many`], the same hits as one ray at a time).
pub fn trace_physical_all(
    map: &DisplacementMap,
    opts: &TraceOptions,
    rays: &[[f32; 6]],
) -> Vec<[f32; 5]> {
    const TASK: usize = 256;
    let mut hits = vec![MISS; rays.len()];
    hits.par_chunks_mut(TASK)
        .zip(rays.par_chunks(TASK))
        .for_each(|(out, rays)| {
            let rays: Vec<[f32; 7]> = rays
                .iter()
                .map(|r| [r[0], r[1], r[2], r[3], r[4], r[5], f32::INFINITY])
                .collect();
            let mut found = vec![None; rays.len()];
            physical::intersect_many(map.into(), opts, &rays, &mut found);
            for (o, hit) in out.iter_mut().zip(&found) {
                if let Some(hit) = hit {
                    *o = record(hit);
                }
            }
        });
    hits
}

pub fn run(args: TraceArgs) -> Result<()> {
    if let Some(scene) = &args.scene {
        return scene::run(
            scene,
            &args.rays,
            &args.output,
            args.any_hit,
            !args.no_cache,
            args.repeat,
        );
    }
    if args.any_hit || args.no_cache || args.repeat > 0 {
        let flag = if args.any_hit {
            "any-hit"
        } else if args.no_cache {
            "no-cache"
        } else {
            "repeat"
        };
        bail!("--{flag} applies to whole-scene queries: add --scene SCENE.toml");
    }
    let (Some(height_source), Some(extent)) = (args.height.as_deref(), args.face.extent) else {
        bail!("--height and --extent are needed to trace one face (or trace a whole --scene)");
    };
    crate::outputs::check_npy_output(&args.output)?;
    let mut inputs = vec![
        ("--rays", args.rays.as_path()),
        ("--height", Path::new(height_source)),
    ];
    inputs.extend(args.map.as_deref().map(|m| ("--map", m)));
    crate::outputs::check_not_inputs(&[("-o", &args.output)], &inputs)?;
    // Counts are refused before the rays are read or a map baked.
    displace_core::check_iterations(args.iterations).context("--iterations")?;
    if args.backend == Backend::Gpu {
        #[cfg(not(feature = "gpu"))]
        bail!("--backend gpu: {}", crate::NO_GPU);
        #[cfg(feature = "gpu")]
        crate::gpu::check_gpu_iterations(args.iterations)
            .context("--iterations with --backend gpu")?;
    }
    let rays = read_rays(&args.rays)?;
    // The GPU is opened before any map is made, so that a map it cannot
    // hold is refused before seconds of bake and gigabytes.
    #[cfg(feature = "gpu")]
    let gpu = match args.backend {
        Backend::Gpu => {
            Some(GpuContext::new_headless().context("opening a GPU for --backend gpu")?)
        }
        Backend::Cpu => None,
    };
    #[cfg(feature = "gpu")]
    let fits_gpu = |height: [usize; 2], size: [usize; 3]| -> Result<()> {
        if let Some(ctx) = &gpu {
            displace_gpu::GpuMap::check_sizes(ctx, height, size).context("--backend gpu")?;
        }
        Ok(())
    };
    #[cfg(not(feature = "gpu"))]
    let fits_gpu = |_: [usize; 2], _: [usize; 3]| -> Result<()> { Ok(()) };
    let address = args.face.height.address;
    let map = match &args.map {
        Some(path) => {
            let distance = dio::read_distance_map(path, extent, address)
                .with_context(|| format!("reading distance map {}", path.display()))?;
            let [w, h, _] = distance.size();
            let dims = crate::args::height_dimensions(height_source, &args.face.height, [w, h])?;
            fits_gpu(dims, distance.size())?;
            let height = load_height(height_source, &args.face.height, [w, h])?;
            DisplacementMap {
                normals: NormalMap::from_height(&height, extent)?,
                height,
                distance,
                extent,
            }
        }
        None => {
            let size = parse_map_size(args.size.as_deref().unwrap_or("256x256x16"))?;
            let dims = crate::args::height_dimensions(
                height_source,
                &args.face.height,
                [size[0], size[1]],
            )?;
            fits_gpu(dims, size)?;
            crate::bake::check_bake_memory(
                height_source,
                &args.face.height,
                size,
                false,
                crate::bake::BakeHolds::Whole,
            )?;
            let height = load_height(height_source, &args.face.height, [size[0], size[1]])?;
            let opts = displace_core::BakeOptions {
                size,
                extent,
                ..Default::default()
            };
            displace_core::bake(&height, &opts).context("baking the distance map")?
        }
    };
    let opts = TraceOptions {
        method: args.method,
        iterations: args.iterations,
        ..TraceOptions::default()
    };
    map.check_trace(&opts).context("trace options")?;

    let (hits, seconds, on) = match args.backend {
        Backend::Cpu => {
            let start = Instant::now();
            let hits = trace_physical_all(&map, &opts, &rays);
            let on = format!("{} threads", rayon::current_num_threads());
            (hits, start.elapsed().as_secs_f64(), on)
        }
        #[cfg(not(feature = "gpu"))]
        Backend::Gpu => bail!("--backend gpu: {}", crate::NO_GPU),
        #[cfg(feature = "gpu")]
        Backend::Gpu => {
            let ctx = gpu.as_ref().context("--backend gpu: no GPU opened")?;
            // Timed from upload to readback, the cost a caller sees.
            let start = Instant::now();
            let hits =
                crate::gpu::trace_physical_gpu(ctx, &map, &opts, DistanceTexture::R32Load, &rays)?;
            (hits, start.elapsed().as_secs_f64(), ctx.describe())
        }
    };
    let flat: Vec<f32> = hits.iter().flatten().copied().collect();
    npy::write_file(&args.output, &[hits.len(), 5], &flat)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let n_hit = hits.iter().filter(|h| h[0].is_finite()).count();
    println!(
        "traced {} rays ({} hits) with {} in {:.3} s ({:.2} Mrays/s on {}) -> {}",
        rays.len(),
        n_hit,
        args.method.name(),
        seconds,
        rays.len() as f64 / seconds.max(1e-9) / 1e6,
        on,
        args.output.display()
    );
    Ok(())
}
