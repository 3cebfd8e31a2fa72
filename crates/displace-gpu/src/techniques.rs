//! The techniques engines ship beside distance mapping
//! ([`displace_core::techniques`]) on the GPU: one compute pipeline
//! (`shaders/techniques.wgsl`) that runs any [`Technique`] with any budget
//! on a batch of map-space rays and returns the CPU's own [`Traced`], so
//! `displace compare` can put the two side by side and time the GPU.
//!
//! The technique is a uniform rather than a pipeline per technique: every
//! invocation of a dispatch takes the same branch, so the switch costs
//! nothing, and one module keeps the shader simple. The distance map is
//! uploaded as [`DistanceTexture::R8Load`], the CPU tracer's own 8-bit codes,
//! so distance mapping reads bit for bit what the CPU reads.

use crate::batch::{check_cell_cap, chunk_size, BatchQuery};
use crate::convention::technique_code;
use crate::descriptors::{
    bind_group_layout, storage_entry, texture_entry, uniform_buffer, uniform_entry,
};
use crate::gpu_map::{GpuMap, MapParams};
use crate::shaders::{technique_compute_source, DistanceTexture};
use crate::technique_maps::TechniqueTextures;
use crate::timing::Timing;
use crate::trace::check_rays;
use crate::{Error, GpuContext, Result};
use bytemuck::{Pod, Zeroable};
use displace_core::techniques::{Hit, Maps, Needs, Technique, Traced};
use displace_core::{MapRay, Method, TraceOptions};
use glam::{Vec2, Vec3};

/// Mirror of WGSL `TechniqueParams`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct TechniqueParams {
    technique: u32,
    budget: u32,
    _pad: [u32; 2],
}

/// Mirror of WGSL `TechniqueHitOut`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
struct TechniqueHitOut {
    position: [f32; 3],
    t: f32,
    uv: [f32; 2],
    fetches: u32,
    flags: u32,
}

/// Bit 0 of `TechniqueHitOut::flags` (technique_compute.wgsl).
const TECHNIQUE_FOUND: u32 = 1;

/// The textures of one [`Maps`] and the pipeline that traces them.
pub struct TechniqueTracer {
    query: BatchQuery,
    has_distance: bool,
    textures: TechniqueTextures,
}

/// Labels of the query's ray and hit buffers.
const LABELS: [&str; 2] = ["technique rays", "technique hits"];

impl TechniqueTracer {
    /// Uploads `maps` (whatever precomputations it holds) and builds the
    /// pipeline. A distance map must have been baked from `maps.height`
    /// with `maps.aspect`, as the CPU techniques assume.
    pub fn new(ctx: &GpuContext, maps: &Maps) -> Result<Self> {
        let texture = DistanceTexture::R8Load;
        let map = match &maps.displacement {
            Some(d) => {
                if d.height != maps.height || d.aspect() != maps.aspect {
                    return Err(Error::InvalidOption(
                        "the distance map was baked from another height map or extent".into(),
                    ));
                }
                GpuMap::new(ctx, d, texture)?
            }
            None => GpuMap::for_height(ctx, &maps.height, maps.aspect)?,
        };
        let textures = TechniqueTextures::new(ctx, maps)?;
        let rays_layout = rays_layout(ctx);
        let query = BatchQuery::new(
            ctx,
            ["techniques", "technique_main"],
            technique_compute_source(texture),
            map,
            rays_layout,
            LABELS,
        )?;
        Ok(Self {
            query,
            has_distance: maps.displacement.is_some(),
            textures,
        })
    }

    /// Traces `rays` (map space, unit directions) with `technique` and
    /// `budget`, as [`Technique::trace`] does on the CPU.
    pub fn trace(
        &self,
        ctx: &GpuContext,
        rays: &[MapRay],
        technique: Technique,
        budget: u32,
    ) -> Result<Vec<Traced>> {
        check_rays(rays)?;
        let uniforms = self.uniforms(ctx, technique, budget)?;
        let chunk = chunk_size(ctx, std::mem::size_of::<TechniqueHitOut>() as u64);
        let mut out = Vec::with_capacity(rays.len());
        for batch in rays.chunks(chunk) {
            let extra = self.extra(&uniforms);
            for h in
                self.query
                    .dispatch::<TechniqueHitOut>(ctx, &uniforms.map_group, batch, &extra)?
            {
                check_cell_cap(h.flags, &format!("tracing rays with {}", technique.name()))?;
                out.push(to_traced(&h));
            }
        }
        Ok(out)
    }

    /// GPU time of `frames` dispatches of `technique` over `rays` (at most
    /// one chunk), by the [`crate::timing`] helpers; the hits are discarded.
    pub fn time(
        &self,
        ctx: &GpuContext,
        rays: &[MapRay],
        technique: Technique,
        budget: u32,
        frames: u32,
    ) -> Result<Timing> {
        check_rays(rays)?;
        let chunk = chunk_size(ctx, std::mem::size_of::<TechniqueHitOut>() as u64);
        if rays.len() > chunk {
            return Err(Error::Limit {
                what: "timed ray batch".into(),
                size: rays.len().to_string(),
                limit: format!("{chunk} rays"),
            });
        }
        let uniforms = self.uniforms(ctx, technique, budget)?;
        self.query.time::<TechniqueHitOut>(
            ctx,
            &uniforms.map_group,
            rays,
            &self.extra(&uniforms),
            frames,
        )
    }

    /// The map's bind group and the technique's uniform; refuses a
    /// technique whose precomputation was not uploaded, as the CPU does.
    fn uniforms(&self, ctx: &GpuContext, technique: Technique, budget: u32) -> Result<Uniforms> {
        let needs = technique.needs();
        let present = if needs == Needs::DistanceMap {
            self.has_distance
        } else {
            self.textures.has(needs)
        };
        if !present {
            return Err(Error::InvalidOption(format!(
                "{} needs {needs:?}",
                technique.name()
            )));
        }
        let budget = budget.max(1);
        let opts = TraceOptions {
            method: if technique == Technique::Distance {
                Method::Sphere
            } else {
                Method::SphereFixed
            },
            iterations: budget,
            ..TraceOptions::default()
        };
        let params: MapParams = self.query.map.params(&opts)?;
        let map_buf = uniform_buffer(ctx, "technique map params", &params);
        let technique = TechniqueParams {
            technique: technique_code(technique),
            budget,
            _pad: [0; 2],
        };
        let technique_buf = uniform_buffer(ctx, "technique params", &technique);
        Ok(Uniforms {
            map_group: self.query.map.bind_group(ctx, &map_buf),
            technique: technique_buf,
        })
    }

    /// Bindings 2 to 5 of group 1: the technique's uniform, cones,
    /// relaxed cones and the pyramid.
    fn extra<'a>(&'a self, uniforms: &'a Uniforms) -> [wgpu::BindingResource<'a>; 4] {
        let view = wgpu::BindingResource::TextureView;
        [
            uniforms.technique.as_entire_binding(),
            view(&self.textures.cones),
            view(&self.textures.relaxed),
            view(&self.textures.pyramid),
        ]
    }
}

struct Uniforms {
    map_group: wgpu::BindGroup,
    technique: wgpu::Buffer,
}

fn to_traced(h: &TechniqueHitOut) -> Traced {
    Traced {
        hit: (h.flags & TECHNIQUE_FOUND != 0).then(|| Hit {
            t: h.t,
            position: Vec3::from_array(h.position),
            uv: Vec2::from_array(h.uv),
        }),
        fetches: h.fetches,
    }
}

/// Group 1: rays, hits, the technique's uniform, cones, relaxed cones and
/// the pyramid.
fn rays_layout(ctx: &GpuContext) -> wgpu::BindGroupLayout {
    let compute = wgpu::ShaderStages::COMPUTE;
    let texture = |binding| texture_entry(binding, compute, false, wgpu::TextureViewDimension::D2);
    bind_group_layout(
        ctx,
        "technique rays",
        &[
            storage_entry(0, true),
            storage_entry(1, false),
            uniform_entry(
                2,
                compute,
                wgpu::BufferSize::new(std::mem::size_of::<TechniqueParams>() as u64),
            ),
            texture(3),
            texture(4),
            texture(5),
        ],
    )
}

/// GPU cost of one technique at one budget over a batch of rays.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TechniqueCost {
    /// The technique timed.
    pub technique: Technique,
    /// Its step budget.
    pub budget: u32,
    /// Rays in the batch.
    pub rays: usize,
    /// What a batch cost.
    pub timing: Timing,
}

impl TechniqueCost {
    /// Milliseconds per million rays.
    pub fn ms_per_mray(&self) -> f64 {
        self.timing.ms_per_frame * 1e6 / self.rays.max(1) as f64
    }
}

/// Times every `(technique, budget)` pair on `rays`, `frames` dispatches
/// each, after one untimed warm-up dispatch: what `displace compare` prints
/// as GPU cost. Pairs whose precomputation `maps` lacks are refused.
pub fn technique_costs(
    ctx: &GpuContext,
    maps: &Maps,
    rays: &[MapRay],
    runs: &[(Technique, u32)],
    frames: u32,
) -> Result<Vec<TechniqueCost>> {
    let tracer = TechniqueTracer::new(ctx, maps)?;
    runs.iter()
        .map(|&(technique, budget)| {
            tracer.time(ctx, rays, technique, budget, 1)?;
            let timing = tracer.time(ctx, rays, technique, budget, frames)?;
            Ok(TechniqueCost {
                technique,
                budget,
                rays: rays.len(),
                timing,
            })
        })
        .collect()
}

#[cfg(test)]
mod layout_tests {
    #[test]
    fn technique_records_match_wgsl() {
        use super::{TechniqueHitOut, TechniqueParams};
        use crate::shaders::{assert_layout, offsets, technique_compute_source, DistanceTexture};
        let src = technique_compute_source(DistanceTexture::R32Load);
        let pad = std::mem::offset_of!(TechniqueParams, _pad);
        assert_layout(
            &src,
            "TechniqueParams",
            std::mem::size_of::<TechniqueParams>(),
            &[
                (
                    "technique",
                    std::mem::offset_of!(TechniqueParams, technique),
                ),
                ("budget", std::mem::offset_of!(TechniqueParams, budget)),
                ("_pad0", pad),
                ("_pad1", pad + 4),
            ],
        );
        assert_layout(
            &src,
            "TechniqueHitOut",
            std::mem::size_of::<TechniqueHitOut>(),
            offsets!(TechniqueHitOut {
                position,
                t,
                uv,
                fetches,
                flags
            }),
        );
    }
}
