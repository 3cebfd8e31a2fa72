//! Maximum mipmaps / quadtree displacement (Tevs, Ihrke and Seidel 2008;
//! Drobot 2009).
//!
//! Level 0 holds, for every bilinear cell of the height map (the square
//! between four texel centres, with the half cells at the borders), the
//! maximum of the surface over it: the largest of its four corners, since a
//! bilinear patch takes its extremes there. Each coarser level keeps the
//! maximum of 2x2 nodes. The papers store a min-max pyramid for rays that
//! may come from below; a ray from above only ever needs the maximum.
//!
//! The walk is stackless: in the node under the current point, if the ray
//! leaves the node's column above the node's maximum (in map space the ray
//! goes down, so its lowest point there is where it leaves) it skips to the
//! column's exit and goes up a level; otherwise it moves down to the
//! node's maximum height and descends. At level 0 the one patch is solved
//! exactly ([`crate::exact::walk`]), so with enough budget the hit is exact.

use super::{Segment, Traced};
use crate::convention::floor_i64;
use crate::exact::{self, Walk};
use crate::HeightMap;
use rayon::prelude::*;

/// The max pyramid of one height map.
#[derive(Clone, Debug, PartialEq)]
pub struct MaxPyramid {
    /// `levels[l]` is `dims[l].0 x dims[l].1`, row-major; level 0 has one
    /// node per bilinear cell, `(W + 1) x (H + 1)`.
    levels: Vec<Vec<f32>>,
    dims: Vec<(usize, usize)>,
}

impl MaxPyramid {
    /// Builds every level, rows in parallel.
    pub fn build(height: &HeightMap) -> Self {
        let (w, h) = (height.width() + 1, height.height() + 1);
        let base: Vec<f32> = (0..h)
            .into_par_iter()
            .flat_map_iter(|k| {
                (0..w).map(move |i| {
                    let c = height.cell(i as i64 - 1, k as i64 - 1);
                    c.into_iter().fold(f32::NEG_INFINITY, f32::max)
                })
            })
            .collect();
        let (levels, dims) = max_levels(base, (w, h));
        Self { levels, dims }
    }

    /// Number of levels, from level 0 (one node per bilinear cell) to the
    /// coarsest.
    pub fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Bytes of all levels as float32.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.len() * 4).sum()
    }

    /// Maximum of node `(i, j)` at `level`.
    pub fn node(&self, level: usize, i: usize, j: usize) -> f32 {
        self.levels[level][j * self.dims[level].0 + i]
    }
}

/// The levels of a maximum pyramid above `base` (`dims.0 x dims.1`,
/// row-major), each node the largest of its 2 x 2 children (fewer at an odd
/// edge), up to a single node; `base` first. Rows in parallel. Shared by
/// [`MaxPyramid`] and the any-hit pyramid of
/// [`crate::cell_trace::AnyHitPyramid`], which differ only in their base.
pub(crate) fn max_levels(
    base: Vec<f32>,
    dims: (usize, usize),
) -> (Vec<Vec<f32>>, Vec<(usize, usize)>) {
    let mut levels = vec![base];
    let mut all = vec![dims];
    while all.last().is_some_and(|&(w, h)| w > 1 || h > 1) {
        let (pw, ph) = *all.last().expect("the base exists");
        let prev = levels.last().expect("the base exists");
        let (nw, nh) = (pw.div_ceil(2), ph.div_ceil(2));
        let next: Vec<f32> = (0..nh)
            .into_par_iter()
            .flat_map_iter(|j| {
                (0..nw).map(move |i| {
                    let mut m = f32::NEG_INFINITY;
                    for y in (2 * j)..(2 * j + 2).min(ph) {
                        for x in (2 * i)..(2 * i + 2).min(pw) {
                            m = m.max(prev[y * pw + x]);
                        }
                    }
                    m
                })
            })
            .collect();
        levels.push(next);
        all.push((nw, nh));
    }
    (levels, all)
}

/// Walks `pyramid` from where the ray enters until it finds the hit or has
/// spent `budget` fetches (node visits plus patches solved); out of budget,
/// the current point is the answer.
pub(crate) fn trace(seg: &Segment, pyramid: &MaxPyramid, budget: u32) -> Traced {
    let (w, h) = (seg.height.width(), seg.height.height());
    let [ax, ay] = seg.aspect;
    // Cell coordinates: s = x * sx - 0.5; cell c covers [c, c + 1], stored
    // at index c + 1.
    let (sx, sy) = (w as f32 / ax, h as f32 / ay);
    let d = seg.ray.dir;
    let top = pyramid.levels() - 1;
    let mut level = top;
    let mut t = seg.t_in;
    let mut fetches = 0u32;
    // Nudges a cell lookup into the cell the ray is heading for.
    let bias = |dc: f32| 1e-4 * dc.signum();
    while t <= seg.t_out {
        if fetches >= budget {
            return seg.hit_at(t, fetches);
        }
        let p = seg.at(t);
        let kx = (floor_i64(p.x * sx - 0.5 + bias(d.x)) + 1).clamp(0, w as i64) as usize;
        let ky = (floor_i64(p.y * sy - 0.5 + bias(d.y)) + 1).clamp(0, h as i64) as usize;
        let (i, j) = (kx >> level, ky >> level);
        let m = pyramid.node(level, i, j);
        fetches += 1;
        // The node's column in map space, clipped to the face.
        let span = 1usize << level;
        let x0 = (((i * span) as f32 - 0.5) / sx).max(0.0);
        let x1 = ((((i + 1) * span) as f32 - 0.5) / sx).min(ax);
        let y0 = (((j * span) as f32 - 0.5) / sy).max(0.0);
        let y1 = ((((j + 1) * span) as f32 - 0.5) / sy).min(ay);
        let exit_x = axis_exit(seg.ray.origin.x, d.x, x0, x1);
        let exit_y = axis_exit(seg.ray.origin.y, d.y, y0, y1);
        let t_exit = exit_x.min(exit_y).min(seg.t_out).max(t);
        // The margin keeps a ray that ends on a node's top (the floor of a
        // zero-height region, say) from skipping it by a rounding error;
        // descending costs a fetch, never correctness.
        if seg.at(t_exit).z > m + 1e-5 {
            t = t_exit.max(next_after(t));
            level = (level + 1).min(top);
            continue;
        }
        // Down to the node's top: nothing above it can be hit.
        t = t.max(seg.t_at_depth(1.0 - m)).min(t_exit);
        if level > 0 {
            level -= 1;
            continue;
        }
        match exact::walk(seg.height, seg.aspect, seg.ray.origin, d, t, t_exit) {
            Walk::Hit(hit) => return seg.hit_at(hit.t as f32, fetches + hit.cells),
            Walk::StartsInside { cells } => return seg.hit_at(t, fetches + cells),
            Walk::Miss { cells } => {
                fetches += cells;
                t = t_exit.max(next_after(t));
                level = (level + 1).min(top);
            }
        }
    }
    Traced { hit: None, fetches }
}

/// Ray parameter where `o + t d` leaves `[lo, hi]` along one axis.
fn axis_exit(o: f32, d: f32, lo: f32, hi: f32) -> f32 {
    if d > 0.0 {
        (hi - o) / d
    } else if d < 0.0 {
        (lo - o) / d
    } else {
        f32::INFINITY
    }
}

/// The next float after `t`, so that a walk stuck on a boundary moves on.
fn next_after(t: f32) -> f32 {
    f32::from_bits(t.to_bits() + 1).max(t + 1e-7)
}
