//! Map-space tracing on the renderer benchmark's two faces
//! (`scripts/bench_render_peers.py`: `studded` 256x256 heights, 1 x 1 x 0.1,
//! 256x256x16 map; `gaussian` 512x512, 1 x 1 x 0.3, 256x256x32), with its
//! camera (45 degrees down onto the face centre, 20 degree field of view):
//! first hits and shadow rays to its light per second on one thread for the GPU-mirroring trilinear loop
//! ([`DisplacementMap::trace_counted`]) and the CPU's throughput tracer
//! ([`DisplacementMap::trace`]), and the mean cost per ray; in packets under
//! each kernel the CPU runs, and the shadow rays also over a maximum-height
//! pyramid ([`occluded_over`]). A profiling aid:
//!
//!     cargo run --release -p displace-core --example trace_profile [RAYS_PER_SIDE] [cell|one|many]
//!
//! (`cell`: the CPU tracer one ray and eight at a time, no trilinear loop;
//! `one`: one ray at a time only; `many`: eight at a time only.)

use displace_core::cell_trace::{occluded_over, with_kernel, AnyHitPyramid, Kernel};
use displace_core::{
    bake, generators, Address, BakeOptions, DisplacementMap, Extent, MapRay, TraceOptions,
};
use glam::Vec3;
use std::time::Instant;

/// The benchmark's point light (world units).
const LIGHT: [f32; 3] = [-0.2, 0.3, 0.9];

fn camera_rays(n: usize, depth: f32) -> Vec<MapRay> {
    let centre = Vec3::new(0.5, 0.5, 0.0);
    let s = 0.5f32.sqrt();
    let pos = centre + 1.2 * Vec3::new(0.0, -s, s);
    let fwd = (centre - pos).normalize();
    let right = fwd.cross(Vec3::Z).normalize();
    let up = right.cross(fwd);
    let t = (10.0f32).to_radians().tan();
    let mut rays = Vec::with_capacity(n * n);
    for y in 0..n {
        for x in 0..n {
            let fx = (x as f32 + 0.5) / n as f32;
            let fy = (y as f32 + 0.5) / n as f32;
            let d = (fwd + (2.0 * fx - 1.0) * t * right + (1.0 - 2.0 * fy) * t * up).normalize();
            // World (x along u, z up, depth `depth`) to map space: divide by
            // the depth; directions keep their unit length after it.
            rays.push(MapRay::new(pos / depth, d));
        }
    }
    rays
}

/// The shortest of `runs` runs of `f`, in seconds (infinite for none).
fn best_of(runs: usize, mut f: impl FnMut()) -> f64 {
    (0..runs)
        .map(|_| {
            let start = Instant::now();
            f();
            start.elapsed().as_secs_f64()
        })
        .fold(f64::INFINITY, f64::min)
}

fn main() {
    let n: usize = std::env::args()
        .nth(1)
        .map_or(1000, |a| a.parse().expect("rays per side"));
    let faces = [
        ("studded", "gen:studded?period=32", 256, 0.1, [256, 256, 16]),
        ("gaussian", "gen:gaussian", 512, 0.3, [256, 256, 32]),
    ];
    for (name, src, texels, depth, size) in faces {
        let height = generators::generate(src, texels, texels, Address::Clamp).expect("height");
        let map: DisplacementMap = bake(
            &height,
            &BakeOptions::new(size, Extent::new(1.0, 1.0, depth).expect("extent")),
        )
        .expect("bake");
        let rays = camera_rays(n, depth);
        let opts = TraceOptions::default();
        let time = |f: &dyn Fn(&MapRay) -> Option<u32>| {
            let mut stats = (0usize, 0u64);
            let best = best_of(3, || {
                stats = rays
                    .iter()
                    .filter_map(f)
                    .fold((0, 0), |(h, it), i| (h + 1, it + i as u64));
            });
            (rays.len() as f64 / best / 1e6, stats)
        };
        let mode = std::env::args().nth(2).unwrap_or_default();
        let only_cell = mode == "cell" || mode == "many" || mode == "one";
        let (old, (h0, i0)) = if only_cell {
            (0.0, (0, 0))
        } else {
            time(&|r| map.trace_counted(r, &opts).0.map(|h| h.iterations))
        };
        let (new, (h1, i1)) = if mode == "many" {
            (0.0, (0, 0))
        } else {
            time(&|r| map.trace(r, &opts).map(|h| h.iterations))
        };
        // In packets (`trace_many`, `occluded_many`), under each kernel
        // this CPU runs: the same hits, at what speed.
        let all_opts = vec![opts; rays.len()];
        let mut hits = vec![None; rays.len()];
        let runs = if mode == "one" { 0 } else { 3 };
        for kernel in Kernel::available() {
            with_kernel(kernel, || {
                let best = best_of(runs, || map.trace_many(&rays, &all_opts, &mut hits));
                let many = rays.len() as f64 / best / 1e6;
                println!(
                    "{name}: {kernel:?} packets {many:.2} Mrays/s ({} hits)",
                    hits.iter().flatten().count()
                );
                // The render's shadow rays: from each hit, just off the
                // surface on the camera's side, to the benchmark's point
                // light (any-hit).
                let light = Vec3::from(LIGHT) / depth;
                let (shadow, shadow_opts): (Vec<MapRay>, Vec<TraceOptions>) = hits
                    .iter()
                    .flatten()
                    .filter_map(|h| {
                        let o = h.position + h.normal * (1e-4 / depth);
                        let to = light - o;
                        (to.dot(h.normal) > 0.0).then(|| {
                            let o2 = TraceOptions {
                                t_max: to.length() * (1.0 - 1e-4),
                                ..opts
                            };
                            (MapRay::new(o, to), o2)
                        })
                    })
                    .unzip();
                let mut blocked = vec![false; shadow.len()];
                let best = best_of(runs, || {
                    map.occluded_many(&shadow, &shadow_opts, &mut blocked)
                });
                println!(
                    "{name}: {kernel:?} shadow rays in packets {:.2} Mrays/s ({} of {} blocked)",
                    shadow.len() as f64 / best / 1e6,
                    blocked.iter().filter(|&&b| b).count(),
                    shadow.len()
                );
                if kernel == Kernel::Scalar {
                    // The same shadow rays over a maximum-height pyramid,
                    // one at a time (what a face's `occluded` queries use).
                    let pyramid = AnyHitPyramid::build(&map.height);
                    let mut over = vec![false; shadow.len()];
                    let best = best_of(runs, || {
                        for ((r, o), b) in shadow.iter().zip(&shadow_opts).zip(over.iter_mut()) {
                            *b = occluded_over(&map.height, &map.distance, &pyramid, r, o);
                        }
                    });
                    println!(
                        "{name}: pyramid shadow rays {:.2} Mrays/s ({} of {} blocked)",
                        shadow.len() as f64 / best / 1e6,
                        over.iter().filter(|&&b| b).count(),
                        shadow.len()
                    );
                }
            });
        }
        println!(
            "{name}: trilinear {old:.2} Mrays/s ({h0} hits, {:.1} fetches/hit), cell {new:.2} Mrays/s ({h1} hits, {:.1} fetches/hit)",
            i0 as f64 / h0.max(1) as f64,
            i1 as f64 / h1.max(1) as f64,
        );
    }
}
