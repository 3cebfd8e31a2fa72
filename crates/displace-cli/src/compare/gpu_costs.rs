//! `compare --gpu`: every technique and budget timed on the GPU's compute
//! path, in a build with the `gpu` feature.

use super::measure::Row;
use anyhow::{Context, Result};
use displace_core::techniques::{Maps, Technique};
use displace_core::MapRay;
use displace_gpu::{technique_costs, GpuContext};

/// Fills `gpu_ns_per_ray` of `rows` (one elevation of one map): the rays
/// repeated to `n` per dispatch, every technique and budget timed on the
/// GPU's compute path.
pub(super) fn time_on_gpu(
    ctx: &GpuContext,
    maps: &Maps,
    rays: &[MapRay],
    n: usize,
    frames: u32,
    rows: &mut [Row],
) -> Result<()> {
    let batch: Vec<MapRay> = rays.iter().copied().cycle().take(n).collect();
    let runs: Vec<(Technique, u32)> = rows.iter().map(|r| (r.technique, r.budget)).collect();
    let costs = technique_costs(ctx, maps, &batch, &runs, frames)
        .context("timing the techniques on the GPU")?;
    for (row, cost) in rows.iter_mut().zip(costs) {
        // Milliseconds per million rays are nanoseconds per ray.
        row.gpu_ns_per_ray = Some(cost.ms_per_mray());
    }
    Ok(())
}
