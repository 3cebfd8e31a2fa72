//! The surface's height range over every column's footprint, and the
//! heights at the columns' centres: stored for the whole map or worked out
//! a row of columns at a time, the same bits either way.

use crate::convention::{texel_centre, texel_lerp};
use crate::edt::BLOCK;
use crate::{memory, HeightMap, Result};
use rayon::prelude::*;

/// Cut points along one axis: the `n` column boundaries `i / n` merged with
/// the texel centres of a `texels`-wide map, and for each column the index
/// range of its cuts.
pub(super) fn axis_cuts(n: usize, texels: usize) -> (Vec<f32>, Vec<(usize, usize)>) {
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
pub(super) enum Ranges {
    /// The minimum and maximum of the surface over every column's
    /// footprint, row-major.
    Stored { lo: Vec<f32>, hi: Vec<f32> },
    /// Computed again for each row of each slice.
    PerRow,
}

/// Where one thread's slices read their rows' ranges: the stored arrays, or
/// its own [`RangeRows`] and a row of ranges (made only where they are used).
pub(super) enum RowSource<'a> {
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
    pub(super) fn new(
        ranges: &'a Ranges,
        grid: &'a RangeGrid,
        height: &'a HeightMap,
        w: usize,
    ) -> Self {
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
pub(super) enum Centres<'h> {
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
    pub(super) fn run(&self, w: usize, h: usize, j: usize, i0: usize, n: usize) -> &[f32] {
        match self {
            Self::Texels(t) => &t[j * w + i0..][..n],
            Self::Blocked(b) => &b[((i0 / BLOCK) * h + j) * BLOCK..][..n],
        }
    }

    /// The centre of column `(i, j)`.
    #[cfg(test)]
    pub(super) fn at(&self, w: usize, h: usize, i: usize, j: usize) -> f32 {
        let i0 = i / BLOCK * BLOCK;
        self.run(w, h, j, i0, i - i0 + 1)[i - i0]
    }

    /// The highest centre.
    pub(super) fn max(&self) -> f32 {
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
pub(super) struct RangeGrid {
    pub(super) along_u: Vec<(usize, usize, f32)>,
    pub(super) uspan: Vec<(usize, usize)>,
    /// Every footprint's cuts along u are its edges and its centre, column
    /// `i`'s at `2i..=2i + 2` (a map as wide as its height map).
    pub(super) halves: bool,
    pub(super) vs: Vec<f32>,
    pub(super) vspan: Vec<(usize, usize)>,
}

impl RangeGrid {
    pub(super) fn new(height: &HeightMap, w: usize, h: usize) -> Self {
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
pub(super) struct RangeRows<'g> {
    pub(super) grid: &'g RangeGrid,
    pub(super) height: &'g HeightMap,
    /// Texel rows interpolated along u, by texel row index: the two most
    /// recent.
    pub(super) texel: [(usize, Vec<f32>); 2],
    /// The last grid row sampled, by its index in `grid.vs`.
    pub(super) last: (usize, Vec<f32>),
    /// The grid row being sampled.
    pub(super) row: Vec<f32>,
    /// Extremes across the grid rows of one column row, per cut along u.
    pub(super) low: Vec<f32>,
    pub(super) high: Vec<f32>,
}

impl<'g> RangeRows<'g> {
    pub(super) fn new(grid: &'g RangeGrid, height: &'g HeightMap) -> Self {
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
    pub(super) fn texel_row(&mut self, t: usize, keep: usize) -> usize {
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
    pub(super) fn sample(&mut self, v: usize) {
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
    pub(super) fn keep(&mut self, v: usize) {
        std::mem::swap(&mut self.last.1, &mut self.row);
        self.last.0 = v;
    }

    /// The exact minimum (`lo`) and maximum (`hi`) of the surface over the
    /// footprints of column row `j`.
    pub(super) fn row(&mut self, j: usize, lo: &mut [f32], hi: &mut [f32]) {
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
pub(super) fn column_ranges(
    height: &HeightMap,
    grid: &RangeGrid,
    w: usize,
    h: usize,
) -> Result<(Vec<f32>, Vec<f32>)> {
    let mut lo = memory::zeroed::<f32>("the columns' lowest heights", w * h)?;
    let mut hi = memory::zeroed::<f32>("the columns' highest heights", w * h)?;
    lo.par_chunks_mut(w)
        .zip(hi.par_chunks_mut(w))
        .enumerate()
        .for_each_init(
            || RangeRows::new(grid, height),
            |rows, (j, (lo, hi))| rows.row(j, lo, hi),
        );
    Ok((lo, hi))
}

/// The height at every column centre, with exactly the arithmetic of
/// [`HeightMap::sample`]: borrowed from the height map where every sample
/// is bit for bit its texel (checked row by row, not assumed), else a
/// `w x h` array of its own.
pub(super) fn column_centres(
    height: &HeightMap,
    w: usize,
    h: usize,
    blocked: bool,
) -> Result<Centres<'_>> {
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
        return Ok(Centres::Texels(data));
    }
    // Block by block, each a run of rows of `BLOCK` centres.
    let n = w.div_ceil(BLOCK) * BLOCK * h;
    let mut out = memory::filled("the columns' centre heights", n, f32::NEG_INFINITY)?;
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
    Ok(Centres::Blocked(out))
}

/// Texel addressing and weight along u for each of `us`.
pub(super) fn along(height: &HeightMap, us: &[f32]) -> Vec<(usize, usize, f32)> {
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
pub(super) fn sample_row(
    height: &HeightMap,
    along_u: &[(usize, usize, f32)],
    v: f32,
    out: &mut [f32],
) {
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
    use crate::bake::plan::MONOTONE_SLACK;
    use crate::bake::*;
    use crate::{Address, Extent};

    #[test]
    fn column_ranges_match_the_direct_range() {
        let data: Vec<f32> = (0..7 * 5).map(|k| ((k * 37) % 11) as f32 / 10.0).collect();
        for address in [Address::Clamp, Address::Repeat] {
            let hm = HeightMap::new(7, 5, data.clone(), address).unwrap();
            for (w, h) in [(3, 4), (7, 5), (16, 9)] {
                let grid = RangeGrid::new(&hm, w, h);
                let (lo_all, hi_all) = column_ranges(&hm, &grid, w, h).unwrap();
                let centres =
                    [false, true].map(|blocked| column_centres(&hm, w, h, blocked).unwrap());
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
