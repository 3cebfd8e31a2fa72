//! Bake throughput (voxels per second) of the conservative distance map,
//! normal map included, at Donnelly's 256x256x16 and at 512x512x32, for the
//! sharp-edged `studded` map and smooth fractal `noise`; and the 1D lower
//! envelope at its heart, eight lines at a time (the AVX2 kernel the bake
//! uses) against the scalar transform on the same lines.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use displace_core::edt::{
    interleave, transform_lanes, transform_line, transform_wide, LaneScratch, LineScratch, LANES,
    WIDE,
};
use displace_core::{bake, generators, Address, BakeOptions, Extent};
use std::hint::black_box;

fn bake_volumes(c: &mut Criterion) {
    let mut group = c.benchmark_group("bake");
    group.sample_size(10);
    for [w, h, d] in [[256, 256, 16], [512, 512, 32]] {
        for name in ["studded", "noise"] {
            let height = generators::generate(&format!("gen:{name}"), w, h, Address::Clamp)
                .expect("generator");
            let opts = BakeOptions::new([w, h, d], Extent::new(1.0, 1.0, 0.1).expect("extent"));
            group.throughput(Throughput::Elements((w * h * d) as u64));
            group.bench_with_input(
                BenchmarkId::new(name, format!("{w}x{h}x{d}")),
                &height,
                |b, height| b.iter(|| bake(black_box(height), &opts).expect("bake")),
            );
        }
    }
    group.finish();
}

/// The 1D transforms of one 512x512 slice's rows as a bake does them: the
/// squared height distance `(z - h)^2` at mid-depth along every row of a
/// `noise` (or `studded`) map, 512 different lines so that the branch
/// predictor cannot learn one line's pops; the kernels take them as 64
/// interleaved groups of eight or 32 of sixteen.
fn envelope_lines(c: &mut Criterion) {
    let mut group = c.benchmark_group("envelope");
    let n = 512;
    for name in ["studded", "noise"] {
        let height =
            generators::generate(&format!("gen:{name}"), n, n, Address::Clamp).expect("generator");
        let lines: Vec<f32> = height
            .data()
            .iter()
            .map(|h| (0.5 - h) * (0.5 - h))
            .collect();
        let interleaved = |width: usize| {
            let mut out = vec![0.0f32; n * n];
            for (rows, block) in lines
                .chunks_exact(n * width)
                .zip(out.chunks_exact_mut(n * width))
            {
                interleave(rows, width, n, width, block);
            }
            out
        };
        let (lanes, wide) = (interleaved(LANES), interleaved(WIDE));
        group.throughput(Throughput::Elements((n * n) as u64));
        let spacing = 10.0 / n as f32;
        group.bench_function(BenchmarkId::new("scalar", name), |b| {
            let mut s = LineScratch::default();
            let mut work = lines.clone();
            b.iter(|| {
                work.copy_from_slice(&lines);
                for line in work.chunks_exact_mut(n) {
                    transform_line(black_box(line), spacing, false, &mut s);
                }
            })
        });
        // Eight lanes, and sixteen: one AVX-512 register, or two AVX2 groups.
        type Kernel = fn(&mut [f32], usize, usize, f32, bool, &mut LaneScratch);
        let kernels: [(&str, &[f32], usize, Kernel); 2] = [
            ("lanes", &lanes, LANES, transform_lanes),
            ("wide", &wide, WIDE, transform_wide),
        ];
        for (id, input, width, kernel) in kernels {
            group.bench_function(BenchmarkId::new(id, name), |b| {
                let mut s = LaneScratch::default();
                let mut work = input.to_vec();
                b.iter(|| {
                    work.copy_from_slice(input);
                    for group in work.chunks_exact_mut(n * width) {
                        kernel(black_box(group), width, n, spacing, false, &mut s);
                    }
                })
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bake_volumes, envelope_lines);
criterion_main!(benches);
