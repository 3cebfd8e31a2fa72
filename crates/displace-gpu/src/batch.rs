//! What every batch ray query shares ([`crate::RayTracer`],
//! [`crate::TechniqueTracer`]): one compute pipeline over the map's group 0
//! and a group 1 of rays and results, one invocation per ray in workgroups
//! of [`WORKGROUP`], dispatched to read the results back or to be timed.

use crate::descriptors::{bind_group, buffer_of, empty_buffer, pipeline_layout, shader_module};
use crate::gpu_map::GpuMap;
use crate::timing::{compute_writes, time_frames, Timing};
use crate::{Error, GpuContext, Result};
use bytemuck::{Pod, Zeroable};
use displace_core::MapRay;

pub(crate) const WORKGROUP: u32 = 64;

/// Mirror of WGSL `RayIn` (convention.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub(crate) struct RayIn {
    pub(crate) origin: [f32; 3],
    pub(crate) pad_origin: f32,
    pub(crate) dir: [f32; 3],
    pub(crate) pad_dir: f32,
}

impl RayIn {
    /// The shader's copies of `rays`.
    pub(crate) fn all(rays: &[MapRay]) -> Vec<RayIn> {
        rays.iter()
            .map(|r| RayIn {
                origin: r.origin.to_array(),
                pad_origin: 0.0,
                dir: r.dir.to_array(),
                pad_dir: 0.0,
            })
            .collect()
    }
}

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

/// Group 1 of a batch query: the `rays` (binding 0), a storage buffer for
/// one `H` per ray (binding 1), then `extra` (bindings 2, 3, ...). Returns
/// the group and the result buffer.
fn ray_buffers<H>(
    ctx: &GpuContext,
    rays_label: &str,
    hits_label: &str,
    layout: &wgpu::BindGroupLayout,
    rays: &[MapRay],
    extra: &[wgpu::BindingResource],
) -> (wgpu::BindGroup, wgpu::Buffer) {
    let ray_buf = buffer_of(
        ctx,
        rays_label,
        bytemuck::cast_slice(&RayIn::all(rays)),
        wgpu::BufferUsages::STORAGE,
    );
    let hit_buf = empty_buffer(
        ctx,
        hits_label,
        (rays.len() * std::mem::size_of::<H>()) as u64,
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    );
    let mut resources = vec![ray_buf.as_entire_binding(), hit_buf.as_entire_binding()];
    resources.extend(extra.iter().cloned());
    let group = bind_group(ctx, rays_label, layout, &resources);
    (group, hit_buf)
}

/// What every batch query holds: the map (group 0), the layout of its
/// group 1 of rays, results and extras, and the pipeline over both.
pub(crate) struct BatchQuery {
    pub(crate) map: GpuMap,
    rays_layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    /// Labels of the ray and result buffers of each dispatch.
    labels: [&'static str; 2],
}

impl BatchQuery {
    /// Compiles `source`'s `entry` over `map`'s group 0 and `rays_layout`
    /// ([`compute_pipeline`]); `labels` name the ray and result buffers.
    pub(crate) fn new(
        ctx: &GpuContext,
        [label, entry]: [&str; 2],
        source: String,
        map: GpuMap,
        rays_layout: wgpu::BindGroupLayout,
        labels: [&'static str; 2],
    ) -> Result<Self> {
        let pipeline = compute_pipeline(ctx, label, source, entry, &[&map.layout, &rays_layout])?;
        Ok(Self {
            map,
            rays_layout,
            pipeline,
            labels,
        })
    }

    /// One dispatch over `rays` (at most one chunk) with `map_group` and a
    /// group 1 of the rays, `H` results and `extra` ([`ray_buffers`]), the
    /// results read back.
    pub(crate) fn dispatch<H: Pod>(
        &self,
        ctx: &GpuContext,
        map_group: &wgpu::BindGroup,
        rays: &[MapRay],
        extra: &[wgpu::BindingResource],
    ) -> Result<Vec<H>> {
        dispatch_and_read(ctx, &self.pipeline, map_group, rays.len(), || {
            self.rays_group::<H>(ctx, rays, extra)
        })
    }

    /// GPU time of `frames` such dispatches ([`time_dispatches`]); the
    /// results are discarded.
    pub(crate) fn time<H>(
        &self,
        ctx: &GpuContext,
        map_group: &wgpu::BindGroup,
        rays: &[MapRay],
        extra: &[wgpu::BindingResource],
        frames: u32,
    ) -> Result<Timing> {
        let (rays_group, _results) = self.rays_group::<H>(ctx, rays, extra);
        time_dispatches(
            ctx,
            &self.pipeline,
            [map_group, &rays_group],
            rays.len(),
            frames,
        )
    }

    fn rays_group<H>(
        &self,
        ctx: &GpuContext,
        rays: &[MapRay],
        extra: &[wgpu::BindingResource],
    ) -> (wgpu::BindGroup, wgpu::Buffer) {
        let [rays_label, results_label] = self.labels;
        ray_buffers::<H>(
            ctx,
            rays_label,
            results_label,
            &self.rays_layout,
            rays,
            extra,
        )
    }
}
