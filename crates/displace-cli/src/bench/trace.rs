//! `displace bench trace`: rays per second of the map-space tracers (sphere,
//! sphere-fixed, exact) on one core and on all, and the mean iterations per
//! hit, on every generator. A measurement, not a test.

use super::bake::height_for;
use crate::args::parse_extent;
use crate::threads::pool;
use anyhow::{Context, Result};
use clap::Args;
use displace_core::random::rays::{tile_rays, Elevation, Start};
use displace_core::{
    generators, BakeOptions, DisplacementMap, Extent, MapRay, Method, TraceOptions,
};
use rayon::prelude::*;
use std::time::Instant;

#[derive(Args, Debug)]
pub struct BenchTraceArgs {
    /// Fewer rays
    #[arg(long)]
    pub quick: bool,
    /// Threads of the "all cores" run [default: all cores]
    #[arg(long)]
    pub threads: Option<usize>,
    /// Rays per generator and method
    #[arg(long)]
    pub rays: Option<usize>,
    /// Steps of sphere-fixed (and the cap of sphere)
    #[arg(long, default_value_t = TraceOptions::default().iterations)]
    pub iterations: u32,
    /// Seed of the random rays
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[arg(long, default_value = "1,1,0.1", value_parser = parse_extent)]
    pub extent: Extent,
}

struct TraceRun {
    rays_per_s: f64,
    hits: usize,
    iterations: u64,
}

fn time_trace(
    pool: &rayon::ThreadPool,
    map: &DisplacementMap,
    rays: &[MapRay],
    opts: &TraceOptions,
) -> TraceRun {
    let t = Instant::now();
    let (hits, iterations) = pool.install(|| {
        rays.par_iter()
            .map(|r| match map.trace(r, opts) {
                Some(h) => (1usize, h.iterations as u64),
                None => (0, 0),
            })
            .reduce(|| (0, 0), |a, b| (a.0 + b.0, a.1 + b.1))
    });
    TraceRun {
        rays_per_s: rays.len() as f64 / t.elapsed().as_secs_f64(),
        hits,
        iterations,
    }
}

pub fn run(args: BenchTraceArgs) -> Result<()> {
    let one = pool(Some(1))?;
    let all = pool(args.threads)?;
    let n = args
        .rays
        .unwrap_or(if args.quick { 5_000 } else { 100_000 });
    let size = if args.quick {
        [128, 128, 16]
    } else {
        [256, 256, 16]
    };
    let extent = args.extent;
    // From just above the shell top, at elevations from 5 to 90 degrees.
    let rays = tile_rays(
        extent.aspect(),
        n,
        args.seed,
        Start::Above(1.0 + 1e-3),
        Elevation::Uniform(5.0, 90.0),
    );
    println!(
        "trace: {}x{}x{} maps, extent {},{},{}, {n} rays from above the shell (seed {}), \
         1 thread vs {} threads; iterations/hit = distance-map steps + patches walked",
        size[0],
        size[1],
        size[2],
        extent.sx,
        extent.sy,
        extent.sz,
        args.seed,
        all.current_num_threads()
    );
    println!(
        "{:<9} {:<13} {:>12} {:>12} {:>7} {:>14}",
        "height", "method", "Mrays/s 1", "Mrays/s all", "hits", "iterations/hit"
    );
    for name in generators::NAMES {
        let height = height_for(name, size[0], size[1])?;
        let opts = BakeOptions::new(size, extent);
        let map = all
            .install(|| displace_core::bake(&height, &opts))
            .context("baking")?;
        for method in [Method::Sphere, Method::SphereFixed, Method::Exact] {
            let topts = TraceOptions {
                method,
                iterations: args.iterations,
                ..TraceOptions::default()
            };
            let single = time_trace(&one, &map, &rays, &topts);
            let multi = time_trace(&all, &map, &rays, &topts);
            println!(
                "{:<9} {:<13} {:>12.3} {:>12.3} {:>7} {:>14.1}",
                name,
                method.name(),
                single.rays_per_s / 1e6,
                multi.rays_per_s / 1e6,
                multi.hits,
                multi.iterations as f64 / multi.hits.max(1) as f64
            );
        }
    }
    Ok(())
}
