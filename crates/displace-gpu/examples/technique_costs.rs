//! GPU cost of every issue-5 technique: milliseconds per million map-space
//! rays (a 1024x1024 grid over the face, all at one elevation), and the mean
//! texture fetches per ray, through [`displace_gpu::technique_costs`].
//!
//! `cargo run --release -p displace-gpu --example technique_costs -- [GEN] [SIZE] [ELEVATION_DEG] [BUDGET]`
//! (defaults: `gen:studded 128 30 16`).

use displace_core::techniques::{ConeKind, ConeMap, Maps, MaxPyramid, Technique};
use displace_core::{bake, generators, Address, BakeOptions, Extent, MapRay};
use displace_gpu::{technique_costs, GpuContext, TechniqueTracer};
use glam::Vec3;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let spec = args.first().map_or("gen:studded", String::as_str);
    let size: usize = args.get(1).map_or(Ok(128), |s| s.parse())?;
    let elevation: f32 = args.get(2).map_or(Ok(30.0), |s| s.parse())?;
    let budget: u32 = args.get(3).map_or(Ok(16), |s| s.parse())?;

    let height = generators::generate(spec, size, size, Address::Clamp)?;
    let extent = Extent::new(1.0, 1.0, 0.1)?;
    let displacement = bake(&height, &BakeOptions::new([size, size, 16], extent))?;
    let aspect = displacement.aspect();
    let maps = Maps {
        cones: Some(ConeMap::build(&height, aspect, ConeKind::Conservative)),
        relaxed: Some(ConeMap::build(&height, aspect, ConeKind::Relaxed)),
        pyramid: Some(MaxPyramid::build(&height)),
        displacement: Some(displacement),
        ..Maps::new(height, aspect)
    };

    // Every ray leaves the shell's top towards a point of the floor.
    let n = 1024usize;
    let (e, a) = (elevation.to_radians(), 30f32.to_radians());
    let dir = Vec3::new(e.cos() * a.cos(), e.cos() * a.sin(), -e.sin());
    let rays: Vec<MapRay> = (0..n * n)
        .map(|k| {
            let floor = Vec3::new(
                ((k % n) as f32 + 0.5) / n as f32 * aspect[0],
                ((k / n) as f32 + 0.5) / n as f32 * aspect[1],
                0.0,
            );
            MapRay::new(floor - dir / dir.z.abs(), dir)
        })
        .collect();

    let ctx = GpuContext::new_headless()?;
    println!("# {}", ctx.describe());
    println!(
        "# {spec} {size}x{size}, extent 1x1x0.1, elevation {elevation} deg, budget {budget}, {} rays",
        rays.len()
    );
    let tracer = TechniqueTracer::new(&ctx, &maps)?;
    let runs: Vec<_> = Technique::ALL.iter().map(|&t| (t, budget)).collect();
    let costs = technique_costs(&ctx, &maps, &rays, &runs, 3)?;
    println!("technique,budget,ms_per_mray,timer,wall_ms_per_mray,mean_fetches,hit_fraction");
    for c in costs {
        let traced = tracer.trace(&ctx, &rays, c.technique, budget)?;
        let fetches = traced.iter().map(|t| t.fetches as f64).sum::<f64>() / rays.len() as f64;
        let hits = traced.iter().filter(|t| t.hit.is_some()).count() as f64 / rays.len() as f64;
        println!(
            "{},{},{:.3},{},{:.3},{:.2},{:.3}",
            c.technique.name(),
            budget,
            c.ms_per_mray(),
            if c.timing.gpu_timestamps {
                "timestamps"
            } else {
                "wall"
            },
            c.timing.wall_ms_per_frame * 1e6 / c.rays as f64,
            fetches,
            hits
        );
    }
    Ok(())
}
