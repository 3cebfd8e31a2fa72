//! The plan of one bake: its checked size, extent and spacing, the
//! surface ranges of its columns, and each depth slice's fill and finish
//! fused into the distance transform's passes (compiled for AVX2 where the
//! machine has it).

use super::options::BakeOptions;
use super::ranges::{column_centres, column_ranges, Centres, RangeGrid, Ranges, RowSource};
use crate::convention::{texel_centre, Extent};
use crate::distance_map::{DistanceMap, R8Encoder};
use crate::edt::{transform_2d_with, Grid2, SliceScratch, BLOCK};
use crate::{Address, Error, HeightMap, Result};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Everything the slices of one bake share: the checked size and extent,
/// voxel spacing, and the surface ranges of the map's columns.
pub(super) struct BakePlan<'h> {
    pub(super) size: [usize; 3],
    pub(super) extent: Extent,
    pub(super) aspect: [f32; 2],
    pub(super) address: Address,
    pub(super) spacing: [f32; 3],
    pub(super) height: &'h HeightMap,
    pub(super) grid: RangeGrid,
    pub(super) ranges: Ranges,
    pub(super) centres: Centres<'h>,
    /// Largest column-centre height: with it, [`Self::slice_lower_bound`].
    pub(super) centre_max: f32,
    pub(super) r_xy: f32,
    pub(super) slack: f32,
}

/// One depth slice's work for [`BakePlan::slice`]: slice `k` into `slice`
/// (or, given `codes`, its R8 codes into those, `slice` then being
/// scratch), with the thread's scratch and its source of column ranges.
pub(super) struct SliceJob<'a, 's> {
    /// The slice's depth index.
    pub(super) k: usize,
    /// The slice's values (or scratch, with `codes`).
    pub(super) slice: &'a mut [f32],
    /// The encoder and the codes to write, for an R8 bake.
    pub(super) codes: Option<(&'a R8Encoder, &'a mut [u8])>,
    /// The 2D transform's scratch.
    pub(super) scratch: &'a mut SliceScratch,
    /// Where each row's height ranges come from.
    pub(super) source: &'a mut RowSource<'s>,
}

/// The body of [`BakePlan::slice`]: the fill and finish of one depth slice
/// around its 2D transform.
macro_rules! slice_body {
    ($plan:expr, $job:expr) => {{
        let SliceJob {
            k,
            slice,
            codes,
            scratch,
            source,
        } = $job;
        let mut codes: Option<(&R8Encoder, &mut [u8])> = codes;
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
        let fill = |j: usize, row: &mut [f32]| match source {
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
        let grid = Grid2 {
            w,
            h,
            spacing: [hx, hy],
            periodic: [periodic; 2],
        };
        transform_2d_with(slice, grid, scratch, true, fill, finish);
        low.into_iter().fold(f32::INFINITY, f32::min)
    }};
}
impl<'h> BakePlan<'h> {
    /// `stored`: keep every column's range (else each slice works out its
    /// rows' own, [`Ranges::PerRow`]).
    pub(super) fn new(height: &'h HeightMap, opts: &BakeOptions, stored: bool) -> Result<Self> {
        let size = opts.size;
        DistanceMap::check_size(size)?;
        let extent = Extent::new(opts.extent.sx, opts.extent.sy, opts.extent.sz)?;
        let [ax, ay] = extent.aspect();
        let [w, h, d] = size;
        let (hx, hy, hz) = (ax / w as f32, ay / h as f32, 1.0 / d as f32);
        let grid = RangeGrid::new(height, w, h);
        let ranges = if stored {
            let (lo, hi) = column_ranges(height, &grid, w, h)?;
            Ranges::Stored { lo, hi }
        } else {
            Ranges::PerRow
        };
        let centres = column_centres(height, w, h, stored)?;
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

    pub(super) fn underestimate(&self) -> f32 {
        2.0 * self.r_xy + 2.0 * self.slack
    }

    /// A lower bound on every value of slice `k`, from the same `f32`
    /// operations [`Self::slices`] uses (each monotone): under the surface a
    /// value is at least `-(hc - z) - slack <= -(max hc - z) - slack`, above
    /// it at least `-r_xy - slack`.
    pub(super) fn slice_lower_bound(&self, k: usize) -> f32 {
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
    pub(super) fn promise(&self, rest: &[f32], next: usize, last_min: f32) -> f32 {
        if next < self.size[2] {
            rest[next].max(monotone_bound(last_min, self.above_bound()))
        } else {
            f32::INFINITY
        }
    }

    /// The least a value above the surface can be: `dist - r_xy - slack`
    /// with `dist >= 0`, in the same `f32` operations.
    pub(super) fn above_bound(&self) -> f32 {
        (0.0 - self.r_xy) - self.slack
    }

    /// Computes slices `first..` into `out` (whole slices), in parallel,
    /// reporting each to `opts.progress` and counting them in `done`.
    pub(super) fn slices(
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
                    let k = first + dk;
                    *slice_min = self.slice(SliceJob {
                        k,
                        slice,
                        codes: None,
                        scratch,
                        source,
                    });
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
    pub(super) fn slice(&self, job: SliceJob) -> f32 {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: AVX2 is present.
            return unsafe { self.slice_avx2(job) };
        }
        slice_body!(self, job)
    }

    /// [`Self::slice`] compiled for AVX2 (its closures too: a closure
    /// takes the target features of the function it is written in, which
    /// is why the body is a macro rather than a function both call).
    ///
    /// # Safety
    /// The CPU has AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn slice_avx2(&self, job: SliceJob) -> f32 {
        slice_body!(self, job)
    }
}

/// Checks the lowest value `min` of depth slices `slices` against the
/// bound `promised` for them ([`BakePlan::promise`]).
pub(super) fn check_promise(slices: std::ops::Range<usize>, min: f32, promised: f32) -> Result<()> {
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
pub(super) const MONOTONE_SLACK: f32 = 1.0 / 4096.0;

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
pub(super) fn monotone_bound(slice_min: f32, above: f32) -> f32 {
    above.min(slice_min) - MONOTONE_SLACK
}

pub(super) fn is_cancelled(opts: &BakeOptions) -> bool {
    opts.cancel
        .as_ref()
        .is_some_and(|c| c.load(Ordering::Relaxed))
}
