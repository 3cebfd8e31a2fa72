//! The bake (height map -> normal map + conservative distance map) and the
//! baked [`DisplacementMap`] that renderers trace.

use crate::convention::{texel_centre, texel_lerp, Extent, MAX_TRACE_ITERATIONS};
use crate::distance_map::DistanceMap;
use crate::edt::{transform_2d_with, SliceScratch};
use crate::sphere_trace::{self, MapHit, MapRay, TraceOptions};
use crate::{Address, Error, HeightMap, NormalMap, Result};
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;

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
    let plan = BakePlan::new(height, opts)?;
    let [w, h, d] = plan.size;
    let done = AtomicUsize::new(0);
    let mut data = vec![0.0f32; w * h * d];
    plan.slices(0, &mut data, opts, &done)?;
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
}

/// Bakes the distance map of [`bake`] a slab of `slab_slices` depth slices
/// at a time (each slab's slices in parallel) and hands each slab to `sink`
/// in order, so that peak memory is the height map, its column ranges and
/// one slab rather than the whole volume. The values are bit-identical to
/// [`bake`]'s.
pub fn bake_streamed(
    height: &HeightMap,
    opts: &BakeOptions,
    slab_slices: usize,
    sink: &mut impl SlabSink,
) -> Result<()> {
    let plan = BakePlan::new(height, opts)?;
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
    for first in (0..d).step_by(slab_slices) {
        let n = slab_slices.min(d - first);
        let values = &mut buf[..w * h * n];
        plan.slices(first, values, opts, &done)?;
        sink.push(Slab {
            first,
            values,
            rest_lower_bound: rest[first + n],
        })?;
    }
    Ok(())
}

/// Everything the slices of one bake share: the checked size and extent,
/// voxel spacing, and the column ranges of the height map.
struct BakePlan {
    size: [usize; 3],
    extent: Extent,
    aspect: [f32; 2],
    address: Address,
    spacing: [f32; 3],
    columns: Columns,
    /// Largest column-centre height: with it, [`Self::slice_lower_bound`].
    centre_max: f32,
    r_xy: f32,
    slack: f32,
}

impl BakePlan {
    fn new(height: &HeightMap, opts: &BakeOptions) -> Result<Self> {
        let size = opts.size;
        DistanceMap::check_size(size)?;
        let extent = Extent::new(opts.extent.sx, opts.extent.sy, opts.extent.sz)?;
        let [ax, ay] = extent.aspect();
        let [w, h, d] = size;
        let (hx, hy, hz) = (ax / w as f32, ay / h as f32, 1.0 / d as f32);
        let columns = column_ranges(height, w, h);
        if is_cancelled(opts) {
            return Err(Error::Cancelled);
        }
        let centre_max = columns
            .centre
            .par_iter()
            .copied()
            .reduce(|| f32::NEG_INFINITY, f32::max);
        Ok(Self {
            size,
            extent,
            aspect: [ax, ay],
            address: height.address(),
            spacing: [hx, hy, hz],
            columns,
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

    /// Computes slices `first..` into `out` (whole slices), in parallel,
    /// reporting each to `opts.progress` and counting them in `done`.
    fn slices(
        &self,
        first: usize,
        out: &mut [f32],
        opts: &BakeOptions,
        done: &AtomicUsize,
    ) -> Result<()> {
        let [w, h, d] = self.size;
        let [hx, hy, _] = self.spacing;
        let periodic = self.address == Address::Repeat;
        let (columns, r_xy, slack) = (&self.columns, self.r_xy, self.slack);
        out.par_chunks_mut(w * h).enumerate().try_for_each_init(
            SliceScratch::default,
            |scratch, (dk, slice)| {
                if is_cancelled(opts) {
                    return Err(Error::Cancelled);
                }
                let z = texel_centre(first + dk, d);
                let fill = |j: usize, row: &mut [f32]| {
                    let span = j * w..(j + 1) * w;
                    for ((g, &lo), &hi) in row
                        .iter_mut()
                        .zip(&columns.lo[span.clone()])
                        .zip(&columns.hi[span])
                    {
                        let dz = (lo - z).max(z - hi).max(0.0);
                        *g = dz * dz;
                    }
                };
                let finish = |start: usize, run: &mut [f32]| {
                    for (v, &hc) in run.iter_mut().zip(&columns.centre[start..]) {
                        let dist = v.sqrt();
                        // Both sides computed, one kept: a select, not a branch
                        // that mispredicts along the surface.
                        let below = -(dist + r_xy).min(hc - z);
                        let above = dist - r_xy;
                        *v = (if z < hc { below } else { above }) - slack;
                    }
                };
                transform_2d_with(
                    slice,
                    w,
                    h,
                    [hx, hy],
                    [periodic, periodic],
                    scratch,
                    fill,
                    finish,
                );
                let n = done.fetch_add(1, Ordering::Relaxed) + 1;
                if let Some(p) = &opts.progress {
                    p(n, d);
                }
                Ok(())
            },
        )
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

/// Per distance-map column, in row-major order and one array per quantity
/// so that the per-slice loops stream them.
struct Columns {
    /// Minimum of the surface over the column's footprint.
    lo: Vec<f32>,
    /// Maximum of the surface over the column's footprint.
    hi: Vec<f32>,
    /// Height at the column's centre, which decides the sign.
    centre: Vec<f32>,
}

/// For every distance-map column `(i, j)`: the exact minimum and maximum of
/// the surface over its footprint (via [`HeightMap::range`]'s argument: the
/// extremes of a bilinear patch lie at the corners of the pieces the texel
/// grid cuts the footprint into), and the height at its centre. The surface
/// is evaluated on the grid of all cuts, one grid row at a time, and the
/// extremes are taken along u, then along v. Rows of columns run in
/// parallel, each evaluating only its own grid rows (a boundary row twice),
/// so the memory is the output plus a grid row per thread: the whole grid of
/// an 8192-texel map under a 2048-column one was 420 MB.
fn column_ranges(height: &HeightMap, w: usize, h: usize) -> Columns {
    let (us, uspan) = axis_cuts(w, height.width());
    let (vs, vspan) = axis_cuts(h, height.height());
    let along_u = along(height, &us);
    let mut lo = vec![0.0f32; w * h];
    let mut hi = vec![0.0f32; w * h];
    lo.par_chunks_mut(w)
        .zip(hi.par_chunks_mut(w))
        .enumerate()
        .for_each_init(
            || vec![0.0f32; us.len()],
            |grid_row, (j, (lo, hi))| {
                lo.fill(f32::INFINITY);
                hi.fill(f32::NEG_INFINITY);
                let (v0, v1) = vspan[j];
                for &v in &vs[v0..=v1] {
                    sample_row(height, &along_u, v, grid_row);
                    for ((l, h), &(u0, u1)) in lo.iter_mut().zip(hi.iter_mut()).zip(&uspan) {
                        let (a, b) = grid_row[u0..=u1]
                            .iter()
                            .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), &x| {
                                (lo.min(x), hi.max(x))
                            });
                        *l = l.min(a);
                        *h = h.max(b);
                    }
                }
            },
        );
    let centres = |n: usize| (0..n).map(|i| texel_centre(i, n)).collect::<Vec<_>>();
    let centre = sample_grid(height, &centres(w), &centres(h));
    Columns { lo, hi, centre }
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

/// The surface at every point of the grid `us x vs` (row-major, one row per
/// `v`), with exactly the arithmetic of [`HeightMap::sample`] and so the same
/// values, but with the texel addressing and the weights along u worked out
/// once per `u` rather than once per point.
fn sample_grid(height: &HeightMap, us: &[f32], vs: &[f32]) -> Vec<f32> {
    let along_u = along(height, us);
    let mut grid = vec![0.0f32; us.len() * vs.len()];
    grid.par_chunks_mut(us.len().max(1))
        .zip(vs.par_iter())
        .for_each(|(row, &v)| sample_row(height, &along_u, v, row));
    grid
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
                let got = column_ranges(&hm, w, h);
                for j in 0..h {
                    for i in 0..w {
                        let want = hm.range(
                            i as f32 / w as f32,
                            (i + 1) as f32 / w as f32,
                            j as f32 / h as f32,
                            (j + 1) as f32 / h as f32,
                        );
                        let (lo, hi) = (got.lo[j * w + i], got.hi[j * w + i]);
                        let centre = hm.sample(texel_centre(i, w), texel_centre(j, h));
                        assert_eq!(got.centre[j * w + i], centre, "{w}x{h} ({i},{j})");
                        assert!(
                            (lo - want.0).abs() < 1e-6 && (hi - want.1).abs() < 1e-6,
                            "{w}x{h} ({i},{j}): {lo},{hi} vs {want:?}"
                        );
                    }
                }
            }
        }
    }
}
