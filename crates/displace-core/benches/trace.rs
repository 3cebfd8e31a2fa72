//! Map-space trace throughput on one core (rays per second): Donnelly's
//! fixed-step sphere trace, the early-out sphere trace as the CPU runs it
//! (`sphere`: `cell_trace`, one-voxel steps and culled patches) and as the
//! GPU runs it (`sphere-trilinear`: `trace_counted`, eight-voxel trilinear
//! steps, every patch of the band solved), any-hit queries over the same
//! rays (`any-hit`), and the exact reference, each on 10k seeded random rays
//! per iteration against 256x256x16 maps of `studded`, `gaussian` and
//! `noise`; the CPU tracer one ray at a time against eight at a time
//! (`sphere-packet`, `any-hit-packet`: `trace_many` / `occluded_many`, AVX2
//! where present) on those random rays and on coherent camera rays
//! (`camera`, `camera-packet`: a 100x100 pinhole grid 45 degrees down onto
//! the face). The mean iterations per ray of each case are printed once
//! before it is timed.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use displace_core::random::rays::{tile_rays, Elevation, Start};
use displace_core::{
    bake, generators, Address, BakeOptions, DisplacementMap, Extent, MapRay, Method, TraceOptions,
};
use glam::Vec3;
use std::hint::black_box;

const RAYS: usize = 10_000;

/// Rays from above the shell (z = 1.05) towards uniformly random points of
/// the base, at elevations from 10 degrees (grazing, the hard case for any
/// marcher) to straight down, so every ray meets the surface.
fn random_rays(aspect: [f32; 2], seed: u64) -> Vec<MapRay> {
    tile_rays(
        aspect,
        RAYS,
        seed,
        Start::Aimed(1.05),
        Elevation::Uniform(10.0, 90.0),
    )
}

/// A pinhole camera 45 degrees above the face centre, a 20 degree field of
/// view: neighbouring rays meet neighbouring cells, as a render's do.
fn camera_rays(aspect: [f32; 2]) -> Vec<MapRay> {
    let side = (RAYS as f32).sqrt() as usize;
    let centre = Vec3::new(aspect[0] * 0.5, aspect[1] * 0.5, 0.0);
    let pos = centre + Vec3::new(0.0, -1.0, 1.0) * (aspect[0] * 0.85);
    let fwd = (centre - pos).normalize();
    let right = fwd.cross(Vec3::Z).normalize();
    let up = right.cross(fwd);
    let t = 10.0f32.to_radians().tan();
    (0..side * side)
        .map(|k| {
            let fx = ((k % side) as f32 + 0.5) / side as f32;
            let fy = ((k / side) as f32 + 0.5) / side as f32;
            MapRay::new(
                pos,
                fwd + (2.0 * fx - 1.0) * t * right + (1.0 - 2.0 * fy) * t * up,
            )
        })
        .collect()
}

fn options(method: Method) -> TraceOptions {
    TraceOptions {
        method,
        // Donnelly's loop runs a fixed 16 steps (section 8.5); the early-out
        // loop gets the library default.
        iterations: if method == Method::SphereFixed {
            16
        } else {
            TraceOptions::default().iterations
        },
        ..TraceOptions::default()
    }
}

fn trace_rays(c: &mut Criterion) {
    let mut group = c.benchmark_group("trace");
    group.throughput(Throughput::Elements(RAYS as u64));
    for name in ["studded", "gaussian", "noise"] {
        let height = generators::generate(&format!("gen:{name}"), 256, 256, Address::Clamp)
            .expect("generator");
        let map: DisplacementMap = bake(
            &height,
            &BakeOptions::new([256, 256, 16], Extent::new(1.0, 1.0, 0.1).expect("extent")),
        )
        .expect("bake");
        let rays = random_rays(map.aspect(), 0x5EED);
        for method in [Method::Sphere, Method::SphereFixed, Method::Exact] {
            let opts = options(method);
            let hits: Vec<_> = rays.iter().filter_map(|r| map.trace(r, &opts)).collect();
            let mean =
                hits.iter().map(|h| h.iterations as f64).sum::<f64>() / hits.len().max(1) as f64;
            println!(
                "trace/{}/{name}: {} of {RAYS} rays hit, {mean:.2} iterations per hit",
                method.name(),
                hits.len()
            );
            group.bench_with_input(BenchmarkId::new(method.name(), name), &rays, |b, rays| {
                b.iter(|| {
                    rays.iter()
                        .filter(|r| map.trace(black_box(r), &opts).is_some())
                        .count()
                })
            });
        }
        let opts = options(Method::Sphere);
        group.bench_with_input(
            BenchmarkId::new("sphere-trilinear", name),
            &rays,
            |b, rays| {
                b.iter(|| {
                    rays.iter()
                        .filter(|r| map.trace_counted(black_box(r), &opts).0.is_some())
                        .count()
                })
            },
        );
        group.bench_with_input(BenchmarkId::new("any-hit", name), &rays, |b, rays| {
            b.iter(|| {
                rays.iter()
                    .filter(|r| map.occluded(black_box(r), &opts))
                    .count()
            })
        });
        let camera = camera_rays(map.aspect());
        group.bench_with_input(BenchmarkId::new("camera", name), &camera, |b, rays| {
            b.iter(|| {
                rays.iter()
                    .filter(|r| map.trace(black_box(r), &opts).is_some())
                    .count()
            })
        });
        // One ray at a time against eight at a time, on the same rays.
        for (id, rays) in [("sphere-packet", &rays), ("camera-packet", &camera)] {
            let all = vec![opts; rays.len()];
            let mut hits = vec![None; rays.len()];
            group.bench_with_input(BenchmarkId::new(id, name), rays, |b, rays| {
                b.iter(|| {
                    map.trace_many(black_box(rays), &all, &mut hits);
                    hits.iter().flatten().count()
                })
            });
        }
        let all = vec![opts; rays.len()];
        let mut blocked = vec![false; rays.len()];
        let id = BenchmarkId::new("any-hit-packet", name);
        group.bench_with_input(id, &rays, |b, rays| {
            b.iter(|| {
                map.occluded_many(black_box(rays), &all, &mut blocked);
                blocked.iter().filter(|&&b| b).count()
            })
        });
    }
    group.finish();
}

criterion_group!(benches, trace_rays);
criterion_main!(benches);
