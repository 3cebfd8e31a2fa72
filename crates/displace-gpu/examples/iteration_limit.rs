//! Where the GPU stops agreeing with the CPU as the step count grows:
//! rays straight down onto a flat face, traced with `sphere-fixed` at each
//! count given (every step of a fixed loop runs, so the count is the
//! invocation's length), GPU hits against CPU hits.
//!
//! `cargo run -p displace-gpu --example iteration_limit -- [COUNT...]`
//! (defaults: 1024 4096 8192 15000 16384 16385 17000 32768 65536).

use displace_core::{bake, generators, Address, BakeOptions, Extent, MapRay, Method, TraceOptions};
use displace_gpu::{DistanceTexture, GpuContext, RayTracer};
use glam::Vec3;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let counts: Vec<u32> = {
        let given: Vec<u32> = std::env::args()
            .skip(1)
            .map(|s| s.parse())
            .collect::<Result<_, _>>()?;
        if given.is_empty() {
            vec![1024, 4096, 8192, 15000, 16384, 16385, 17000, 32768, 65536]
        } else {
            given
        }
    };
    let height = generators::generate("gen:gaussian", 32, 32, Address::Clamp)?;
    let map = bake(
        &height,
        &BakeOptions::new([32, 32, 8], Extent::new(1.0, 1.0, 0.25)?),
    )?;
    let ctx = GpuContext::new_headless()?;
    println!("{}", ctx.describe());
    let tracer = RayTracer::new(&ctx, &map, DistanceTexture::R32Load)?;
    let rays: Vec<MapRay> = (0..64)
        .map(|k| {
            let (x, y) = ((k % 8) as f32 + 0.5, (k / 8) as f32 + 0.5);
            MapRay::new(Vec3::new(x / 2.0, y / 2.0, 1.5), Vec3::new(0.1, 0.05, -1.0))
        })
        .collect();
    println!("| iterations | CPU hits | GPU hits | agree |");
    println!("|---|---|---|---|");
    for n in counts {
        let opts = TraceOptions {
            method: Method::SphereFixed,
            iterations: n,
            ..TraceOptions::default()
        };
        let cpu: Vec<bool> = rays.iter().map(|r| map.trace(r, &opts).is_some()).collect();
        let gpu: Vec<bool> = tracer
            .trace(&ctx, &rays, &opts)?
            .iter()
            .map(Option::is_some)
            .collect();
        let count = |v: &[bool]| v.iter().filter(|h| **h).count();
        println!(
            "| {n} | {} | {} | {} |",
            count(&cpu),
            count(&gpu),
            cpu == gpu
        );
    }
    Ok(())
}
