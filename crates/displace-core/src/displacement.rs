//! The bake (height map -> normal map + conservative distance map) and the
//! baked [`DisplacementMap`] that renderers trace.

use crate::convention::{texel_centre, texel_lerp, Extent, MAX_CELL_SPAN, MAX_TRACE_ITERATIONS};
use crate::distance_map::{DistanceMap, R8Encoder};
use crate::edt::{transform_2d_with, SliceScratch, BLOCK};
use crate::sphere_trace::{self, MapHit, MapRay, TraceOptions};
use crate::{Address, Error, HeightMap, NormalMap, Result};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

pub(crate) mod coded;

/// Called with `(slices done, slices in all)` as the bake progresses.
pub type Progress = Arc<dyn Fn(usize, usize) + Send + Sync>;

/// What [`bake`] builds: the distance map's resolution, the tile's
/// proportions, and the caller's hooks for progress and cancellation.
#[derive(Clone)]
pub struct BakeOptions {
    /// Distance-map voxels `[W, H, D]`. Donnelly used 256x256x16.
    pub size: [usize; 3],
    /// Physical size of one tile of the face.
    pub extent: Extent,
    /// Told after each depth slice; `None` for silence.
    pub progress: Option<Progress>,
    /// Set to stop a bake early; [`bake`] then returns [`Error::Cancelled`].
    pub cancel: Option<Arc<AtomicBool>>,
}

impl Default for BakeOptions {
    fn default() -> Self {
        Self {
            size: [256, 256, 16],
            extent: Extent {
                sx: 1.0,
                sy: 1.0,
                sz: 0.1,
            },
            progress: None,
            cancel: None,
        }
    }
}

impl BakeOptions {
    /// A bake of `size` voxels over tiles of `extent`, silent and not
    /// cancellable: what a caller without a progress bar or a Ctrl-C
    /// handler (a test, a benchmark, a one-off tool) asks for.
    pub fn new(size: [usize; 3], extent: Extent) -> Self {
        Self {
            size,
            extent,
            ..Self::default()
        }
    }
}

impl std::fmt::Debug for BakeOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("BakeOptions")
            .field("size", &self.size)
            .field("extent", &self.extent)
            .finish_non_exhaustive()
    }
}

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
    /// values and their 8-bit codes (what a scene's displaced surfaces cost
    /// beside the triangles a tessellation would need).
    pub fn memory_bytes(&self) -> usize {
        let texels = self.height.width() * self.height.height();
        let voxels: usize = self.distance.size().iter().product();
        texels * std::mem::size_of::<f32>()
            + self.normals.data.len() * std::mem::size_of::<Vec3>()
            + voxels * (std::mem::size_of::<f32>() + 1)
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

/// Bakes the normal map and the conservative distance map of `height` for
/// one tile of `opts.extent`.
///
/// Cost: `O(W H D)` for the distance transform (two 1D passes of the lower
/// envelope per depth slice, slices in parallel) plus the exact height range
/// of every column footprint. Memory: the output plus one 32-column block per
/// thread. [`bake_streamed`] computes the same values a slab at a time, for
/// writers that need not hold the whole volume.
pub fn bake(height: &HeightMap, opts: &BakeOptions) -> Result<DisplacementMap> {
    let plan = BakePlan::new(height, opts, true)?;
    let [w, h, d] = plan.size;
    let done = AtomicUsize::new(0);
    let mut data = vec![0.0f32; w * h * d];
    plan.slices(0, &mut data, &mut vec![0.0; d], opts, &done)?;
    let distance = DistanceMap::from_raw(
        plan.size,
        plan.aspect,
        plan.address,
        data,
        plan.underestimate(),
    )?;
    Ok(DisplacementMap {
        normals: NormalMap::from_height(height, plan.extent),
        height: height.clone(),
        distance,
        extent: plan.extent,
    })
}

/// One slab of consecutive depth slices of a streamed bake, handed to the
/// sink of [`bake_streamed`] in order of depth.
#[derive(Debug)]
pub struct Slab<'a> {
    /// Depth index of the slab's first slice.
    pub first: usize,
    /// The slices' values (`[k][j][i]`, depth units), exactly as [`bake`]
    /// computes them.
    pub values: &'a [f32],
    /// The lowest of `values` (found as they were computed, so a sink need
    /// not pass over them again).
    pub min: f32,
    /// A lower bound on every value of the slices still to come (`+inf`
    /// after the last slab), so that a writer whose header depends on the
    /// volume's minimum (KTX2's r8 range) can settle it early instead of
    /// holding the whole volume.
    pub rest_lower_bound: f32,
}

/// What a streamed bake knows about its map before any slab is computed.
#[derive(Clone, Copy, Debug)]
pub struct BakeLayout {
    /// Distance-map voxels `[W, H, D]`.
    pub size: [usize; 3],
    /// Tile width and height in shell depths.
    pub aspect: [f32; 2],
    /// The map's addressing (the height map's).
    pub address: Address,
    /// Physical size of one tile.
    pub extent: Extent,
    /// The bound [`DistanceMap::from_raw`] takes, before any rounding.
    pub underestimate: f32,
}

/// Where a streamed bake's slabs go ([`crate::io::stream::MapStream`]
/// writes them to a file).
pub trait SlabSink {
    /// Called once, before the first slab, with what a writer needs for its
    /// header.
    fn begin(&mut self, layout: BakeLayout) -> Result<()>;
    /// Called with each slab, in order of depth.
    fn push(&mut self, slab: Slab<'_>) -> Result<()>;

    /// The encoder of the sink's R8 codes, once what it writes no longer
    /// depends on the values still to come (a KTX2 r8 file's range
    /// settled, a DDS r8 file's fixed one): the bake then encodes each
    /// value as it computes it and hands the slabs' codes to
    /// [`Self::push_codes`] instead of their values to [`Self::push`], so
    /// that the values never go through memory as `f32` (their write and
    /// read back were a fifth of an r8 bake). `None`, the default: values.
    fn encoder(&self) -> Option<R8Encoder> {
        None
    }

    /// A buffer for a slab's codes: one the sink has finished with, where
    /// it keeps them, or a new one.
    fn code_buffer(&mut self) -> Vec<u8> {
        Vec::new()
    }

    /// Called with the codes of each slice, in order of depth, once
    /// [`Self::encoder`] gave an encoder (it is asked before each slab).
    fn push_codes(&mut self, slab: CodedSlab) -> Result<()> {
        Err(Error::Invariant(format!(
            "codes of depth slices from {} were pushed to a sink that offered no encoder",
            slab.first
        )))
    }
}

/// Depth slices of a streamed bake as R8 codes ([`SlabSink::push_codes`];
/// one slice each, from the bake's pipeline).
#[derive(Debug)]
pub struct CodedSlab {
    /// Depth index of the first slice.
    pub first: usize,
    /// The codes of the slices' values (`[k][j][i]`), as the sink's
    /// encoder gives them.
    pub codes: Vec<u8>,
    /// The lowest of the slices' values.
    pub min: f32,
    /// A lower bound on every value of the slices still to come (as
    /// [`Slab::rest_lower_bound`]).
    pub rest_lower_bound: f32,
}

/// Bakes the distance map of [`bake`] a slab of `slab_slices` depth slices
/// at a time (each slab's slices in parallel) and hands each slab to `sink`
/// in order, so that peak memory is the height map, its column ranges and
/// one slab rather than the whole volume. The values are bit-identical to
/// [`bake`]'s. Once the sink offers an encoder ([`SlabSink::encoder`]: an
/// r8 file whose range is known, usually after the first slab) and slices
/// are small ([`crate::memory::SMALL_SLICE_VOXELS`]) the rest is computed
/// as codes, each slice taken by whichever of up to `slab_slices`
/// threads is free and pushed in order of depth ([`SlabSink::push_codes`]),
/// with no barrier between slabs.
pub fn bake_streamed(
    height: &HeightMap,
    opts: &BakeOptions,
    slab_slices: usize,
    sink: &mut (impl SlabSink + Send),
) -> Result<()> {
    let stored = crate::memory::stores_column_ranges([height.width(), height.height()], opts.size);
    let plan = BakePlan::new(height, opts, stored)?;
    sink.begin(BakeLayout {
        size: plan.size,
        aspect: plan.aspect,
        address: plan.address,
        extent: plan.extent,
        underestimate: plan.underestimate(),
    })?;
    let [w, h, d] = plan.size;
    let slab_slices = slab_slices.clamp(1, d);
    // Suffix minima of the per-slice lower bounds.
    let mut rest = vec![f32::INFINITY; d + 1];
    for k in (0..d).rev() {
        rest[k] = rest[k + 1].min(plan.slice_lower_bound(k));
    }
    let done = AtomicUsize::new(0);
    let mut buf = vec![0.0f32; w * h * slab_slices];
    let mut mins = vec![0.0f32; slab_slices];
    // The bound promised for the slices still to come, checked on each.
    let mut promised = f32::NEG_INFINITY;
    let small = crate::memory::small_slices(w * h);
    for first in (0..d).step_by(slab_slices) {
        let encoder = if small { sink.encoder() } else { None };
        if let Some(encoder) = encoder {
            // The sink's range is known: codes, a slice at a time.
            return coded::bake_coded(
                &plan, first, promised, &encoder, &rest, &mut buf, sink, opts, &done,
            );
        }
        let n = slab_slices.min(d - first);
        let values = &mut buf[..w * h * n];
        let mins = &mut mins[..n];
        plan.slices(first, values, mins, opts, &done)?;
        let min = mins.iter().copied().fold(f32::INFINITY, f32::min);
        check_promise(first..first + n, min, promised)?;
        let rest_lower_bound = plan.promise(&rest, first + n, mins[n - 1]);
        sink.push(Slab {
            first,
            values,
            min,
            rest_lower_bound,
        })?;
        promised = rest_lower_bound;
    }
    Ok(())
}

/// Checks the lowest value `min` of depth slices `slices` against the
/// bound `promised` for them ([`BakePlan::promise`]).
fn check_promise(slices: std::ops::Range<usize>, min: f32, promised: f32) -> Result<()> {
    if min < promised {
        return Err(Error::Invariant(format!(
            "depth slices {}..{} reach {min}, below the bound {promised} promised for them \
             (the values below the surface rise with depth, within {MONOTONE_SLACK})",
            slices.start, slices.end
        )));
    }
    Ok(())
}

/// Rounding the lower bound of [`monotone_bound`] allows for, in depth
/// units: the transform's values carry a few `f32` roundings of squared
/// distances of at most a few depths (the `edt` module's Precision), under
/// 1e-5 depths, and this is 24 times that. It only decides how soon a KTX2
/// r8 writer may settle its range; [`bake_streamed`] checks every slab
/// against the bound it promised.
const MONOTONE_SLACK: f32 = 1.0 / 4096.0;

/// A lower bound on every value of the slices above one whose lowest value
/// is `slice_min`, given `above`, the least a value above the surface can
/// be.
///
/// Why: below the surface a voxel's value is `-min(D + r, hc - z) - slack`,
/// and both `hc - z` and the distance `D` to the nearest column band (the
/// surface's height range over a column's footprint) shrink as `z` rises.
/// For `hc - z` it is plain. For `D`: say `D(z)` is reached at column `c`,
/// at lateral distance `L`, and `z < z' < hc` at the voxel's column `c0`. If
/// `z'` lies in `c`'s band, or below it (then it is nearer), `D(z') <= D(z)`.
/// If `z'` is above `c`'s band, walk a monotone staircase of columns from
/// `c0` to `c`: neighbours share a footprint edge, so their bands overlap,
/// and the bands along the walk join `c`'s (below `z'`) to `c0`'s (which
/// holds `hc > z'`): one column on the walk, no farther from `c0` than `L`,
/// has `z'` in its band, so `D(z') <= L <= D(z)`. Values above the surface
/// are at least `above`.
fn monotone_bound(slice_min: f32, above: f32) -> f32 {
    above.min(slice_min) - MONOTONE_SLACK
}

/// Everything the slices of one bake share: the checked size and extent,
/// voxel spacing, and the surface ranges of the map's columns.
struct BakePlan<'h> {
    size: [usize; 3],
    extent: Extent,
    aspect: [f32; 2],
    address: Address,
    spacing: [f32; 3],
    height: &'h HeightMap,
    grid: RangeGrid,
    ranges: Ranges,
    centres: Centres<'h>,
    /// Largest column-centre height: with it, [`Self::slice_lower_bound`].
    centre_max: f32,
    r_xy: f32,
    slack: f32,
}

/// The body of [`BakePlan::slice`]: the fill and finish of one depth slice
/// around its 2D transform.
macro_rules! slice_body {
    ($plan:expr, $k:expr, $slice:expr, $scratch:expr, $source:expr, $codes:expr) => {{
        let k: usize = $k;
        let mut codes: Option<(&R8Encoder, &mut [u8])> = $codes;
        let [w, h, d] = $plan.size;
        let [hx, hy, _] = $plan.spacing;
        let periodic = $plan.address == Address::Repeat;
        let (centres, r_xy, slack) = (&$plan.centres, $plan.r_xy, $plan.slack);
        let z = texel_centre(k, d);
        let squared = |row: &mut [f32], lo: &[f32], hi: &[f32]| {
            for ((g, &lo), &hi) in row.iter_mut().zip(lo).zip(hi) {
                // `max` as compare-selects: the operands are finite (the
                // heights are), so `f32::max`'s NaN rule would only cost.
                let (under, over) = (lo - z, z - hi);
                let dz = if under > over { under } else { over };
                let dz = if dz > 0.0 { dz } else { 0.0 };
                *g = dz * dz;
            }
        };
        let fill = |j: usize, row: &mut [f32]| match $source {
            RowSource::Stored { lo, hi } => {
                let span = j * w..(j + 1) * w;
                squared(row, &lo[span.clone()], &hi[span]);
            }
            RowSource::PerRow { rows, lo, hi } => {
                rows.row(j, lo, hi);
                squared(row, lo, hi);
            }
        };
        // Eight running minima, folded once per slice.
        let mut low = [f32::INFINITY; 8];
        let finish = |j: usize, i0: usize, results: &[f32], out: &mut [f32]| {
            let n = out.len();
            // The run's values on the stack, then into the slice or, as
            // codes, into `codes` (the slice is then only the first pass's
            // scratch, and the values never go back to memory as `f32`).
            let mut run_values = [0.0f32; BLOCK];
            let values = &mut run_values[..n];
            let hcs = centres.run(w, h, j, i0, n);
            for ((o, &v), &hc) in values.iter_mut().zip(results).zip(hcs) {
                let dist = v.sqrt();
                // Both sides computed, one kept: a select, not a branch
                // that mispredicts along the surface. Comparisons rather
                // than `f32::min` (whose NaN rule costs a compare and a
                // blend): both operands are finite, and where they tie
                // either is the same value.
                let (near, depth) = (dist + r_xy, hc - z);
                let below = -(if depth < near { depth } else { near });
                let above = dist - r_xy;
                *o = (if z < hc { below } else { above }) - slack;
            }
            // This run's minima in registers, then into the slice's.
            let mut run = low;
            let chunks = values.chunks_exact(8);
            for &v in chunks.remainder() {
                run[0] = if v < run[0] { v } else { run[0] };
            }
            for c in chunks {
                for (l, &v) in run.iter_mut().zip(c) {
                    *l = if v < *l { v } else { *l };
                }
            }
            low = run;
            match codes.as_mut() {
                Some((encoder, codes)) => {
                    encoder.encode_runs(values, &mut codes[j * w + i0..][..n])
                }
                None => out.copy_from_slice(values),
            }
        };
        transform_2d_with(
            $slice,
            w,
            h,
            [hx, hy],
            [periodic, periodic],
            $scratch,
            true,
            fill,
            finish,
        );
        low.into_iter().fold(f32::INFINITY, f32::min)
    }};
}
impl<'h> BakePlan<'h> {
    /// `stored`: keep every column's range (else each slice works out its
    /// rows' own, [`Ranges::PerRow`]).
    fn new(height: &'h HeightMap, opts: &BakeOptions, stored: bool) -> Result<Self> {
        let size = opts.size;
        DistanceMap::check_size(size)?;
        let extent = Extent::new(opts.extent.sx, opts.extent.sy, opts.extent.sz)?;
        let [ax, ay] = extent.aspect();
        let [w, h, d] = size;
        let (hx, hy, hz) = (ax / w as f32, ay / h as f32, 1.0 / d as f32);
        let grid = RangeGrid::new(height, w, h);
        let ranges = if stored {
            let (lo, hi) = column_ranges(height, &grid, w, h);
            Ranges::Stored { lo, hi }
        } else {
            Ranges::PerRow
        };
        let centres = column_centres(height, w, h, stored);
        if is_cancelled(opts) {
            return Err(Error::Cancelled);
        }
        let centre_max = centres.max();
        Ok(Self {
            size,
            extent,
            aspect: [ax, ay],
            address: height.address(),
            spacing: [hx, hy, hz],
            height,
            grid,
            ranges,
            centres,
            centre_max,
            r_xy: 0.5 * (hx * hx + hy * hy).sqrt(),
            slack: 0.5 * (hx * hx + hy * hy + hz * hz).sqrt(),
        })
    }

    fn underestimate(&self) -> f32 {
        2.0 * self.r_xy + 2.0 * self.slack
    }

    /// A lower bound on every value of slice `k`, from the same `f32`
    /// operations [`Self::slices`] uses (each monotone): under the surface a
    /// value is at least `-(hc - z) - slack <= -(max hc - z) - slack`, above
    /// it at least `-r_xy - slack`.
    fn slice_lower_bound(&self, k: usize) -> f32 {
        let z = texel_centre(k, self.size[2]);
        let below = -(self.centre_max - z);
        let above = 0.0 - self.r_xy;
        below.min(above) - self.slack
    }

    /// The bound promised for slices `next..` once the slice below them
    /// has reached `last_min` (`rest`: suffix minima of
    /// [`Self::slice_lower_bound`]; `+inf` past the last slice). Below the
    /// surface, a column's values do not fall from one slice to the next
    /// up ([`monotone_bound`]); above it they are at least the static
    /// bound's `above` part.
    fn promise(&self, rest: &[f32], next: usize, last_min: f32) -> f32 {
        if next < self.size[2] {
            rest[next].max(monotone_bound(last_min, self.above_bound()))
        } else {
            f32::INFINITY
        }
    }

    /// The least a value above the surface can be: `dist - r_xy - slack`
    /// with `dist >= 0`, in the same `f32` operations.
    fn above_bound(&self) -> f32 {
        (0.0 - self.r_xy) - self.slack
    }

    /// Computes slices `first..` into `out` (whole slices), in parallel,
    /// reporting each to `opts.progress` and counting them in `done`.
    fn slices(
        &self,
        first: usize,
        out: &mut [f32],
        mins: &mut [f32],
        opts: &BakeOptions,
        done: &AtomicUsize,
    ) -> Result<()> {
        let (grid, height, w) = (&self.grid, self.height, self.size[0]);
        out.par_chunks_mut(self.size[0] * self.size[1])
            .zip(mins.par_iter_mut())
            .enumerate()
            .try_for_each_init(
                || {
                    (
                        SliceScratch::default(),
                        RowSource::new(&self.ranges, grid, height, w),
                    )
                },
                |(scratch, source), (dk, (slice, slice_min))| {
                    if is_cancelled(opts) {
                        return Err(Error::Cancelled);
                    }
                    *slice_min = self.slice(first + dk, slice, None, scratch, source);
                    let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                    if let Some(p) = &opts.progress {
                        p(n, self.size[2]);
                    }
                    Ok(())
                },
            )
    }

    /// Depth slice `k` into `slice` (or, given `codes`, its R8 codes into
    /// those, `slice` then being scratch); returns its lowest value.
    /// Compiled for AVX2 where the CPU has it: the per-voxel work fused
    /// into the transform's passes (squared band distances in, roots, signs
    /// and margins out) runs eight values an instruction instead of four,
    /// with the same operations and so the same bits.
    fn slice(
        &self,
        k: usize,
        slice: &mut [f32],
        codes: Option<(&R8Encoder, &mut [u8])>,
        scratch: &mut SliceScratch,
        source: &mut RowSource,
    ) -> f32 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is present.
            return unsafe { self.slice_avx2(k, slice, codes, scratch, source) };
        }
        slice_body!(self, k, slice, scratch, source, codes)
    }

    /// [`Self::slice`] compiled for AVX2 (its closures too: a closure
    /// takes the target features of the function it is written in, which
    /// is why the body is a macro rather than a function both call).
    ///
    /// # Safety
    /// The CPU has AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn slice_avx2(
        &self,
        k: usize,
        slice: &mut [f32],
        codes: Option<(&R8Encoder, &mut [u8])>,
        scratch: &mut SliceScratch,
        source: &mut RowSource,
    ) -> f32 {
        slice_body!(self, k, slice, scratch, source, codes)
    }
}

fn is_cancelled(opts: &BakeOptions) -> bool {
    opts.cancel
        .as_ref()
        .is_some_and(|c| c.load(Ordering::Relaxed))
}

/// Cut points along one axis: the `n` column boundaries `i / n` merged with
/// the texel centres of a `texels`-wide map, and for each column the index
/// range of its cuts.
fn axis_cuts(n: usize, texels: usize) -> (Vec<f32>, Vec<(usize, usize)>) {
    let mut cuts = Vec::with_capacity(n + texels + 1);
    let mut spans = Vec::with_capacity(n);
    let mut t = 0usize;
    let centre = |t: usize| (t as f32 + 0.5) / texels as f32;
    for i in 0..=n {
        let b = i as f32 / n as f32;
        while t < texels && centre(t) < b {
            cuts.push(centre(t));
            t += 1;
        }
        if i > 0 {
            spans.push((0, cuts.len()));
        }
        cuts.push(b);
    }
    // Each column runs from its lower boundary to its upper one.
    let mut lower = 0;
    for span in spans.iter_mut() {
        let upper = span.1;
        *span = (lower, upper);
        lower = upper;
    }
    (cuts, spans)
}

/// How the slices find each column's surface range: stored for every
/// column, or worked out a row of columns at a time inside each slice's
/// first pass. The second trades time for memory where the stored ranges
/// would outweigh the slices in flight (8 bytes a column: 537 MB for an
/// 8192x8192 map, more than the two 8K slices a streamed bake holds); both
/// run [`RangeRows::row`], so the values are the same bits.
enum Ranges {
    /// The minimum and maximum of the surface over every column's
    /// footprint, row-major.
    Stored { lo: Vec<f32>, hi: Vec<f32> },
    /// Computed again for each row of each slice.
    PerRow,
}

/// Where one thread's slices read their rows' ranges: the stored arrays, or
/// its own [`RangeRows`] and a row of ranges (made only where they are used).
enum RowSource<'a> {
    Stored {
        lo: &'a [f32],
        hi: &'a [f32],
    },
    PerRow {
        rows: RangeRows<'a>,
        lo: Vec<f32>,
        hi: Vec<f32>,
    },
}

impl<'a> RowSource<'a> {
    fn new(ranges: &'a Ranges, grid: &'a RangeGrid, height: &'a HeightMap, w: usize) -> Self {
        match ranges {
            Ranges::Stored { lo, hi } => Self::Stored { lo, hi },
            Ranges::PerRow => Self::PerRow {
                rows: RangeRows::new(grid, height),
                lo: vec![0.0; w],
                hi: vec![0.0; w],
            },
        }
    }
}

/// The heights at the column centres, which decide the sign: the height
/// map itself where the map's columns sit exactly on its texels (the same
/// size, so each centre's sample is its texel), or their own array in the
/// order the transform's second pass finishes them ([`crate::edt::BLOCK`]
/// columns at a time, a block's rows one after another), so that the pass
/// reads them in the order it writes, not a row's stride apart.
enum Centres<'h> {
    /// Row-major: the height map's texels.
    Texels(&'h [f32]),
    /// Block `c` of `BLOCK` columns holds row `j`'s centres at
    /// `(c * h + j) * BLOCK..`; the last block's missing columns are
    /// `-inf`.
    Blocked(Vec<f32>),
}

impl Centres<'_> {
    /// The `n` centres of row `j` from column `i0`, a multiple of `BLOCK`
    /// (`n <= BLOCK`), of a `w x h`-column map.
    #[inline(always)]
    fn run(&self, w: usize, h: usize, j: usize, i0: usize, n: usize) -> &[f32] {
        match self {
            Self::Texels(t) => &t[j * w + i0..][..n],
            Self::Blocked(b) => &b[((i0 / BLOCK) * h + j) * BLOCK..][..n],
        }
    }

    /// The centre of column `(i, j)`.
    #[cfg(test)]
    fn at(&self, w: usize, h: usize, i: usize, j: usize) -> f32 {
        let i0 = i / BLOCK * BLOCK;
        self.run(w, h, j, i0, i - i0 + 1)[i - i0]
    }

    /// The highest centre.
    fn max(&self) -> f32 {
        let all = match self {
            Self::Texels(t) => t,
            Self::Blocked(b) => &b[..],
        };
        all.par_iter()
            .copied()
            .reduce(|| f32::NEG_INFINITY, f32::max)
    }
}

/// The grid of cuts over which a column's surface range is exact (via
/// [`HeightMap::range`]'s argument: the extremes of a bilinear patch lie at
/// the corners of the pieces the texel grid cuts the footprint into), for a
/// `w x h`-column map.
struct RangeGrid {
    along_u: Vec<(usize, usize, f32)>,
    uspan: Vec<(usize, usize)>,
    /// Every footprint's cuts along u are its edges and its centre, column
    /// `i`'s at `2i..=2i + 2` (a map as wide as its height map).
    halves: bool,
    vs: Vec<f32>,
    vspan: Vec<(usize, usize)>,
}

impl RangeGrid {
    fn new(height: &HeightMap, w: usize, h: usize) -> Self {
        let (us, uspan) = axis_cuts(w, height.width());
        let (vs, vspan) = axis_cuts(h, height.height());
        let halves = uspan
            .iter()
            .enumerate()
            .all(|(i, &span)| span == (2 * i, 2 * i + 2));
        Self {
            along_u: along(height, &us),
            uspan,
            halves,
            vs,
            vspan,
        }
    }
}

/// One thread's evaluator of [`RangeGrid`] rows. Column rows are asked for
/// in increasing order (a slice's rows, a run of rows), so it keeps the last
/// texel rows interpolated along u and the last grid row: a grid row on the
/// boundary of two column rows is sampled once, and each texel row is
/// interpolated along u once rather than once per grid row that reads it.
/// The samples are [`HeightMap::sample`]'s to the bit (the same two
/// interpolations along u, then the one along v); the extremes are taken
/// first across the grid rows, then along each footprint's cuts (min and
/// max of finite values: the order changes at most the sign of a zero,
/// which no distance reads, since a slice's height is never zero).
struct RangeRows<'g> {
    grid: &'g RangeGrid,
    height: &'g HeightMap,
    /// Texel rows interpolated along u, by texel row index: the two most
    /// recent.
    texel: [(usize, Vec<f32>); 2],
    /// The last grid row sampled, by its index in `grid.vs`.
    last: (usize, Vec<f32>),
    /// The grid row being sampled.
    row: Vec<f32>,
    /// Extremes across the grid rows of one column row, per cut along u.
    low: Vec<f32>,
    high: Vec<f32>,
}

impl<'g> RangeRows<'g> {
    fn new(grid: &'g RangeGrid, height: &'g HeightMap) -> Self {
        let n = grid.along_u.len();
        let row = || vec![0.0f32; n];
        Self {
            grid,
            height,
            texel: [(usize::MAX, row()), (usize::MAX, row())],
            last: (usize::MAX, row()),
            row: row(),
            low: row(),
            high: row(),
        }
    }

    /// Texel row `t` interpolated along u, into one of the two slots, and
    /// that slot's index.
    fn texel_row(&mut self, t: usize, keep: usize) -> usize {
        if let Some(k) = self.texel.iter().position(|(i, _)| *i == t) {
            return k;
        }
        // Overwrite the slot not holding the row the caller still needs.
        let k = if self.texel[0].0 == keep { 1 } else { 0 };
        let tw = self.height.width();
        let r = &self.height.data()[t * tw..][..tw];
        let (slot, out) = &mut self.texel[k];
        *slot = t;
        for (o, &(i0, i1, fx)) in out.iter_mut().zip(&self.grid.along_u) {
            *o = r[i0] + (r[i1] - r[i0]) * fx;
        }
        k
    }

    /// Grid row `v` (an index into `grid.vs`) into `self.row`.
    fn sample(&mut self, v: usize) {
        let th = self.height.height();
        let address = self.height.address();
        let (j, fy) = texel_lerp(self.grid.vs[v], th);
        let t0 = address.texel_index(j, th);
        let t1 = address.texel_index(j + 1, th);
        // Each loaded without evicting the other.
        let k0 = self.texel_row(t0, t1);
        let k1 = self.texel_row(t1, t0);
        let (a, b) = (&self.texel[k0].1, &self.texel[k1].1);
        for ((o, &a), &b) in self.row.iter_mut().zip(a).zip(b) {
            *o = a + (b - a) * fy;
        }
    }

    /// `self.row` becomes the last grid row sampled, `v`.
    fn keep(&mut self, v: usize) {
        std::mem::swap(&mut self.last.1, &mut self.row);
        self.last.0 = v;
    }

    /// The exact minimum (`lo`) and maximum (`hi`) of the surface over the
    /// footprints of column row `j`.
    fn row(&mut self, j: usize, lo: &mut [f32], hi: &mut [f32]) {
        let (v0, v1) = self.grid.vspan[j];
        // The first grid row is usually the previous column row's last.
        if self.last.0 != v0 {
            self.sample(v0);
            self.keep(v0);
        }
        if v1 == v0 {
            self.low.copy_from_slice(&self.last.1);
            self.high.copy_from_slice(&self.last.1);
        }
        for v in v0 + 1..=v1 {
            self.sample(v);
            let (row, last) = (&self.row, &self.last.1);
            if v == v0 + 1 {
                for (((l, h), &x), &y) in self
                    .low
                    .iter_mut()
                    .zip(self.high.iter_mut())
                    .zip(row)
                    .zip(last)
                {
                    *l = x.min(y);
                    *h = x.max(y);
                }
            } else {
                for ((l, h), &x) in self.low.iter_mut().zip(self.high.iter_mut()).zip(row) {
                    *l = l.min(x);
                    *h = h.max(x);
                }
            }
            self.keep(v);
        }
        let (low, high) = (&self.low[..], &self.high[..]);
        if self.grid.halves {
            // Each footprint's cuts are its two edges and its centre.
            let n = lo.len();
            let (low, high) = (&low[..2 * n + 1], &high[..2 * n + 1]);
            for (i, (l, h)) in lo.iter_mut().zip(hi.iter_mut()).enumerate() {
                let b = 2 * i;
                *l = low[b].min(low[b + 1]).min(low[b + 2]);
                *h = high[b].max(high[b + 1]).max(high[b + 2]);
            }
            return;
        }
        for ((l, h), &(u0, u1)) in lo.iter_mut().zip(hi.iter_mut()).zip(&self.grid.uspan) {
            let (a, b) = low[u0 + 1..=u1]
                .iter()
                .zip(&high[u0 + 1..=u1])
                .fold((low[u0], high[u0]), |(lo, hi), (&a, &b)| {
                    (lo.min(a), hi.max(b))
                });
            *l = a;
            *h = b;
        }
    }
}

/// For every distance-map column `(i, j)`, row-major, one array per
/// quantity so that the per-slice loops stream them: the exact minimum and
/// maximum of the surface over its footprint ([`RangeRows::row`]). Rows of
/// columns run in parallel, each task evaluating only its own grid rows (a
/// boundary between two tasks twice), so the memory is the output plus a
/// few grid rows per task: the whole grid of an 8192-texel map under a
/// 2048-column one was 420 MB.
fn column_ranges(height: &HeightMap, grid: &RangeGrid, w: usize, h: usize) -> (Vec<f32>, Vec<f32>) {
    let mut lo = vec![0.0f32; w * h];
    let mut hi = vec![0.0f32; w * h];
    lo.par_chunks_mut(w)
        .zip(hi.par_chunks_mut(w))
        .enumerate()
        .for_each_init(
            || RangeRows::new(grid, height),
            |rows, (j, (lo, hi))| rows.row(j, lo, hi),
        );
    (lo, hi)
}

/// The height at every column centre, with exactly the arithmetic of
/// [`HeightMap::sample`]: borrowed from the height map where every sample
/// is bit for bit its texel (checked row by row, not assumed), else a
/// `w x h` array of its own.
fn column_centres(height: &HeightMap, w: usize, h: usize, blocked: bool) -> Centres<'_> {
    let centres = |n: usize| (0..n).map(|i| texel_centre(i, n)).collect::<Vec<_>>();
    let (us, vs) = (centres(w), centres(h));
    let along_u = along(height, &us);
    let data = height.data();
    let texels = w == height.width() && h == height.height() && {
        vs.par_iter()
            .enumerate()
            .map_init(
                || vec![0.0f32; w],
                |row, (j, &v)| {
                    sample_row(height, &along_u, v, row);
                    row.iter()
                        .zip(&data[j * w..(j + 1) * w])
                        .all(|(a, b)| a.to_bits() == b.to_bits())
                },
            )
            .all(|same| same)
    };
    if texels && !blocked {
        return Centres::Texels(data);
    }
    // Block by block, each a run of rows of `BLOCK` centres.
    let mut out = vec![f32::NEG_INFINITY; w.div_ceil(BLOCK) * BLOCK * h];
    out.par_chunks_mut(BLOCK * h.max(1))
        .enumerate()
        .for_each(|(c, block)| {
            let i0 = c * BLOCK;
            let n = BLOCK.min(w - i0);
            for (j, row) in block.chunks_exact_mut(BLOCK).enumerate() {
                if texels {
                    row[..n].copy_from_slice(&data[j * w + i0..][..n]);
                } else {
                    sample_row(height, &along_u[i0..i0 + n], vs[j], &mut row[..n]);
                }
            }
        });
    Centres::Blocked(out)
}

/// Texel addressing and weight along u for each of `us`.
fn along(height: &HeightMap, us: &[f32]) -> Vec<(usize, usize, f32)> {
    let (tw, address) = (height.width(), height.address());
    us.iter()
        .map(|&u| {
            let (i, fx) = texel_lerp(u, tw);
            (
                address.texel_index(i, tw),
                address.texel_index(i + 1, tw),
                fx,
            )
        })
        .collect()
}

/// The surface along one grid row `v` at the points `along_u` describes,
/// with exactly the arithmetic of [`HeightMap::sample`].
fn sample_row(height: &HeightMap, along_u: &[(usize, usize, f32)], v: f32, out: &mut [f32]) {
    let (tw, th, address, data) = (
        height.width(),
        height.height(),
        height.address(),
        height.data(),
    );
    let (j, fy) = texel_lerp(v, th);
    let r0 = &data[address.texel_index(j, th) * tw..][..tw];
    let r1 = &data[address.texel_index(j + 1, th) * tw..][..tw];
    for (o, &(i0, i1, fx)) in out.iter_mut().zip(along_u) {
        let a = r0[i0] + (r0[i1] - r0[i0]) * fx;
        let b = r1[i0] + (r1[i1] - r1[i0]) * fx;
        *o = a + (b - a) * fy;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn column_ranges_match_the_direct_range() {
        let data: Vec<f32> = (0..7 * 5).map(|k| ((k * 37) % 11) as f32 / 10.0).collect();
        for address in [Address::Clamp, Address::Repeat] {
            let hm = HeightMap::new(7, 5, data.clone(), address).unwrap();
            for (w, h) in [(3, 4), (7, 5), (16, 9)] {
                let grid = RangeGrid::new(&hm, w, h);
                let (lo_all, hi_all) = column_ranges(&hm, &grid, w, h);
                let centres = [false, true].map(|blocked| column_centres(&hm, w, h, blocked));
                for j in 0..h {
                    for i in 0..w {
                        let want = hm.range(
                            i as f32 / w as f32,
                            (i + 1) as f32 / w as f32,
                            j as f32 / h as f32,
                            (j + 1) as f32 / h as f32,
                        );
                        let (lo, hi) = (lo_all[j * w + i], hi_all[j * w + i]);
                        let centre = hm.sample(texel_centre(i, w), texel_centre(j, h));
                        for c in &centres {
                            assert_eq!(c.at(w, h, i, j), centre, "{w}x{h} ({i},{j})");
                        }
                        assert!(
                            (lo - want.0).abs() < 1e-6 && (hi - want.1).abs() < 1e-6,
                            "{w}x{h} ({i},{j}): {lo},{hi} vs {want:?}"
                        );
                    }
                }
            }
        }
    }

    fn test_maps() -> Vec<HeightMap> {
        let mut maps = Vec::new();
        for address in [Address::Clamp, Address::Repeat] {
            for (spec, w, h) in [
                ("gen:noise", 32, 32),
                ("gen:studded", 24, 40),
                ("gen:gaussian", 17, 9),
            ] {
                maps.push(crate::generators::generate(spec, w, h, address).unwrap());
            }
        }
        maps
    }

    #[test]
    fn ranges_worked_out_per_row_give_the_stored_ones_bits() {
        for height in test_maps() {
            let (tw, th) = (height.width(), height.height());
            // The height map's own size (the `halves` fast path), coarser,
            // finer and odd.
            for [w, h, d] in [
                [tw, th, 5],
                [tw / 2, th / 3, 4],
                [2 * tw, th + 3, 3],
                [7, 5, 6],
            ] {
                let opts = BakeOptions::new([w, h, d], Extent::new(1.0, 0.7, 0.05).unwrap());
                let done = AtomicUsize::new(0);
                let mut got = [vec![0.0f32; w * h * d], vec![0.0f32; w * h * d]];
                for (stored, out) in [true, false].into_iter().zip(got.iter_mut()) {
                    let plan = BakePlan::new(&height, &opts, stored).unwrap();
                    plan.slices(0, out, &mut vec![0.0; d], &opts, &done)
                        .unwrap();
                }
                let same = got[0]
                    .iter()
                    .zip(&got[1])
                    .all(|(a, b)| a.to_bits() == b.to_bits());
                assert!(same, "{tw}x{th} heights, {w}x{h}x{d} map");
            }
        }
    }

    /// What [`bake_streamed`] promises the slabs to come (`monotone_bound`),
    /// held voxel by voxel: below the surface a column's values never fall
    /// by more than the rounding allowance from one slice to the next up.
    #[test]
    fn values_below_the_surface_do_not_fall_with_depth() {
        let mut worst = 0.0f32;
        for height in test_maps() {
            for (size, extent) in [
                ([32, 32, 16], Extent::new(1.0, 1.0, 0.05).unwrap()),
                ([13, 21, 24], Extent::new(1.0, 1.5, 0.3).unwrap()),
                ([8, 8, 32], Extent::new(1.0, 1.0, 1.0).unwrap()),
            ] {
                let map = bake(&height, &BakeOptions::new(size, extent)).unwrap();
                let [w, h, d] = size;
                let data = map.distance.data();
                for j in 0..h {
                    for i in 0..w {
                        let hc = height.sample(texel_centre(i, w), texel_centre(j, h));
                        for k in 1..d {
                            if texel_centre(k, d) >= hc {
                                break;
                            }
                            let (lower, upper) =
                                (data[((k - 1) * h + j) * w + i], data[(k * h + j) * w + i]);
                            worst = worst.max(lower - upper);
                        }
                    }
                }
            }
        }
        assert!(
            worst <= MONOTONE_SLACK / 24.0,
            "a value fell by {worst} going up a column"
        );
    }
}
