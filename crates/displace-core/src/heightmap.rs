//! The height map and the continuous surface it defines: the bilinear
//! interpolation of its texels (texel centres and addressing from
//! [`crate::convention`]), with values in `[0, 1]` (0 = base surface, 1 = top
//! of the shell).

use crate::convention::{check_allocation, texel_lerp, Address};
use crate::horizon::HorizonMap;
use crate::{Error, Result};
use rayon::prelude::*;
use std::sync::{Arc, OnceLock};

/// A displacement map: heights in `[0, 1]` (0 on the base surface, 1 at
/// the top of the shell) on a texel grid, read as a continuous surface of
/// bilinear patches between texel centres, as the software ray-tracing
/// displacement paper intersects it.
#[derive(Clone, Debug)]
pub struct HeightMap {
    width: usize,
    height: usize,
    data: Vec<f32>,
    address: Address,
    /// [`Self::max_steps`], found on first use.
    steps: OnceLock<[f32; 2]>,
    /// [`Self::horizon`], built by [`Self::prepare_horizon`].
    horizon: OnceLock<Option<Arc<HorizonMap>>>,
}

/// Maps are equal when their texels and addressing are.
impl PartialEq for HeightMap {
    fn eq(&self, other: &Self) -> bool {
        self.width == other.width
            && self.height == other.height
            && self.address == other.address
            && self.data == other.data
    }
}

impl HeightMap {
    /// Row-major texels, `data[j * width + i]`, row `j = 0` at `v = 0`.
    /// Refuses maps smaller than 2x2, non-finite values and values outside
    /// `[0, 1]`.
    pub fn new(width: usize, height: usize, data: Vec<f32>, address: Address) -> Result<Self> {
        if width < 2 || height < 2 {
            return Err(Error::InvalidHeightMap(format!(
                "{width}x{height} is too small: a height map needs at least 2x2 texels"
            )));
        }
        if data.len() != width * height {
            return Err(Error::InvalidHeightMap(format!(
                "{width}x{height} needs {} texels, got {}",
                width * height,
                data.len()
            )));
        }
        // In parallel: an 8192x8192 map is 67 M texels.
        if let Some((k, v)) = data
            .par_iter()
            .enumerate()
            .find_first(|(_, v)| !v.is_finite() || **v < 0.0 || **v > 1.0)
        {
            return Err(Error::InvalidHeightMap(format!(
                "texel ({}, {}) is {v}: heights must be finite and in [0, 1]",
                k % width,
                k / width
            )));
        }
        Ok(Self {
            width,
            height,
            data,
            address,
            steps: OnceLock::new(),
            horizon: OnceLock::new(),
        })
    }

    /// Checks a requested size before anything is allocated for it.
    pub fn check_size(width: usize, height: usize) -> Result<()> {
        if width < 2 || height < 2 {
            return Err(Error::InvalidHeightMap(format!(
                "{width}x{height} is too small: a height map needs at least 2x2 texels"
            )));
        }
        check_allocation(
            "height map",
            &format!("{width}x{height}"),
            width as u128 * height as u128,
            4,
        )
    }

    /// Texels per row (along `u`).
    pub fn width(&self) -> usize {
        self.width
    }
    /// Rows (along `v`).
    pub fn height(&self) -> usize {
        self.height
    }
    /// How [`Self::texel`] reads indices past the edges.
    pub fn address(&self) -> Address {
        self.address
    }
    /// The texels, row-major (`data[j * width + i]`), each in `[0, 1]`.
    pub fn data(&self) -> &[f32] {
        &self.data
    }
    /// The same texels read with another addressing mode.
    pub fn with_address(mut self, address: Address) -> Self {
        self.address = address;
        self.steps = OnceLock::new();
        self.horizon = OnceLock::new();
        self
    }

    /// Builds the map's horizon bounds ([`crate::horizon`]) unless they are
    /// built already, so that any-hit queries from then on may answer rays
    /// that leave the surface without tracing them, and keeps them where
    /// they pay: where at least [`crate::horizon::MIN_SHARE`] of the cells
    /// and sectors clear a ray rising `rise` heights per cell (a 45-degree
    /// ray of the face the map is traced on: one shell depth per map unit).
    /// A scene calls it once while it loads; the queries never build them
    /// (a build in the middle of a parallel batch would hold every other
    /// thread). Maps over [`crate::horizon::MAX_HORIZON_CELLS`] get none.
    pub fn prepare_horizon(&self, rise: f32) -> Option<&HorizonMap> {
        self.horizon
            .get_or_init(|| {
                HorizonMap::could_pay(self, rise)
                    .then(|| HorizonMap::build(self))
                    .flatten()
                    .filter(|h| h.pays_at(rise))
                    .map(Arc::new)
            })
            .as_deref()
    }

    /// The horizon bounds, where [`Self::prepare_horizon`] has built them.
    pub fn horizon(&self) -> Option<&HorizonMap> {
        self.horizon.get().and_then(|h| h.as_deref())
    }

    /// The largest difference in height between neighbouring texels along
    /// `u` and along `v`, across the wrap too when the map repeats (clamped
    /// edges add none: the surface is flat past the edge centres).
    ///
    /// Within a bilinear patch the slope along `u` varies linearly between
    /// two such differences, so `steps / texel size` bounds the surface's
    /// slope everywhere: how far its height can move under a point that
    /// moves across it, which is what a curved face's chords must bound
    /// (a chord near the ray's curve in position is near it in height
    /// above the surface only up to that slope). Found once, on first use,
    /// and shared by every face over the map.
    pub fn max_steps(&self) -> [f32; 2] {
        *self.steps.get_or_init(|| {
            let (w, h) = (self.width, self.height);
            let wrap = self.address == Address::Repeat;
            let row_step = |j: usize| {
                let row = &self.data[j * w..(j + 1) * w];
                let inner = row.windows(2).map(|p| (p[1] - p[0]).abs());
                let across = wrap.then(|| (row[0] - row[w - 1]).abs());
                inner.chain(across).fold(0.0f32, f32::max)
            };
            let col_step = |j: usize| {
                let next = if j + 1 < h { j + 1 } else { 0 };
                if next == 0 && !wrap {
                    return 0.0;
                }
                let (a, b) = (
                    &self.data[j * w..(j + 1) * w],
                    &self.data[next * w..(next + 1) * w],
                );
                a.iter()
                    .zip(b)
                    .map(|(x, y)| (y - x).abs())
                    .fold(0.0f32, f32::max)
            };
            let su = (0..h)
                .into_par_iter()
                .map(row_step)
                .reduce(|| 0.0, f32::max);
            let sv = (0..h)
                .into_par_iter()
                .map(col_step)
                .reduce(|| 0.0, f32::max);
            [su, sv]
        })
    }

    /// Texel `(i, j)` with addressing applied to out-of-range indices.
    #[inline]
    pub fn texel(&self, i: i64, j: i64) -> f32 {
        let i = self.address.texel_index(i, self.width);
        let j = self.address.texel_index(j, self.height);
        self.data[j * self.width + i]
    }

    /// The four corners of bilinear cell `(ci, cj)`: the cell whose lower
    /// corner is texel centre `(ci, cj)`; cells `-1` and `W - 1` are the
    /// half-cells at the borders. Order: `h00, h10, h01, h11`.
    #[inline]
    pub fn cell(&self, ci: i64, cj: i64) -> [f32; 4] {
        [
            self.texel(ci, cj),
            self.texel(ci + 1, cj),
            self.texel(ci, cj + 1),
            self.texel(ci + 1, cj + 1),
        ]
    }

    /// [`Self::cell`] with a fast path for interior cells (both corners of
    /// each axis inside the map), which are all but the border ring: four
    /// plain loads from two rows instead of four addressed look-ups. The
    /// throughput tracer ([`crate::cell_trace`]) fetches a cell per patch
    /// it walks.
    #[inline(always)]
    pub fn cell_fast(&self, ci: i64, cj: i64) -> [f32; 4] {
        // One unsigned comparison per axis: a negative index wraps to a
        // huge one.
        let (i, j) = (ci as u64, cj as u64);
        if i < self.width as u64 - 1 && j < self.height as u64 - 1 {
            let k = j as usize * self.width + i as usize;
            let w = self.width;
            // SAFETY: `i < width - 1` and `j < height - 1`, so all four
            // indices are below `width * height == data.len()` (checked by
            // `new`).
            unsafe {
                [
                    *self.data.get_unchecked(k),
                    *self.data.get_unchecked(k + 1),
                    *self.data.get_unchecked(k + w),
                    *self.data.get_unchecked(k + w + 1),
                ]
            }
        } else {
            self.cell(ci, cj)
        }
    }

    /// The continuous surface `h(u, v)`: bilinear between texel centres.
    #[inline]
    pub fn sample(&self, u: f32, v: f32) -> f32 {
        let (i, fx) = texel_lerp(u, self.width);
        let (j, fy) = texel_lerp(v, self.height);
        let [h00, h10, h01, h11] = self.cell_fast(i, j);
        let a = h00 + (h10 - h00) * fx;
        let b = h01 + (h11 - h01) * fx;
        a + (b - a) * fy
    }

    /// `(dh/du, dh/dv)` of the bilinear surface, in height per texture unit.
    #[inline]
    pub fn gradient(&self, u: f32, v: f32) -> [f32; 2] {
        let (i, fx) = texel_lerp(u, self.width);
        let (j, fy) = texel_lerp(v, self.height);
        let [h00, h10, h01, h11] = self.cell(i, j);
        let dfx = (h10 - h00) * (1.0 - fy) + (h11 - h01) * fy;
        let dfy = (h01 - h00) * (1.0 - fx) + (h11 - h10) * fx;
        [dfx * self.width as f32, dfy * self.height as f32]
    }

    /// Exact minimum and maximum of the continuous surface over the texture
    /// rectangle `[u0, u1] x [v0, v1]`. A bilinear patch takes its extremes
    /// over a rectangle at the rectangle's corners, so it is enough to look at
    /// the corners of every piece the texel-centre grid cuts the rectangle
    /// into. This is what makes the bake conservative against the continuous
    /// surface, not just its texels (the flaw of the ray-tracer paper, section 2.3).
    pub fn range(&self, u0: f32, u1: f32, v0: f32, v1: f32) -> (f32, f32) {
        let us = grid_cuts(u0, u1, self.width);
        let vs = grid_cuts(v0, v1, self.height);
        let mut lo = f32::INFINITY;
        let mut hi = f32::NEG_INFINITY;
        for &v in &vs {
            for &u in &us {
                let h = self.sample(u, v);
                lo = lo.min(h);
                hi = hi.max(h);
            }
        }
        (lo, hi)
    }
}

/// `t0`, `t1` and every texel-centre coordinate strictly between them.
fn grid_cuts(t0: f32, t1: f32, n: usize) -> Vec<f32> {
    let mut out = vec![t0];
    let first = (t0 * n as f32 - 0.5).floor() as i64 + 1;
    let mut i = first;
    loop {
        let t = (i as f32 + 0.5) / n as f32;
        if t >= t1 {
            break;
        }
        if t > t0 {
            out.push(t);
        }
        i += 1;
    }
    out.push(t1);
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map(address: Address) -> HeightMap {
        HeightMap::new(3, 2, vec![0.0, 0.5, 1.0, 0.25, 0.75, 0.0], address).unwrap()
    }

    #[test]
    fn max_steps_bound_the_slope_and_follow_the_addressing() {
        // Rows 0 0.5 1 / 0.25 0.75 0: along u 0.5 and 1 (0.75 to 0);
        // along v 0.25, 0.25 and 1 (1 to 0). Repeating adds the wraps:
        // u 1 -> 0 and 0 -> 0.25 (1 and 0.25), v none larger.
        assert_eq!(map(Address::Clamp).max_steps(), [0.75, 1.0]);
        assert_eq!(map(Address::Repeat).max_steps(), [1.0, 1.0]);
        // The surface's slope never exceeds them, anywhere (finite
        // differences of the bilinear surface, in texels).
        let m = map(Address::Repeat);
        let [su, sv] = m.max_steps();
        for k in 0..200 {
            let (u, v) = ((k % 20) as f32 / 20.0, (k / 20) as f32 / 10.0);
            let e = 1e-3;
            let du = (m.sample(u + e, v) - m.sample(u, v)).abs() / e / 3.0;
            let dv = (m.sample(u, v + e) - m.sample(u, v)).abs() / e / 2.0;
            assert!(du <= su * 1.01 && dv <= sv * 1.01, "({u}, {v}): {du} {dv}");
        }
        // A new addressing finds its own steps.
        let clamped = map(Address::Repeat).with_address(Address::Clamp);
        assert_eq!(clamped.max_steps(), [0.75, 1.0]);
    }

    #[test]
    fn samples_texel_centres_exactly() {
        let m = map(Address::Clamp);
        for j in 0..2 {
            for i in 0..3 {
                let u = (i as f32 + 0.5) / 3.0;
                let v = (j as f32 + 0.5) / 2.0;
                assert!((m.sample(u, v) - m.texel(i, j)).abs() < 1e-6);
            }
        }
        // Clamp: the border half-texel is flat.
        assert!((m.sample(0.0, 0.25) - 0.0).abs() < 1e-6);
        // Repeat: the border interpolates towards the opposite edge.
        let r = map(Address::Repeat);
        assert!((r.sample(0.0, 0.25) - 0.5).abs() < 1e-6);
    }

    #[test]
    fn refuses_bad_maps() {
        assert!(HeightMap::new(1, 1, vec![0.0], Address::Clamp).is_err());
        assert!(HeightMap::new(2, 2, vec![0.0; 3], Address::Clamp).is_err());
        assert!(HeightMap::new(2, 2, vec![0.0, f32::NAN, 0.0, 0.0], Address::Clamp).is_err());
        assert!(HeightMap::new(2, 2, vec![0.0, 1.5, 0.0, 0.0], Address::Clamp).is_err());
    }

    #[test]
    fn range_is_exact_on_a_dense_sampling() {
        let m = map(Address::Repeat);
        let (u0, u1, v0, v1) = (0.1, 0.9, 0.2, 0.7);
        let (lo, hi) = m.range(u0, u1, v0, v1);
        let mut slo = f32::INFINITY;
        let mut shi = f32::NEG_INFINITY;
        for a in 0..=200 {
            for b in 0..=200 {
                let h = m.sample(
                    u0 + (u1 - u0) * a as f32 / 200.0,
                    v0 + (v1 - v0) * b as f32 / 200.0,
                );
                slo = slo.min(h);
                shi = shi.max(h);
            }
        }
        assert!(lo <= slo + 1e-6 && lo >= slo - 1e-2);
        assert!(hi >= shi - 1e-6 && hi <= shi + 1e-2);
    }

    #[test]
    fn gradient_matches_finite_differences() {
        let m = map(Address::Repeat);
        let (u, v) = (0.4, 0.6);
        let e = 1e-3;
        let g = m.gradient(u, v);
        let du = (m.sample(u + e, v) - m.sample(u - e, v)) / (2.0 * e);
        let dv = (m.sample(u, v + e) - m.sample(u, v - e)) / (2.0 * e);
        assert!((g[0] - du).abs() < 1e-2, "{g:?} vs {du}");
        assert!((g[1] - dv).abs() < 1e-2, "{g:?} vs {dv}");
    }
}
