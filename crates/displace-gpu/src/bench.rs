//! `displace bench gpu` (BENCHMARKS.md): Donnelly's setting (section 8.6) and larger frames,
//! timed by GPU timestamps, for the raster path, the compute path and the
//! bare loop of dependent trilinear fetches that bounds them both.

use crate::gpu_map::GpuMap;
use crate::raster::{PlaneScene, Renderer, Shadows};
use crate::shaders::{fetch_loop_source, DistanceTexture};
use crate::timing::{compute_writes, time_frames, Timing};
use crate::{GpuContext, RayTracer, Result};
use displace_core::{DisplacementMap, MapRay, Method, TraceOptions};
use wgpu::util::DeviceExt;

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
    scene.target = centre;
    scene.eye = centre + glam::Vec3::new(0.05 * e.sx, -0.1 * e.sy, 0.55 * e.sx.min(e.sy));
    scene.up = glam::Vec3::Y;
    scene
}

/// Every pixel's primary ray of `scene`, map space.
pub fn frame_rays(map: &DisplacementMap, scene: &PlaneScene) -> Vec<MapRay> {
    let [w, h] = scene.size;
    (0..h)
        .flat_map(|y| (0..w).map(move |x| scene.pixel_ray(map, x, y)))
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
            method,
            iterations,
            shadows,
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
    let params_buf = ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fetch params"),
            contents: bytemuck::bytes_of(&params),
            usage: wgpu::BufferUsages::UNIFORM,
        });
    let map_group = gpu_map.bind_group(ctx, &params_buf);
    let loop_buf = ctx
        .device
        .create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("fetch loop"),
            contents: bytemuck::cast_slice(&[size[0], size[1], steps, 0u32]),
            usage: wgpu::BufferUsages::UNIFORM,
        });
    let out = ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("fetch out"),
        size: size[0] as u64 * size[1] as u64 * 4,
        usage: wgpu::BufferUsages::STORAGE,
        mapped_at_creation: false,
    });
    let pipeline = ctx.checked("building the fetch loop", || {
        let module = ctx
            .device
            .create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some("fetch loop"),
                source: wgpu::ShaderSource::Wgsl(fetch_loop_source().into()),
            });
        let entry = |binding, ty| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let loop_layout = ctx
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("fetch loop"),
                entries: &[
                    entry(0, wgpu::BufferBindingType::Uniform),
                    entry(1, wgpu::BufferBindingType::Storage { read_only: false }),
                ],
            });
        let layout = ctx
            .device
            .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("fetch loop"),
                bind_group_layouts: &[Some(&gpu_map.layout), Some(&loop_layout)],
                immediate_size: 0,
            });
        let pipeline = ctx
            .device
            .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("fetch loop"),
                layout: Some(&layout),
                module: &module,
                entry_point: Some("fetch_main"),
                compilation_options: Default::default(),
                cache: None,
            });
        let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("fetch loop"),
            layout: &loop_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: loop_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: out.as_entire_binding(),
                },
            ],
        });
        (pipeline, group)
    })?;
    let (pipeline, group) = pipeline;
    let frames = frames.max(1);
    time_frames(ctx, frames, |encoder, query| {
        for f in 0..frames {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("fetch loop"),
                timestamp_writes: compute_writes(query, f, frames),
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &map_group, &[]);
            pass.set_bind_group(1, &group, &[]);
            pass.dispatch_workgroups(size[0].div_ceil(8), size[1].div_ceil(8), 1);
        }
        Ok(())
    })
}
