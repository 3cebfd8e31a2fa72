//! Cone step mapping (Dummer 2006) and relaxed cone stepping (Policarpo and
//! Oliveira, GPU Gems 3 ch. 18), with their cone maps.
//!
//! A cone map stores, per height texel, a cone ratio `c` (horizontal over
//! vertical, in map units: shell depths both ways, so the ratio depends on
//! the face's proportions). Tracing reads the height `h` under the current
//! point (bilinear) and the ratio of the texel it lies in (nearest), and
//! steps to where the ray meets the cone of apex `(x, y, h)`: with the ray
//! falling `s_v` and moving `s_h` sideways per unit length, and `z - h`
//! above the surface (texture space's `depth_surface - depth_ray`), the step
//! is `c (z - h) / (c s_v + s_h)`, Dummer's formula with depth turned into
//! height.
//!
//! **Conservative cones** ([`ConeKind::Conservative`]) contain no surface,
//! for any apex in the texel, so a step never passes the first hit. Dummer
//! bakes them from texel samples, which is not safe on the bilinear
//! surface; here the ratio of texel `T` (footprint `[i, i + 1] / W`) is the
//! largest `c` with `h(q) - h(p) <= |q - p| / c` for every `p` in `T` and
//! every surface point `q` of the face, bounded exactly from below:
//! texels `Q` next to `T` through the steepest slope over the 3x3 block
//! (the segment `p -> q` stays in it; a bilinear patch is steepest at a
//! corner), farther ones through `dist(T, Q) / (max_Q h - min_T h)`.
//!
//! **Relaxed cones** ([`ConeKind::Relaxed`]) may contain surface, but no
//! point where a viewing ray through the top of the texel's column leaves
//! the surface after entering it, so one step crosses the surface at most
//! once and a binary search on the last step finds the hit. Baked as
//! Policarpo and Oliveira's listing 18-5: for each other texel `Q`, the ray
//! from `(T, top)` through `Q`'s surface point is marched on until it comes
//! out of the surface, and the ratio is capped by that exit point. The
//! march steps a quarter texel; a ray that only comes out past the face or
//! the floor does not constrain the cone.

use super::linear::{bisect, Bracket, BINARY_STEPS};
use super::{Segment, Traced};
use crate::bake::Progress;
use crate::convention::texel_centre;
use crate::HeightMap;
use glam::{Vec2, Vec3};
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Largest ratio stored: a cone that wide covers any face the tests and
/// `displace compare` use from any height.
pub const MAX_RATIO: f32 = 1.0e6;

/// Which cones a [`ConeMap`] holds (module docs give both definitions).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ConeKind {
    /// Cones that contain no surface (Dummer 2006): a step never passes the
    /// first hit.
    Conservative,
    /// Relaxed cones (Policarpo and Oliveira, GPU Gems 3 ch. 18): a step
    /// crosses the surface at most once, and a binary search finds the hit.
    Relaxed,
}

impl ConeKind {
    /// `conservative` or `relaxed`, as reports print it.
    pub fn name(self) -> &'static str {
        match self {
            ConeKind::Conservative => "conservative",
            ConeKind::Relaxed => "relaxed",
        }
    }
}

/// Cone ratios, one per height texel, row-major.
#[derive(Clone, Debug, PartialEq)]
pub struct ConeMap {
    kind: ConeKind,
    width: usize,
    height: usize,
    /// Texel size in map units.
    texel: Vec2,
    data: Vec<f32>,
}

impl ConeMap {
    /// Bakes the cone map of `height` for a tile of `aspect` (shell depths),
    /// texels in parallel.
    pub fn build(height: &HeightMap, aspect: [f32; 2], kind: ConeKind) -> Self {
        Self::built(height, aspect, kind, None, &|| false)
    }

    /// [`Self::build`], telling `progress` `(rows done, rows)` as rows of
    /// texels finish, and stopping within a texel's work when `cancel` is
    /// raised ([`crate::Error::Cancelled`]): relaxed cones of a large smooth
    /// map take minutes.
    pub fn build_with(
        height: &HeightMap,
        aspect: [f32; 2],
        kind: ConeKind,
        progress: Option<&Progress>,
        cancel: Option<&std::sync::atomic::AtomicBool>,
    ) -> crate::Result<Self> {
        let stop = || cancel.is_some_and(|c| c.load(Ordering::Relaxed));
        let map = Self::built(height, aspect, kind, progress, &stop);
        if stop() {
            return Err(crate::Error::Cancelled);
        }
        Ok(map)
    }

    fn built(
        height: &HeightMap,
        aspect: [f32; 2],
        kind: ConeKind,
        progress: Option<&Progress>,
        stop: &(dyn Fn() -> bool + Sync),
    ) -> Self {
        let (w, h) = (height.width(), height.height());
        let texel = Vec2::new(aspect[0] / w as f32, aspect[1] / h as f32);
        let done = AtomicUsize::new(0);
        let row_done = || {
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            if let Some(p) = progress {
                p(n, h);
            }
        };
        let data = match kind {
            ConeKind::Conservative => conservative(height, texel, &row_done, stop),
            ConeKind::Relaxed => relaxed(height, aspect, texel, &row_done, stop),
        };
        Self {
            kind,
            width: w,
            height: h,
            texel,
            data,
        }
    }

    /// Which cones the map holds.
    pub fn kind(&self) -> ConeKind {
        self.kind
    }
    /// Ratios per row: the height map's width.
    pub fn width(&self) -> usize {
        self.width
    }
    /// Rows: the height map's height.
    pub fn height(&self) -> usize {
        self.height
    }
    /// Row-major ratios, `data[j * width + i]`.
    pub fn data(&self) -> &[f32] {
        &self.data
    }
    /// Memory the ratios take as float32.
    pub fn bytes(&self) -> usize {
        self.data.len() * 4
    }

    /// The ratio of the texel under map-space `p` (nearest, clamped).
    pub fn ratio_at(&self, p: Vec3) -> f32 {
        let i = ((p.x / self.texel.x) as i64).clamp(0, self.width as i64 - 1) as usize;
        let j = ((p.y / self.texel.y) as i64).clamp(0, self.height as i64 - 1) as usize;
        self.data[j * self.width + i]
    }
}

/// Exact range of the surface over every texel footprint.
fn footprint_ranges(height: &HeightMap) -> Vec<(f32, f32)> {
    let (w, h) = (height.width(), height.height());
    (0..h)
        .into_par_iter()
        .flat_map_iter(|j| {
            (0..w).map(move |i| {
                height.range(
                    i as f32 / w as f32,
                    (i + 1) as f32 / w as f32,
                    j as f32 / h as f32,
                    (j + 1) as f32 / h as f32,
                )
            })
        })
        .collect()
}

/// Steepest slope (height per map unit) of every bilinear cell, indexed by
/// cell + 1 as [`super::MaxPyramid`] does: `(W + 1) x (H + 1)`.
fn cell_slopes(height: &HeightMap, texel: Vec2) -> Vec<f32> {
    let (w, h) = (height.width() + 1, height.height() + 1);
    (0..h)
        .into_par_iter()
        .flat_map_iter(|k| {
            (0..w).map(move |i| {
                let [h00, h10, h01, h11] = height.cell(i as i64 - 1, k as i64 - 1);
                let (a, b, c) = (h10 - h00, h01 - h00, h00 - h10 - h01 + h11);
                let mut s = 0.0f32;
                for (fx, fy) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
                    let gx = (a + c * fy) / texel.x;
                    let gy = (b + c * fx) / texel.y;
                    s = s.max((gx * gx + gy * gy).sqrt());
                }
                s
            })
        })
        .collect()
}

/// The cones of every texel; a row started after `stop` holds is left
/// empty (the caller discards the map).
fn conservative(
    height: &HeightMap,
    texel: Vec2,
    row_done: &(dyn Fn() + Sync),
    stop: &(dyn Fn() -> bool + Sync),
) -> Vec<f32> {
    let (w, h) = (height.width() as i64, height.height() as i64);
    let ranges = footprint_ranges(height);
    let slopes = cell_slopes(height, texel);
    let range = |i: i64, j: i64| ranges[(j * w + i) as usize];
    let peaks = BlockMax::new(ranges.iter().map(|r| r.1).collect(), w, h);
    (0..h)
        .into_par_iter()
        .flat_map_iter(|j| {
            let (range, slopes, peaks) = (&range, &slopes, &peaks);
            if stop() {
                return Vec::new();
            }
            let row: Vec<f32> = (0..w)
                .map(move |i| {
                    let lo = range(i, j).0;
                    // Texels next to T: the steepest slope over the 3x3 block,
                    // whose bilinear cells are indices i - 1 ..= i + 2.
                    let mut best = MAX_RATIO;
                    let mut rises = false;
                    let mut slope = 0.0f32;
                    for jj in (j - 1).max(0)..=(j + 1).min(h - 1) {
                        for ii in (i - 1).max(0)..=(i + 1).min(w - 1) {
                            rises |= range(ii, jj).1 > lo;
                        }
                    }
                    if rises {
                        for k in (j - 1).max(0)..=(j + 2).min(h) {
                            for c in (i - 1).max(0)..=(i + 2).min(w) {
                                slope = slope.max(slopes[(k * (w + 1) + c) as usize]);
                            }
                        }
                        if slope > 0.0 {
                            best = best.min(1.0 / slope);
                        }
                    }
                    // Farther texels (Chebyshev distance 2 and up): through the
                    // gap between the footprints, searched block by block.
                    if lo < 1.0 {
                        let ratio = |gx: i64, gy: i64, hi: f32| {
                            let dx = ((gx - 1) as f32 * texel.x).max(0.0);
                            let dy = ((gy - 1) as f32 * texel.y).max(0.0);
                            (dx * dx + dy * dy).sqrt() / (hi - lo)
                        };
                        peaks.search(
                            (i, j),
                            &mut best,
                            |[gx, gy], hi| {
                                if hi > lo {
                                    ratio(gx, gy, hi)
                                } else {
                                    f32::INFINITY
                                }
                            },
                            |(ii, jj), best| {
                                let (gx, gy) = ((ii - i).abs(), (jj - j).abs());
                                let hi = range(ii, jj).1;
                                if gx.max(gy) >= 2 && hi > lo {
                                    *best = best.min(ratio(gx, gy, hi));
                                }
                            },
                        );
                    }
                    best
                })
                .collect();
            row_done();
            row
        })
        .collect()
}

fn relaxed(
    height: &HeightMap,
    aspect: [f32; 2],
    texel: Vec2,
    row_done: &(dyn Fn() + Sync),
    stop: &(dyn Fn() -> bool + Sync),
) -> Vec<f32> {
    let (w, h) = (height.width() as i64, height.height() as i64);
    let centre = |i: i64, j: i64| {
        Vec2::new(
            texel_centre(i as usize, w as usize) * aspect[0],
            texel_centre(j as usize, h as usize) * aspect[1],
        )
    };
    let surface = |p: Vec2| height.sample(p.x / aspect[0], p.y / aspect[1]);
    let march = 0.25 * texel.min_element();
    let peaks = BlockMax::new(height.data().to_vec(), w, h);
    // Where the ray is below the lowest texel a sample could interpolate,
    // it is still inside the surface: that step needs no sample. A sample
    // at texel coordinate t (centre of texel i at i + 0.5) interpolates
    // texels floor(t) - 1 ..= floor(t) + 1, so block `t / FLOOR` takes the
    // minimum over its texels and one more on each side (through the map's
    // addressing). The margin covers the interpolation's rounding.
    const FLOOR: i64 = 4;
    let (bw, bh) = (w / FLOOR + 1, h / FLOOR + 1);
    let floors: Vec<f32> = (0..bh)
        .flat_map(|by| (0..bw).map(move |bx| (bx, by)))
        .map(|(bx, by)| {
            let mut m = f32::INFINITY;
            for jj in by * FLOOR - 1..=(by + 1) * FLOOR {
                for ii in bx * FLOOR - 1..=(bx + 1) * FLOOR {
                    m = m.min(height.texel(ii, jj));
                }
            }
            m - 1e-6
        })
        .collect();
    let inside = |xy: Vec2, z: f32| {
        let bx = ((xy.x / texel.x) as i64 / FLOOR).min(bw - 1);
        let by = ((xy.y / texel.y) as i64 / FLOOR).min(bh - 1);
        z < floors[(by * bw + bx) as usize]
    };
    (0..h)
        .into_par_iter()
        .flat_map_iter(|j| {
            let peaks = &peaks;
            if stop() {
                return Vec::new();
            }
            let row: Vec<f32> = (0..w)
                .map(move |i| {
                    // A texel's search can take seconds: checked per texel.
                    if stop() {
                        return MAX_RATIO;
                    }
                    let apex_xy = centre(i, j);
                    let apex = height.texel(i, j);
                    let mut best = MAX_RATIO;
                    if apex >= 1.0 {
                        return best;
                    }
                    // The exit point of a ray through (q, hq) lies past q and
                    // below hq, so a block's ratios are at least the distance to
                    // its nearest texel centre over its highest texel's rise
                    // (shrunk by a few ulps: the leaves measure between rounded
                    // centres).
                    let bound = |[gx, gy]: [i64; 2], hq: f32| {
                        if hq <= apex {
                            return f32::INFINITY;
                        }
                        let d = Vec2::new(gx as f32 * texel.x, gy as f32 * texel.y).length();
                        d / (hq - apex) * (1.0 - 1e-5)
                    };
                    peaks.search((i, j), &mut best, bound, |(ii, jj), best| {
                        let hq = height.texel(ii, jj);
                        if hq <= apex {
                            return;
                        }
                        let q = centre(ii, jj);
                        // The exit point lies past q and below hq: no ratio
                        // under this one.
                        if (q - apex_xy).length() >= *best * (hq - apex) {
                            return;
                        }
                        let exit = relaxed_exit(apex_xy, q, hq, march, aspect, |xy, z| {
                            !inside(xy, z) && z > surface(xy)
                        });
                        if let Some((xy, z)) = exit.filter(|&(_, z)| z > apex) {
                            *best = best.min((xy - apex_xy).length() / (z - apex));
                        }
                    });
                    best
                })
                .collect();
            row_done();
            row
        })
        .collect()
}

/// Where the relaxed cone's ray from `(apex_xy, 1)` through texel centre
/// `(q, hq)` first comes out above the surface past `q`, stepping `march`
/// across (per unit of horizontal travel it falls `fall`): the first step
/// at which `above(xy, z)` holds, or `None` when the ray leaves the face or
/// the shell's floor first.
fn relaxed_exit(
    apex_xy: Vec2,
    q: Vec2,
    hq: f32,
    march: f32,
    aspect: [f32; 2],
    mut above: impl FnMut(Vec2, f32) -> bool,
) -> Option<(Vec2, f32)> {
    let along = (q - apex_xy).normalize();
    let fall = (1.0 - hq) / (q - apex_xy).length();
    let mut s = march;
    loop {
        let xy = q + along * s;
        let z = hq - fall * s;
        if z <= 0.0 || xy.x < 0.0 || xy.y < 0.0 || xy.x > aspect[0] || xy.y > aspect[1] {
            return None;
        }
        if above(xy, z) {
            return Some((xy, z));
        }
        s += march;
    }
}

/// Maxima of per-texel values over aligned blocks of 2^k x 2^k texels, for
/// the branch and bound that finds a texel's cone: a block whose lower
/// bound (from its nearest texel and its largest value) cannot beat the
/// best ratio so far is skipped whole. The ring-by-ring scan this replaces
/// stopped only at a ring no texel could beat, which on smooth maps (wide
/// cones) meant the whole map for every texel: O(n^2) per texel. The result
/// is the same minimum over the same texels.
struct BlockMax {
    /// `(width, height, maxima)` per level, level 0 the texels.
    levels: Vec<(i64, i64, Vec<f32>)>,
}

impl BlockMax {
    fn new(values: Vec<f32>, w: i64, h: i64) -> Self {
        let mut levels = vec![(w, h, values)];
        while let Some(&(lw, lh, ref v)) = levels.last() {
            if lw == 1 && lh == 1 {
                break;
            }
            let (nw, nh) = ((lw + 1) / 2, (lh + 1) / 2);
            let at = |x: i64, y: i64| {
                if x < lw && y < lh {
                    v[(y * lw + x) as usize]
                } else {
                    f32::NEG_INFINITY
                }
            };
            let next = (0..nh)
                .flat_map(|y| (0..nw).map(move |x| (x, y)))
                .map(|(x, y)| {
                    at(2 * x, 2 * y)
                        .max(at(2 * x + 1, 2 * y))
                        .max(at(2 * x, 2 * y + 1))
                        .max(at(2 * x + 1, 2 * y + 1))
                })
                .collect();
            levels.push((nw, nh, next));
        }
        Self { levels }
    }

    /// Visits the texels of every block not ruled out for texel `from`,
    /// nearest blocks first: `bound([gx, gy], max)` is a lower bound of the
    /// ratio of any texel of a block whose nearest texel is `gx` columns and
    /// `gy` rows from `from` and whose largest value is `max`, and
    /// `leaf((i, j), best)` tries texel `(i, j)`.
    fn search(
        &self,
        from: (i64, i64),
        best: &mut f32,
        bound: impl Fn([i64; 2], f32) -> f32,
        mut leaf: impl FnMut((i64, i64), &mut f32),
    ) {
        let gap = |lo: i64, hi: i64, at: i64| (lo - at).max(at - hi).max(0);
        let node_bound = |level: usize, x: i64, y: i64| {
            let (lw, _, ref v) = self.levels[level];
            let size = 1i64 << level;
            let (w, h) = (self.levels[0].0, self.levels[0].1);
            let gx = gap(x * size, ((x + 1) * size).min(w) - 1, from.0);
            let gy = gap(y * size, ((y + 1) * size).min(h) - 1, from.1);
            bound([gx, gy], v[(y * lw + x) as usize])
        };
        // Depth-first; at most three siblings wait per level, so the stack
        // never holds more than 3 per level plus the root.
        let top = self.levels.len() - 1;
        let mut stack = vec![(0usize, 0i64, 0i64, 0.0f32); 3 * top + 2];
        stack[0] = (top, 0, 0, node_bound(top, 0, 0));
        let mut len = 1;
        while len > 0 {
            len -= 1;
            let (level, x, y, b) = stack[len];
            if b >= *best {
                continue;
            }
            if level == 0 {
                leaf((x, y), best);
                continue;
            }
            let (lw, lh, _) = self.levels[level - 1];
            let first = len;
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (cx, cy) = (2 * x + dx, 2 * y + dy);
                if cx < lw && cy < lh {
                    let cb = node_bound(level - 1, cx, cy);
                    if cb < *best {
                        // Insertion by decreasing bound: the nearest on top.
                        let mut k = len;
                        while k > first && stack[k - 1].3 < cb {
                            stack[k] = stack[k - 1];
                            k -= 1;
                        }
                        stack[k] = (level - 1, cx, cy, cb);
                        len += 1;
                    }
                }
            }
        }
    }
}

/// Cone stepping with `cones` for at most `budget` steps (two fetches each:
/// the height and the ratio). Conservative cones stop on the surface or
/// where the budget ends; relaxed cones finish with a binary search once a
/// step lands under the surface.
pub(crate) fn trace(seg: &Segment, cones: &ConeMap, budget: u32) -> Traced {
    let d = seg.ray.dir;
    let s_v = -d.z;
    let s_h = (d.x * d.x + d.y * d.y).sqrt();
    let mut t = seg.t_in;
    let mut fetches = 0;
    let mut above = None;
    for _ in 0..budget {
        if t > seg.t_out {
            return Traced { hit: None, fetches };
        }
        let probe = seg.probe(t);
        let c = cones.ratio_at(seg.at(t));
        fetches += 2;
        if probe.gap <= 0.0 {
            return match above {
                Some(above) if cones.kind == ConeKind::Relaxed => {
                    let b = Bracket {
                        above,
                        below: probe,
                        fetches,
                    };
                    let (t, fetches) = bisect(seg, b, BINARY_STEPS);
                    seg.hit_at(t, fetches)
                }
                _ => seg.hit_at(t, fetches),
            };
        }
        above = Some(probe);
        t += c * probe.gap / (c * s_v + s_h);
    }
    seg.hit_at(t, fetches)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The cone maps against the plain definitions, every texel against
    /// every other with no pruning and no skipped steps: the block search
    /// and the march's inside test must not change a single ratio.
    #[test]
    fn cone_maps_equal_their_unpruned_definitions() {
        for (name, address, [w, h], aspect) in [
            (
                "gaussian",
                crate::Address::Clamp,
                [13i64, 11i64],
                [3.0f32, 2.5f32],
            ),
            ("studded", crate::Address::Clamp, [13, 11], [3.0, 2.5]),
            ("noise", crate::Address::Repeat, [24, 20], [1.0, 0.8]),
            ("noise", crate::Address::Clamp, [20, 24], [0.5, 0.6]),
        ] {
            let height = crate::generators::generate(
                &format!("gen:{name}"),
                w as usize,
                h as usize,
                address,
            )
            .expect("generator");
            let texel = Vec2::new(aspect[0] / w as f32, aspect[1] / h as f32);
            let all = || (0..h).flat_map(move |jj| (0..w).map(move |ii| (ii, jj)));

            let got = ConeMap::build(&height, aspect, ConeKind::Conservative);
            let ranges = footprint_ranges(&height);
            let near = conservative_near_only(&height, texel);
            for (i, j) in all() {
                let lo = ranges[(j * w + i) as usize].0;
                let mut best = near[(j * w + i) as usize];
                for (ii, jj) in all() {
                    let (gx, gy) = ((ii - i).abs(), (jj - j).abs());
                    let hi = ranges[(jj * w + ii) as usize].1;
                    if gx.max(gy) >= 2 && hi > lo {
                        let dx = ((gx - 1) as f32 * texel.x).max(0.0);
                        let dy = ((gy - 1) as f32 * texel.y).max(0.0);
                        best = best.min((dx * dx + dy * dy).sqrt() / (hi - lo));
                    }
                }
                assert_eq!(
                    got.data()[(j * w + i) as usize],
                    best,
                    "{name} conservative ({i},{j})"
                );
            }

            let got = ConeMap::build(&height, aspect, ConeKind::Relaxed);
            let centre = |i: i64, j: i64| {
                Vec2::new(
                    texel_centre(i as usize, w as usize) * aspect[0],
                    texel_centre(j as usize, h as usize) * aspect[1],
                )
            };
            let march = 0.25 * texel.min_element();
            for (i, j) in all() {
                let (apex_xy, apex) = (centre(i, j), height.texel(i, j));
                let mut best = MAX_RATIO;
                for (ii, jj) in all() {
                    let hq = height.texel(ii, jj);
                    if hq <= apex {
                        continue;
                    }
                    let q = centre(ii, jj);
                    let exit = relaxed_exit(apex_xy, q, hq, march, aspect, |xy, z| {
                        z > height.sample(xy.x / aspect[0], xy.y / aspect[1])
                    });
                    if let Some((xy, z)) = exit.filter(|&(_, z)| z > apex) {
                        best = best.min((xy - apex_xy).length() / (z - apex));
                    }
                }
                assert_eq!(
                    got.data()[(j * w + i) as usize],
                    best,
                    "{name} relaxed ({i},{j})"
                );
            }
        }
    }

    /// The conservative ratios from the 3x3 block alone (the slope bound),
    /// as the bake computes them before searching farther texels.
    fn conservative_near_only(height: &HeightMap, texel: Vec2) -> Vec<f32> {
        let (w, h) = (height.width() as i64, height.height() as i64);
        let ranges = footprint_ranges(height);
        let slopes = cell_slopes(height, texel);
        (0..h)
            .flat_map(|j| (0..w).map(move |i| (i, j)))
            .map(|(i, j)| {
                let lo = ranges[(j * w + i) as usize].0;
                let mut rises = false;
                for jj in (j - 1).max(0)..=(j + 1).min(h - 1) {
                    for ii in (i - 1).max(0)..=(i + 1).min(w - 1) {
                        rises |= ranges[(jj * w + ii) as usize].1 > lo;
                    }
                }
                let mut slope = 0.0f32;
                if rises {
                    for k in (j - 1).max(0)..=(j + 2).min(h) {
                        for c in (i - 1).max(0)..=(i + 2).min(w) {
                            slope = slope.max(slopes[(k * (w + 1) + c) as usize]);
                        }
                    }
                }
                if slope > 0.0 {
                    MAX_RATIO.min(1.0 / slope)
                } else {
                    MAX_RATIO
                }
            })
            .collect()
    }

    #[test]
    fn progress_counts_every_row_once() {
        use std::sync::{Arc, Mutex};
        let height = crate::generators::generate("gen:gaussian", 12, 9, crate::Address::Clamp)
            .expect("generator");
        for kind in [ConeKind::Conservative, ConeKind::Relaxed] {
            let seen = Arc::new(Mutex::new(Vec::new()));
            let s = Arc::clone(&seen);
            let progress: Progress =
                Arc::new(move |done, total| s.lock().unwrap().push((done, total)));
            let cones = ConeMap::build_with(&height, [2.0, 1.5], kind, Some(&progress), None)
                .expect("not cancelled");
            let mut seen = seen.lock().unwrap().clone();
            seen.sort_unstable();
            assert_eq!(
                seen,
                (1..=9).map(|n| (n, 9)).collect::<Vec<_>>(),
                "{kind:?}"
            );
            assert_eq!(cones, ConeMap::build(&height, [2.0, 1.5], kind));
        }
    }

    /// Raised after the first row, the flag stops both kinds of bake within
    /// the rows in flight (no further row is started) and the bake ends in
    /// `Cancelled`, not in a map.
    #[test]
    fn a_raised_cancel_flag_stops_the_bake() {
        use std::sync::atomic::AtomicBool;
        use std::sync::Arc;
        let height = crate::generators::generate("gen:noise", 64, 64, crate::Address::Clamp)
            .expect("generator");
        for kind in [ConeKind::Conservative, ConeKind::Relaxed] {
            let cancel = Arc::new(AtomicBool::new(false));
            let rows = Arc::new(AtomicUsize::new(0));
            let (c, r) = (Arc::clone(&cancel), Arc::clone(&rows));
            let progress: Progress = Arc::new(move |_, _| {
                r.fetch_add(1, Ordering::SeqCst);
                c.store(true, Ordering::SeqCst);
            });
            let got =
                ConeMap::build_with(&height, [1.0, 1.0], kind, Some(&progress), Some(&cancel));
            assert!(matches!(got, Err(crate::Error::Cancelled)), "{kind:?}");
            let done = rows.load(Ordering::SeqCst);
            assert!(
                done <= 1 + rayon::current_num_threads(),
                "{kind:?}: {done} rows"
            );
        }
    }

    #[test]
    fn block_search_finds_the_brute_force_minimum() {
        // Random values; the ratio of texel q from p is its distance over
        // its value, as the cone bakes' bounds are shaped.
        let mut next = crate::random::xorshift_unit(11);
        for (w, h) in [(1i64, 1i64), (7, 5), (16, 16), (33, 9)] {
            let values: Vec<f32> = (0..w * h).map(|_| next()).collect();
            let peaks = BlockMax::new(values.clone(), w, h);
            let ratio = |gx: i64, gy: i64, v: f32| ((gx * gx + gy * gy) as f32).sqrt() / v;
            for (i, j) in [(0i64, 0i64), (w / 2, h / 2), (w - 1, h - 1)] {
                let mut best = 1e6f32;
                let mut visited = 0;
                peaks.search(
                    (i, j),
                    &mut best,
                    |[gx, gy], v| ratio(gx, gy, v),
                    |(ii, jj), best| {
                        visited += 1;
                        if (ii, jj) != (i, j) {
                            *best = best.min(ratio(ii - i, jj - j, values[(jj * w + ii) as usize]));
                        }
                    },
                );
                let want = (0..h)
                    .flat_map(|jj| (0..w).map(move |ii| (ii, jj)))
                    .filter(|&q| q != (i, j))
                    .map(|(ii, jj)| ratio(ii - i, jj - j, values[(jj * w + ii) as usize]))
                    .fold(1e6f32, f32::min);
                assert_eq!(best, want, "{w}x{h} from ({i}, {j})");
                assert!(visited <= w * h, "{visited} leaves of {}", w * h);
            }
        }
    }
}
