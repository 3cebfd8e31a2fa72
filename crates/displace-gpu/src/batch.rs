//! What every batch ray query shares ([`crate::RayTracer`],
//! [`crate::TechniqueTracer`]): one compute pipeline over the map's group 0
//! and a group 1 of rays and results, one invocation per ray in workgroups
//! of [`WORKGROUP`], dispatched to read the results back or to be timed.

use crate::descriptors::{empty_buffer, pipeline_layout, shader_module};
use crate::timing::{compute_writes, time_frames, Timing};
use crate::{Error, GpuContext, Result};
use bytemuck::Pod;

pub(crate) const WORKGROUP: u32 = 64;

/// Compiles `source` and builds the pipeline of `entry` over `layouts`;
/// shader and layout mistakes come back as [`Error::Gpu`].
pub(crate) fn compute_pipeline(
    ctx: &GpuContext,
    label: &str,
    source: String,
    entry: &str,
    layouts: &[&wgpu::BindGroupLayout],
) -> Result<wgpu::ComputePipeline> {
    ctx.checked(&format!("building the {label} pipeline"), || {
        compute_pipeline_unchecked(ctx, label, &source, entry, layouts)
    })
}

/// [`compute_pipeline`] inside the caller's own error scope.
pub(crate) fn compute_pipeline_unchecked(
    ctx: &GpuContext,
    label: &str,
    source: &str,
    entry: &str,
    layouts: &[&wgpu::BindGroupLayout],
) -> wgpu::ComputePipeline {
    let module = shader_module(ctx, label, source);
    let layout = pipeline_layout(ctx, label, layouts);
    ctx.device
        .create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(label),
            layout: Some(&layout),
            module: &module,
            entry_point: Some(entry),
            compilation_options: Default::default(),
            cache: None,
        })
}

/// Rays per dispatch: what one storage binding of `per_hit`-byte results
/// and one dispatch dimension allow, at most 2^20.
pub(crate) fn chunk_size(ctx: &GpuContext, per_hit: u64) -> usize {
    let by_buffer = ctx.limits.max_storage_buffer_binding_size / per_hit;
    let by_dispatch = ctx.limits.max_compute_workgroups_per_dimension as u64 * WORKGROUP as u64;
    by_buffer.min(by_dispatch).clamp(WORKGROUP as u64, 1 << 20) as usize
}

/// One dispatch over `rays` rays with the map's group 0 and the group 1 that
/// `rays_group` makes (with the result buffer it binds), read back.
pub(crate) fn dispatch_and_read<T: Pod>(
    ctx: &GpuContext,
    pipeline: &wgpu::ComputePipeline,
    map_group: &wgpu::BindGroup,
    rays: usize,
    rays_group: impl FnOnce() -> (wgpu::BindGroup, wgpu::Buffer),
) -> Result<Vec<T>> {
    if rays == 0 {
        return Ok(Vec::new());
    }
    let size = (rays * std::mem::size_of::<T>()) as u64;
    ctx.checked("tracing rays", || {
        let (group, results) = rays_group();
        let readback = empty_buffer(
            ctx,
            "results readback",
            size,
            wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        );
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&Default::default());
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, map_group, &[]);
            pass.set_bind_group(1, &group, &[]);
            pass.dispatch_workgroups((rays as u32).div_ceil(WORKGROUP), 1, 1);
        }
        encoder.copy_buffer_to_buffer(&results, 0, &readback, 0, size);
        ctx.queue.submit([encoder.finish()]);
        readback
    })
    .and_then(|readback| ctx.read_buffer(&readback))
    .map(|bytes| bytemuck::pod_collect_to_vec(&bytes))
}

/// Refuses a result whose exact walk hit its cell cap (`FLAG_CELL_CAP`, a
/// bug guard, never expected) or whose loops the driver ended early
/// (`FLAG_LOOP_CUT`: too many steps for this driver, which would otherwise
/// read as a miss).
pub(crate) fn check_cell_cap(flags: u32, during: &str) -> Result<()> {
    if flags & crate::convention::FLAG_LOOP_CUT != 0 {
        return Err(Error::Gpu {
            during: during.to_string(),
            message: "the driver ended the trace loop early (lavapipe stops the loops of one \
                      invocation after 65535 iterations in all): use fewer iterations"
                .into(),
        });
    }
    if flags & crate::convention::FLAG_CELL_CAP == 0 {
        return Ok(());
    }
    Err(Error::Gpu {
        during: during.to_string(),
        message: "the exact walk ran past its cell budget (a bug: please report the ray)".into(),
    })
}

/// GPU time of `frames` dispatches over `rays` rays (timestamps around
/// them, [`crate::timing`]).
pub(crate) fn time_dispatches(
    ctx: &GpuContext,
    pipeline: &wgpu::ComputePipeline,
    groups: [&wgpu::BindGroup; 2],
    rays: usize,
    frames: u32,
) -> Result<Timing> {
    let workgroups = (rays as u32).div_ceil(WORKGROUP);
    if workgroups > ctx.limits.max_compute_workgroups_per_dimension {
        return Err(Error::Limit {
            what: "ray batch".into(),
            size: rays.to_string(),
            limit: format!(
                "{} workgroups of {WORKGROUP}",
                ctx.limits.max_compute_workgroups_per_dimension
            ),
        });
    }
    time_compute(ctx, "timed rays", pipeline, groups, [workgroups, 1], frames)
}

/// GPU time of `frames` dispatches of `workgroups` (x, y) with `groups` as
/// groups 0 and 1 (timestamps around them, [`crate::timing`]).
pub(crate) fn time_compute(
    ctx: &GpuContext,
    label: &str,
    pipeline: &wgpu::ComputePipeline,
    groups: [&wgpu::BindGroup; 2],
    [x, y]: [u32; 2],
    frames: u32,
) -> Result<Timing> {
    let frames = frames.max(1);
    time_frames(ctx, frames, |encoder, query| {
        for f in 0..frames {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(label),
                timestamp_writes: compute_writes(query, f, frames),
            });
            pass.set_pipeline(pipeline);
            pass.set_bind_group(0, groups[0], &[]);
            pass.set_bind_group(1, groups[1], &[]);
            pass.dispatch_workgroups(x, y, 1);
        }
        Ok(())
    })
}
