//! The batch ray query on the GPU: one compute invocation per map-space ray,
//! the same trace as [`DisplacementMap::trace`] (`shaders/surface.wgsl`),
//! returning the CPU's own [`MapHit`] so the two backends are
//! interchangeable.

use crate::convention::{FLAG_CELL_CAP, FLAG_CONVERGED, HIT_NONE, HIT_SURFACE, HIT_WALL};
use crate::gpu_map::{GpuMap, MapParams};
use crate::shaders::{compute_trace_source, DistanceTexture};
use crate::{Error, GpuContext, Result};
use bytemuck::{Pod, Zeroable};
use displace_core::sphere_trace::HitKind;
use displace_core::{DisplacementMap, MapHit, MapRay, TraceOptions};
use glam::{Vec2, Vec3};
use wgpu::util::DeviceExt;

/// What [`trace_rays`] returns per ray: the CPU's hit record.
pub type GpuHit = MapHit;

/// Mirror of WGSL `RayIn` (convention.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct RayIn {
    origin: [f32; 3],
    _pad0: f32,
    dir: [f32; 3],
    _pad1: f32,
}

impl RayIn {
    /// The shader's copies of `rays`.
    pub(crate) fn all(rays: &[MapRay]) -> Vec<RayIn> {
        rays.iter()
            .map(|r| RayIn {
                origin: r.origin.to_array(),
                _pad0: 0.0,
                dir: r.dir.to_array(),
                _pad1: 0.0,
            })
            .collect()
    }
}

/// Refuses rays the shaders cannot trace, naming the first bad one.
pub(crate) fn check_rays(rays: &[MapRay]) -> Result<()> {
    for (index, r) in rays.iter().enumerate() {
        if !(r.origin.is_finite() && r.dir.is_finite()) {
            return Err(Error::InvalidRay {
                index,
                reason: format!("origin {} and direction {} must be finite", r.origin, r.dir),
            });
        }
        if r.dir.length_squared() == 0.0 {
            return Err(Error::InvalidRay {
                index,
                reason: "direction is zero".into(),
            });
        }
    }
    Ok(())
}

/// Rays per dispatch: what one storage binding of `per_hit`-byte results
/// and one dispatch dimension allow, at most 2^20.
pub(crate) fn chunk_size(ctx: &GpuContext, per_hit: u64) -> usize {
    let by_buffer = ctx.limits.max_storage_buffer_binding_size / per_hit;
    let by_dispatch = ctx.limits.max_compute_workgroups_per_dimension as u64 * WORKGROUP as u64;
    by_buffer.min(by_dispatch).clamp(WORKGROUP as u64, 1 << 20) as usize
}

/// Mirror of WGSL `HitOut`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct HitOut {
    position: [f32; 3],
    t: f32,
    normal: [f32; 3],
    kind: u32,
    uv: [f32; 2],
    iterations: u32,
    flags: u32,
}

pub(crate) const WORKGROUP: u32 = 64;

/// Options of the GPU query beyond the CPU's [`TraceOptions`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuTraceOptions {
    pub trace: TraceOptions,
    pub texture: DistanceTexture,
}

/// A compiled ray-query pipeline for one map, reusable across batches.
pub struct RayTracer {
    map: GpuMap,
    pipeline: wgpu::ComputePipeline,
    rays_layout: wgpu::BindGroupLayout,
}

impl RayTracer {
    pub fn new(ctx: &GpuContext, map: &DisplacementMap, texture: DistanceTexture) -> Result<Self> {
        let gpu_map = GpuMap::new(ctx, map, texture)?;
        let (pipeline, rays_layout) = ctx.checked("building the ray-query pipeline", || {
            let module = ctx
                .device
                .create_shader_module(wgpu::ShaderModuleDescriptor {
                    label: Some("trace_compute"),
                    source: wgpu::ShaderSource::Wgsl(compute_trace_source(texture).into()),
                });
            let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            };
            let rays_layout =
                ctx.device
                    .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                        label: Some("rays"),
                        entries: &[storage(0, true), storage(1, false)],
                    });
            let layout = ctx
                .device
                .create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                    label: Some("trace"),
                    bind_group_layouts: &[Some(&gpu_map.layout), Some(&rays_layout)],
                    immediate_size: 0,
                });
            let pipeline = ctx
                .device
                .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some("trace"),
                    layout: Some(&layout),
                    module: &module,
                    entry_point: Some("trace_main"),
                    compilation_options: Default::default(),
                    cache: None,
                });
            (pipeline, rays_layout)
        })?;
        Ok(Self {
            map: gpu_map,
            pipeline,
            rays_layout,
        })
    }

    /// Traces `rays` (map space, `dir` unit length as for the CPU).
    pub fn trace(
        &self,
        ctx: &GpuContext,
        rays: &[MapRay],
        opts: &TraceOptions,
    ) -> Result<Vec<Option<GpuHit>>> {
        let params = self.map.params(opts)?;
        check_rays(rays)?;
        let chunk = chunk_size(ctx, std::mem::size_of::<HitOut>() as u64);
        let params_buf = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("trace params"),
                contents: bytemuck::bytes_of::<MapParams>(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let map_group = self.map.bind_group(ctx, &params_buf);
        let mut out = Vec::with_capacity(rays.len());
        for batch in rays.chunks(chunk) {
            for h in self.trace_chunk(ctx, &map_group, batch)? {
                if h.flags & FLAG_CELL_CAP != 0 {
                    return Err(Error::Gpu {
                        during: "tracing rays".into(),
                        message:
                            "the exact walk ran past its cell budget (a bug: please report the ray)"
                                .into(),
                    });
                }
                out.push(to_hit(&h)?);
            }
        }
        Ok(out)
    }

    /// Times `frames` dispatches over `rays` (at most one chunk) for the
    /// benchmarks; the hits are discarded.
    pub fn time(
        &self,
        ctx: &GpuContext,
        rays: &[MapRay],
        opts: &TraceOptions,
        frames: u32,
    ) -> Result<crate::timing::Timing> {
        let params = self.map.params(opts)?;
        let params_buf = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("trace params"),
                contents: bytemuck::bytes_of::<MapParams>(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let map_group = self.map.bind_group(ctx, &params_buf);
        let (rays_group, _hits) = self.ray_buffers(ctx, rays);
        let groups = (rays.len() as u32).div_ceil(WORKGROUP);
        if groups > ctx.limits.max_compute_workgroups_per_dimension {
            return Err(Error::Limit {
                what: "ray batch".into(),
                size: rays.len().to_string(),
                limit: format!(
                    "{} workgroups of {WORKGROUP}",
                    ctx.limits.max_compute_workgroups_per_dimension
                ),
            });
        }
        crate::timing::time_frames(ctx, frames, |encoder, query| {
            for f in 0..frames.max(1) {
                let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                    label: Some("trace"),
                    timestamp_writes: crate::timing::compute_writes(query, f, frames.max(1)),
                });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &map_group, &[]);
                pass.set_bind_group(1, &rays_group, &[]);
                pass.dispatch_workgroups(groups, 1, 1);
            }
            Ok(())
        })
    }

    fn ray_buffers(&self, ctx: &GpuContext, rays: &[MapRay]) -> (wgpu::BindGroup, wgpu::Buffer) {
        let input = RayIn::all(rays);
        let size = (rays.len() * std::mem::size_of::<HitOut>()) as u64;
        let ray_buf = ctx
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("rays"),
                contents: bytemuck::cast_slice(&input),
                usage: wgpu::BufferUsages::STORAGE,
            });
        let hit_buf = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("hits"),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let group = ctx.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("rays"),
            layout: &self.rays_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: ray_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: hit_buf.as_entire_binding(),
                },
            ],
        });
        (group, hit_buf)
    }

    fn trace_chunk(
        &self,
        ctx: &GpuContext,
        map_group: &wgpu::BindGroup,
        rays: &[MapRay],
    ) -> Result<Vec<HitOut>> {
        if rays.is_empty() {
            return Ok(Vec::new());
        }
        let size = (rays.len() * std::mem::size_of::<HitOut>()) as u64;
        ctx.checked("tracing rays", || {
            let (rays_group, hit_buf) = self.ray_buffers(ctx, rays);
            let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("hits readback"),
                size,
                usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            });
            let mut encoder = ctx.device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder.begin_compute_pass(&Default::default());
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, map_group, &[]);
                pass.set_bind_group(1, &rays_group, &[]);
                pass.dispatch_workgroups((rays.len() as u32).div_ceil(WORKGROUP), 1, 1);
            }
            encoder.copy_buffer_to_buffer(&hit_buf, 0, &readback, 0, size);
            ctx.queue.submit([encoder.finish()]);
            readback
        })
        .and_then(|readback| ctx.read_buffer(&readback))
        .map(|bytes| bytemuck::pod_collect_to_vec(&bytes))
    }
}

fn to_hit(h: &HitOut) -> Result<Option<GpuHit>> {
    let kind = match h.kind {
        HIT_NONE => return Ok(None),
        HIT_SURFACE => HitKind::Surface,
        HIT_WALL => HitKind::Wall,
        other => {
            return Err(Error::Gpu {
                during: "reading hits".into(),
                message: format!("unknown hit kind {other}"),
            })
        }
    };
    Ok(Some(MapHit {
        t: h.t,
        position: Vec3::from_array(h.position),
        uv: Vec2::from_array(h.uv),
        normal: Vec3::from_array(h.normal),
        kind,
        iterations: h.iterations,
        converged: h.flags & FLAG_CONVERGED != 0,
    }))
}

/// One-shot query: uploads `map`, builds the pipeline and traces `rays`.
/// Keep a [`RayTracer`] instead when tracing several batches.
pub fn trace_rays(
    ctx: &GpuContext,
    map: &DisplacementMap,
    rays: &[MapRay],
    opts: &GpuTraceOptions,
) -> Result<Vec<Option<GpuHit>>> {
    map.check_trace(&opts.trace)?;
    RayTracer::new(ctx, map, opts.texture)?.trace(ctx, rays, &opts.trace)
}
