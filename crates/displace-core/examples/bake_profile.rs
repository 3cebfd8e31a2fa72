//! One bake, timed, for profilers: `perf record` or
//! `valgrind --tool=callgrind` (instruction counts are repeatable on a busy
//! machine, wall times are not).
//!
//! ```text
//! cargo run --release -p displace-core --example bake_profile -- noise 512x512x64 [runs]
//! ```

use displace_core::{bake, generators, Address, BakeOptions, Extent};
use std::time::Instant;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let name = args.next().unwrap_or_else(|| "noise".into());
    let size = args.next().unwrap_or_else(|| "512x512x64".into());
    let runs: usize = args.next().map_or(Ok(1), |r| r.parse())?;
    let dims: Vec<usize> = size.split('x').map(str::parse).collect::<Result<_, _>>()?;
    let [w, h, d] = dims[..] else {
        return Err(format!("size `{size}`: expected WxHxD").into());
    };
    let height = generators::generate(&format!("gen:{name}"), w, h, Address::Clamp)?;
    let opts = BakeOptions::new([w, h, d], Extent::new(1.0, 1.0, 0.1)?);
    let mut best = f64::INFINITY;
    for _ in 0..runs.max(1) {
        let t = Instant::now();
        let map = bake(&height, &opts)?;
        best = best.min(t.elapsed().as_secs_f64());
        std::hint::black_box(map);
    }
    let mvox = (w * h * d) as f64 / best / 1e6;
    println!("{name} {w}x{h}x{d}: {best:.4} s, {mvox:.1} Mvoxels/s (best of {runs})");
    Ok(())
}
