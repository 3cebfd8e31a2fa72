//! The batch ray query on the GPU: one compute invocation per map-space ray,
//! the same trace as [`DisplacementMap::trace`] (`shaders/surface.wgsl`),
//! returning the CPU's own [`MapHit`] so the two backends are
//! interchangeable.

use crate::batch::{check_cell_cap, chunk_size, BatchQuery};
use crate::convention::{FLAG_CONVERGED, HIT_NONE, HIT_SURFACE, HIT_WALL};
use crate::descriptors::{bind_group_layout, storage_entry, uniform_buffer};
use crate::gpu_map::{GpuMap, MapParams};
use crate::shaders::{compute_trace_source, DistanceTexture};
use crate::{Error, GpuContext, Result};
use bytemuck::{Pod, Zeroable};
use displace_core::sphere_trace::HitKind;
use displace_core::{DisplacementMap, MapHit, MapRay, TraceOptions};
use glam::{Vec2, Vec3};

/// What [`trace_rays`] returns per ray: the CPU's hit record.
pub type GpuHit = MapHit;

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

/// Options of the GPU query beyond the CPU's [`TraceOptions`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct GpuTraceOptions {
    /// What the CPU would take: method, iterations, tiles, ray bounds.
    pub trace: TraceOptions,
    /// How the shader reads the distance map.
    pub texture: DistanceTexture,
}

/// A compiled ray-query pipeline for one map, reusable across batches.
pub struct RayTracer {
    query: BatchQuery,
}

/// Labels of the query's ray and hit buffers.
const LABELS: [&str; 2] = ["rays", "hits"];

impl RayTracer {
    /// Uploads `map` and compiles the query for `texture`.
    pub fn new(ctx: &GpuContext, map: &DisplacementMap, texture: DistanceTexture) -> Result<Self> {
        let gpu_map = GpuMap::new(ctx, map, texture)?;
        let rays_layout = bind_group_layout(
            ctx,
            "rays",
            &[storage_entry(0, true), storage_entry(1, false)],
        );
        let query = BatchQuery::new(
            ctx,
            ["ray-query", "trace_main"],
            compute_trace_source(texture),
            gpu_map,
            rays_layout,
            LABELS,
        )?;
        Ok(Self { query })
    }

    /// Traces `rays` (map space, `dir` unit length as for the CPU).
    pub fn trace(
        &self,
        ctx: &GpuContext,
        rays: &[MapRay],
        opts: &TraceOptions,
    ) -> Result<Vec<Option<GpuHit>>> {
        let params = self.query.map.params(opts)?;
        check_rays(rays)?;
        let chunk = chunk_size(ctx, std::mem::size_of::<HitOut>() as u64);
        let params_buf = uniform_buffer::<MapParams>(ctx, "trace params", &params);
        let map_group = self.query.map.bind_group(ctx, &params_buf);
        let mut out = Vec::with_capacity(rays.len());
        for batch in rays.chunks(chunk) {
            for h in self.query.dispatch::<HitOut>(ctx, &map_group, batch, &[])? {
                check_cell_cap(h.flags, "tracing rays")?;
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
        let params = self.query.map.params(opts)?;
        let params_buf = uniform_buffer::<MapParams>(ctx, "trace params", &params);
        let map_group = self.query.map.bind_group(ctx, &params_buf);
        self.query
            .time::<HitOut>(ctx, &map_group, rays, &[], frames)
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

#[cfg(test)]
mod layout_tests {
    /// The batch query's records, in (rays) and out (hits).
    #[test]
    fn ray_and_hit_records_match_wgsl() {
        use super::HitOut;
        use crate::batch::RayIn;
        use crate::shaders::{assert_layout, compute_trace_source, offsets, DistanceTexture};
        let src = compute_trace_source(DistanceTexture::R32Load);
        assert_layout(
            &src,
            "RayIn",
            std::mem::size_of::<RayIn>(),
            offsets!(RayIn {
                origin,
                pad_origin,
                dir,
                pad_dir
            }),
        );
        assert_layout(
            &src,
            "HitOut",
            std::mem::size_of::<HitOut>(),
            offsets!(HitOut {
                position,
                t,
                normal,
                kind,
                uv,
                iterations,
                flags
            }),
        );
    }
}
