//! Bake throughput (voxels per second) of the conservative distance map,
//! normal map included, at Donnelly's 256x256x16 and at 512x512x32, for the
//! sharp-edged `studded` map and smooth fractal `noise`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion, Throughput};
use displace_core::{bake, generators, Address, BakeOptions, Extent};
use std::hint::black_box;

fn bake_volumes(c: &mut Criterion) {
    let mut group = c.benchmark_group("bake");
    group.sample_size(10);
    for [w, h, d] in [[256, 256, 16], [512, 512, 32]] {
        for name in ["studded", "noise"] {
            let height = generators::generate(&format!("gen:{name}"), w, h, Address::Clamp)
                .expect("generator");
            let opts = BakeOptions {
                size: [w, h, d],
                extent: Extent::new(1.0, 1.0, 0.1).expect("extent"),
                ..BakeOptions::default()
            };
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

criterion_group!(benches, bake_volumes);
criterion_main!(benches);
