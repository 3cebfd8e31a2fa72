//! `displace bench gpu` (BENCHMARKS.md): Donnelly's setting (section 8.6) and larger frames,
//! timed by GPU timestamps, for the raster path, the compute path and the
//! bare loop of dependent trilinear fetches that bounds them both.

use crate::batch::{compute_pipeline_unchecked, time_compute};
use crate::descriptors::{
    bind_group, bind_group_layout, buffer_of, empty_buffer, storage_entry, uniform_buffer,
    uniform_entry,
};
use crate::gpu_map::GpuMap;
use crate::raster::{Draw, PlaneScene, Renderer, Shadows};
use crate::shaders::{fetch_loop_source, DistanceTexture};
use crate::timing::Timing;
use crate::{GpuContext, RayTracer, Result};
use displace_core::{DisplacementMap, MapRay, Method, TraceOptions};

/// One measured configuration.
#[derive(Clone, Debug)]
pub struct BenchRow {
    /// Which path was timed: `raster` (section 8.5's fragment stage), `compute`
    /// (the batch ray query) or `fetch-loop` (the bare dependent-fetch roofline).
    pub path: String,
    /// The configuration within the path (distance texture, method), as the
    /// benchmark table prints it.
    pub variant: String,
    /// Frame size in pixels (for `compute`, the ray count laid out as a frame).
    pub size: [u32; 2],
    /// Sphere-tracing steps per ray: Donnelly's fixed count (section 8.6 uses 16).
    pub iterations: u32,
    /// What the frames cost.
    pub timing: Timing,
}

impl BenchRow {
    /// Throughput in billions of pixels (or rays) per second, the figure
    /// section 8.6 compares across GPUs.
    pub fn gpix_per_s(&self) -> f64 {
        self.size[0] as f64 * self.size[1] as f64 / (self.timing.ms_per_frame * 1e-3) / 1e9
    }
}

/// A camera looking down the face's normal, slightly tilted, close enough
/// that every pixel lands on the face (Donnelly's "every pixel displaced").
pub fn filled_view(map: &DisplacementMap, size: [u32; 2]) -> PlaneScene {
    let mut scene = PlaneScene::for_map(map, size);
    let e = map.extent;
    let centre = glam::Vec3::new(e.sx * 0.5, e.sy * 0.5, 0.0);
    scene.view.target = centre;
    scene.view.eye = centre + glam::Vec3::new(0.05 * e.sx, -0.1 * e.sy, 0.55 * e.sx.min(e.sy));
    scene.view.up = glam::Vec3::Y;
    scene
}

/// Every pixel's primary ray of `scene`, map space (none for a mesh draw,
/// which has no one texture-space frame).
pub fn frame_rays(map: &DisplacementMap, scene: &PlaneScene) -> Vec<MapRay> {
    let [w, h] = scene.view.size;
    (0..h)
        .flat_map(|y| (0..w).filter_map(move |x| scene.pixel_ray(map, x, y)))
        .collect()
}

/// Raster and compute paths, fixed-step and early-out (and the fixed
/// variant with self-shadowing), plus the bare fetch loop, at one frame
/// size and iteration count.
pub fn bench_config(
    ctx: &GpuContext,
    map: &DisplacementMap,
    size: [u32; 2],
    iterations: u32,
    frames: u32,
) -> Result<Vec<BenchRow>> {
    let texture = DistanceTexture::R8Linear;
    let renderer = Renderer::new(ctx, map, texture)?;
    let tracer = RayTracer::new(ctx, map, texture)?;
    let base = filled_view(map, size);
    let mut rows = Vec::new();
    let mut row = |path: &str, variant: &str, timing| {
        rows.push(BenchRow {
            path: path.into(),
            variant: variant.into(),
            size,
            iterations,
            timing,
        })
    };
    let variants = [
        ("fixed", Method::SphereFixed, Shadows::None),
        ("early-out", Method::Sphere, Shadows::None),
        ("fixed+shadow", Method::SphereFixed, Shadows::Hard),
    ];
    for (name, method, shadows) in variants {
        let scene = PlaneScene {
            draw: Draw {
                method,
                iterations,
                shadows,
                ..base.draw
            },
            ..base
        };
        row("raster", name, renderer.time(ctx, &scene, frames)?);
    }
    let rays = frame_rays(map, &base);
    for (name, method) in [
        ("fixed", Method::SphereFixed),
        ("early-out", Method::Sphere),
    ] {
        let opts = TraceOptions {
            method,
            iterations,
            ..TraceOptions::default()
        };
        row("compute", name, tracer.time(ctx, &rays, &opts, frames)?);
    }
    row(
        "fetch-loop",
        "bare",
        time_fetch_loop(ctx, map, size, iterations, frames)?,
    );
    Ok(rows)
}

/// N dependent filtered fetches per pixel and nothing else.
pub fn time_fetch_loop(
    ctx: &GpuContext,
    map: &DisplacementMap,
    size: [u32; 2],
    steps: u32,
    frames: u32,
) -> Result<Timing> {
    let gpu_map = GpuMap::new(ctx, map, DistanceTexture::R8Linear)?;
    let params = gpu_map.params(&TraceOptions::default())?;
    let params_buf = uniform_buffer(ctx, "fetch params", &params);
    let map_group = gpu_map.bind_group(ctx, &params_buf);
    let loop_buf = buffer_of(
        ctx,
        "fetch loop",
        bytemuck::cast_slice(&[size[0], size[1], steps, 0u32]),
        wgpu::BufferUsages::UNIFORM,
    );
    let out = empty_buffer(
        ctx,
        "fetch out",
        size[0] as u64 * size[1] as u64 * 4,
        wgpu::BufferUsages::STORAGE,
    );
    let (pipeline, group) = ctx.checked("building the fetch loop", || {
        let loop_layout = bind_group_layout(
            ctx,
            "fetch loop",
            &[
                uniform_entry(0, wgpu::ShaderStages::COMPUTE, None),
                storage_entry(1, false),
            ],
        );
        let pipeline = compute_pipeline_unchecked(
            ctx,
            "fetch loop",
            &fetch_loop_source(),
            "fetch_main",
            &[&gpu_map.layout, &loop_layout],
        );
        let group = bind_group(
            ctx,
            "fetch loop",
            &loop_layout,
            &[loop_buf.as_entire_binding(), out.as_entire_binding()],
        );
        (pipeline, group)
    })?;
    time_compute(
        ctx,
        "fetch loop",
        &pipeline,
        [&map_group, &group],
        [size[0].div_ceil(8), size[1].div_ceil(8)],
        frames,
    )
}
