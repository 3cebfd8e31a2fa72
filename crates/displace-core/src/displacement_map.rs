//! The baked [`DisplacementMap`] that renderers trace: the height map its
//! hits are refined on, its normals and the conservative distance map, for
//! one tile's proportions, with the checks of a trace's options against it.

use crate::convention::{Extent, MAX_CELL_SPAN, MAX_TRACE_ITERATIONS};
use crate::distance_map::DistanceMap;
use crate::sphere_trace::{self, MapHit, MapRay, TraceOptions};
use crate::{Address, Error, HeightMap, NormalMap, Result};
use glam::{Vec2, Vec3};

/// Everything a renderer needs to trace one displaced surface: shared by
/// every face with the same height source, resolution and proportions.
#[derive(Clone, Debug)]
pub struct DisplacementMap {
    /// The source heights: the bilinear surface hits are refined on.
    pub height: HeightMap,
    /// Tangent-space normals for shading, one per height texel.
    pub normals: NormalMap,
    /// The conservative distance map the tracer steps through.
    pub distance: DistanceMap,
    /// Physical size of one tile, to scale map space back to the face.
    pub extent: Extent,
}

impl DisplacementMap {
    /// Tile width and height in shell depths.
    pub fn aspect(&self) -> [f32; 2] {
        self.distance.aspect()
    }

    /// Whether the surface repeats past a tile's edges (the height map's
    /// addressing, which the distance map shares).
    pub fn address(&self) -> Address {
        self.height.address()
    }

    /// First hit of a map-space ray. Faces of a clamped map are one tile.
    /// [`crate::Method::Sphere`] runs the CPU's throughput tracer
    /// ([`crate::cell_trace`]), which finds the same exact hit as
    /// [`Self::trace_counted`]'s GPU-mirroring loop with fewer loads.
    pub fn trace(&self, ray: &MapRay, opts: &TraceOptions) -> Option<MapHit> {
        crate::cell_trace::trace(&self.height, &self.distance, ray, opts)
    }

    /// Whether anything of the displaced solid lies on `ray` within
    /// `[opts.t_min, opts.t_max]`: the shadow-ray query, which may stop
    /// before working out the first hit.
    pub fn occluded(&self, ray: &MapRay, opts: &TraceOptions) -> bool {
        crate::cell_trace::occluded(&self.height, &self.distance, ray, opts)
    }

    /// [`Self::trace`] for many rays, each with its own options: `out[i]`
    /// is exactly `self.trace(&rays[i], &opts[i])`, found eight rays at a
    /// time where the CPU has AVX2 ([`crate::cell_trace::trace_many`]).
    pub fn trace_many(&self, rays: &[MapRay], opts: &[TraceOptions], out: &mut [Option<MapHit>]) {
        crate::cell_trace::trace_many(&self.height, &self.distance, rays, opts, out)
    }

    /// [`Self::trace_many`] handing each hit to `hit(i, ..)` (misses say
    /// nothing): the same hits, without a slice of answers to fill and read
    /// back ([`crate::cell_trace::trace_each`]).
    pub fn trace_each(
        &self,
        rays: &[MapRay],
        opts: &[TraceOptions],
        hit: impl FnMut(usize, MapHit),
    ) {
        crate::cell_trace::trace_each(&self.height, &self.distance, rays, opts, hit)
    }

    /// [`Self::occluded`] for many rays, eight at a time where the CPU
    /// allows: `out[i]` is exactly `self.occluded(&rays[i], &opts[i])`.
    pub fn occluded_many(&self, rays: &[MapRay], opts: &[TraceOptions], out: &mut [bool]) {
        crate::cell_trace::occluded_many(&self.height, &self.distance, rays, opts, out)
    }

    /// The first hit as the GPU tracer finds it (trilinear steps, Donnelly
    /// section 8.3), with its fetch count (distance samples plus patches
    /// walked), which misses report too: what `displace compare` charges
    /// and the WGSL techniques mirror fetch for fetch.
    pub fn trace_counted(&self, ray: &MapRay, opts: &TraceOptions) -> (Option<MapHit>, u32) {
        sphere_trace::trace_counted(&self.height, &self.distance, ray, opts)
    }

    /// Checks that `opts` makes sense for this map before tracing many rays.
    pub fn check_trace(&self, opts: &TraceOptions) -> Result<()> {
        check_iterations(opts.iterations)?;
        if !(opts.tiles.iter().all(|t| t.is_finite() && *t > 0.0)) {
            return Err(Error::InvalidTrace(format!(
                "tiles {:?} must be positive",
                opts.tiles
            )));
        }
        if self.address() == Address::Clamp && opts.tiles != [1.0, 1.0] {
            return Err(Error::InvalidTrace(
                "a clamped map covers exactly one tile; bake with repeat addressing to tile it"
                    .into(),
            ));
        }
        let texels = [self.height.width(), self.height.height()];
        let span = [0, 1].map(|a| f64::from(opts.tiles[a]) * texels[a] as f64);
        if span.iter().any(|&c| c > MAX_CELL_SPAN) {
            return Err(Error::InvalidTrace(format!(
                "{:?} tiles of a {}x{} height map span {:.0} x {:.0} height cells, more than the tracer's limit of {MAX_CELL_SPAN} a side (it steps cells in single precision); use fewer tiles or a smaller height map",
                opts.tiles, texels[0], texels[1], span[0], span[1]
            )));
        }
        Ok(())
    }

    /// Bytes this map holds in memory: heights, normals, the distance
    /// values and their 8-bit codes, and the horizon bounds where they are
    /// built (what a scene's displaced surfaces cost beside the triangles a
    /// tessellation would need).
    pub fn memory_bytes(&self) -> usize {
        let texels = self.height.width() * self.height.height();
        let voxels: usize = self.distance.size().iter().product();
        texels * std::mem::size_of::<f32>()
            + self.normals.data.len() * std::mem::size_of::<Vec3>()
            + voxels * (std::mem::size_of::<f32>() + 1)
            + self.height.horizon().map_or(0, |h| h.bytes())
    }

    /// Builds the height map's horizon bounds ([`crate::horizon`]) for
    /// this map's proportions, keeping them where they pay
    /// ([`HeightMap::prepare_horizon`] with the rise of a 45-degree ray,
    /// one shell depth per map unit: `aspect / width` heights per cell).
    /// Any-hit queries from then on answer the shadow rays that climb
    /// clear of the surface without tracing them. A scene calls it once
    /// while it loads.
    pub fn prepare_horizon(&self) -> Option<&crate::horizon::HorizonMap> {
        let rise = self.aspect()[0] / self.height.width() as f32;
        self.height.prepare_horizon(rise)
    }

    /// Shading normal at texture coordinate `uv` (tiles), map space.
    pub fn shading_normal(&self, uv: Vec2) -> Vec3 {
        self.normals.sample(uv.x, uv.y)
    }

    /// [`Self::shading_normal`] not yet renormalised (its direction, at a
    /// length within rounding of the blend of unit normals), for a renderer
    /// that carries it into the world and normalises there.
    pub fn shading_direction(&self, uv: Vec2) -> Vec3 {
        self.normals.blend(uv.x, uv.y)
    }
}

/// Refuses a step count outside `1..=MAX_TRACE_ITERATIONS`, which
/// [`DisplacementMap::check_trace`] also checks; callers check it before a
/// bake too, so a bad count costs no bake.
pub fn check_iterations(iterations: u32) -> Result<()> {
    if !(1..=MAX_TRACE_ITERATIONS).contains(&iterations) {
        return Err(Error::InvalidTrace(format!(
            "iterations = {iterations}: must be 1..={MAX_TRACE_ITERATIONS} (the most steps one ray may take)"
        )));
    }
    Ok(())
}
