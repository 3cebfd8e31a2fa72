//! GPU timing: a pair of timestamp queries around `frames` passes recorded
//! into one submission, so the figure excludes submission and readback
//! overhead. Without `TIMESTAMP_QUERY` the wall clock around submit-and-wait
//! is used instead, and the result says so.

use crate::{GpuContext, Result};

/// The cost of one frame (or batch), with how it was measured.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Timing {
    /// Milliseconds per frame, by timestamps where the device has them.
    pub ms_per_frame: f64,
    /// True when timed by GPU timestamps, false for the wall clock.
    pub gpu_timestamps: bool,
    /// Wall clock from submission to idle, per frame: a cross-check, since
    /// some drivers (lavapipe's compute passes among them) write timestamps
    /// that do not bracket the work.
    pub wall_ms_per_frame: f64,
}

/// Runs `record(encoder, query_set)` (which records the passes, writing
/// timestamp 0 at the first pass's start and 1 at the last's end when given
/// a query set) and returns the time per frame.
pub fn time_frames(
    ctx: &GpuContext,
    frames: u32,
    record: impl FnOnce(&mut wgpu::CommandEncoder, Option<&wgpu::QuerySet>) -> Result<()>,
) -> Result<Timing> {
    let frames = frames.max(1);
    let query = ctx.timestamps.then(|| {
        ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("timing"),
            ty: wgpu::QueryType::Timestamp,
            count: 2,
        })
    });
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    ctx.checked("recording timed passes", || {
        record(&mut encoder, query.as_ref())
    })??;
    let readback = query.as_ref().map(|q| {
        let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamps"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let readback = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("timestamps readback"),
            size: 16,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        encoder.resolve_query_set(q, 0..2, &resolve, 0);
        encoder.copy_buffer_to_buffer(&resolve, 0, &readback, 0, 16);
        readback
    });
    let start = std::time::Instant::now();
    let commands = ctx.checked("finishing timed passes", || encoder.finish())?;
    ctx.queue.submit([commands]);
    ctx.wait()?;
    let wall = start.elapsed().as_secs_f64() * 1e3;
    match readback {
        Some(buf) => {
            let ticks: Vec<u64> = bytemuck::pod_collect_to_vec(&ctx.read_buffer(&buf)?);
            let ns =
                ticks[1].saturating_sub(ticks[0]) as f64 * ctx.queue.get_timestamp_period() as f64;
            Ok(Timing {
                ms_per_frame: ns / 1e6 / frames as f64,
                gpu_timestamps: true,
                wall_ms_per_frame: wall / frames as f64,
            })
        }
        None => Ok(Timing {
            ms_per_frame: wall / frames as f64,
            gpu_timestamps: false,
            wall_ms_per_frame: wall / frames as f64,
        }),
    }
}

/// Timestamp writes for frame `f` of `frames` compute passes.
pub fn compute_writes(
    query: Option<&wgpu::QuerySet>,
    f: u32,
    frames: u32,
) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
    // A pass with neither index set is a validation error: only the first
    // and the last pass write.
    if f != 0 && f + 1 != frames {
        return None;
    }
    query.map(|q| wgpu::ComputePassTimestampWrites {
        query_set: q,
        beginning_of_pass_write_index: (f == 0).then_some(0),
        end_of_pass_write_index: (f + 1 == frames).then_some(1),
    })
}
