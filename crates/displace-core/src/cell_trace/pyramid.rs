//! Any-hit queries over a maximum-height pyramid: the shadow-ray and
//! line-of-sight query for rays that graze the surface.
//!
//! The distance map's steps are bounded by the ray's clearance above the
//! surface, so a ray that runs low over it for a long way (a line of sight
//! across an elevation model, a shadow ray from a low sun) takes short
//! steps the whole way and walks many bands: hundreds of iterations a ray.
//! A maximum mipmap (Tevs, Ihrke and Seidel, "Maximum Mipmaps for Fast,
//! Accurate, and Scalable Dynamic Height Field Rendering", I3D 2008) skips a
//! whole node wherever the ray's lowest point over the node's column lies
//! above the node's maximum, whichever way the ray climbs, so the cost
//! follows how often the ray comes near the surface, not how long it runs
//! near it.
//!
//! Before the walk, a few points spread along the ray are tested against
//! the surface ([`probed_under`]): a point under it proves the ray blocked
//! (it entered above), and a line of sight across terrain is mostly blocked
//! by some ridge far from both its ends, which the front-to-back walk
//! reaches last. Only rays that no probe proves blocked are walked.
//!
//! The answer is the distance-map tracer's ([`super::occluded`]): both
//! come down to the same exact walk of the cells ([`super::walk`]). The
//! walk over the whole clipped ray is itself exact; the distance map's
//! steps and the pyramid's skips each leave out only stretches the walk
//! would pass without a solve (a step never crosses the surface; a skipped
//! node's cells all lie below the ray by more than the walk's margin). The
//! ends are the tracer's too: the clip and the entry test of
//! [`Lane::begin`], and the floor exit of [`Lane::floor_exit`]. What may
//! differ is a ray that touches the surface within rounding (a ridge
//! grazed to a ten-millionth): where a walk starts decides how its cell
//! boundaries round, and so whether the touch counts, for the distance
//! map's bands and the pyramid's leaves alike.

use super::{walk, Constants, Grid, Lane, Outcome};
use crate::exact::Walk;
use crate::sphere_trace::{leaves_through_floor, MapRay, Method, TraceOptions};
use crate::{DistanceMap, HeightMap};
use rayon::prelude::*;

/// The level whose nodes are walked cell by cell instead of split: 8 x 8
/// cells. The walk passes a cell the ray clears for about what a node
/// costs, so splitting further pays less than it costs (measured on an
/// elevation model's lines of sight and the studded face's random
/// stretches, one thread: leaves of 2, 4, 8, 16 and 32 cells a side gave
/// 0.16, 0.24, 0.28, 0.27 and 0.24 Mrays/s on the first, 1.43, 1.54, 1.68,
/// 1.77 and 1.73 on the second).
const LEAF_LEVEL: usize = 3;

/// Most nodes pending at once: three siblings a level and the one being
/// split, for a pyramid of up to 31 levels (maps past a billion texels a
/// side are refused long before).
const STACK: usize = 96;

/// The maximum of the height surface over blocks of cells, and of blocks
/// of blocks up to the whole map: a maximum mipmap (Tevs, Ihrke and
/// Seidel 2008) whose finest level is the walk's leaf, blocks of 8 x 8
/// bilinear cells, since the levels below it would never be read. So it
/// costs a sixty-fourth of a full pyramid: about a twelfth of a byte a
/// texel.
#[derive(Clone, Debug, PartialEq)]
pub struct AnyHitPyramid {
    /// `levels[k]` is `dims[k].0 x dims[k].1`, row-major; level `k` holds
    /// blocks of `2^(k + LEAF_LEVEL)` cells a side.
    levels: Vec<Vec<f32>>,
    dims: Vec<(usize, usize)>,
    /// Bilinear cells across and down of the map it was built from,
    /// borders included (`W + 1`, `H + 1`).
    cells: (usize, usize),
}

impl AnyHitPyramid {
    /// Builds every level from `height`'s cells (with its address mode at
    /// the borders), rows of blocks in parallel.
    pub fn build(height: &HeightMap) -> Self {
        let cells = (height.width() + 1, height.height() + 1);
        let side = 1usize << LEAF_LEVEL;
        let (w, h) = (cells.0.div_ceil(side), cells.1.div_ceil(side));
        // Cell `c` of the walk's grid is stored at index `c + 1` (the half
        // cells at the borders are `-1` and `W - 1`).
        let leaf: Vec<f32> = (0..h)
            .into_par_iter()
            .flat_map_iter(|j| {
                (0..w).map(move |i| {
                    let mut m = f32::NEG_INFINITY;
                    for k in j * side..((j + 1) * side).min(cells.1) {
                        for l in i * side..((i + 1) * side).min(cells.0) {
                            let c = height.cell(l as i64 - 1, k as i64 - 1);
                            m = c.into_iter().fold(m, f32::max);
                        }
                    }
                    m
                })
            })
            .collect();
        let (levels, dims) = crate::techniques::max_levels(leaf, (w, h));
        Self {
            levels,
            dims,
            cells,
        }
    }

    /// Bytes a pyramid of a `width x height` map holds, at most: for a
    /// memory check before [`AnyHitPyramid::build`].
    pub fn bytes_for(width: usize, height: usize) -> u128 {
        let side = 1u128 << LEAF_LEVEL;
        let leaf = (width as u128 + 1).div_ceil(side) * (height as u128 + 1).div_ceil(side);
        // Each level a quarter of the one below, rounded up: under 4/3
        // of the leaf level, plus a node a level for the rounding.
        (leaf * 4 / 3 + 64) * 4
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.levels.iter().map(|l| l.len() * 4).sum()
    }

    /// Whether this pyramid was built from a map of `height`'s size.
    pub fn fits(&self, height: &HeightMap) -> bool {
        self.cells == (height.width() + 1, height.height() + 1)
    }

    /// Levels, counted from the leaves.
    fn levels(&self) -> usize {
        self.levels.len()
    }

    /// Maximum of block `(i, j)` of level `k` (from the leaves).
    fn node(&self, k: usize, i: usize, j: usize) -> f32 {
        self.levels[k][j * self.dims[k].0 + i]
    }
}

/// [`super::occluded`] answered over `pyramid` (built from `height` by
/// [`AnyHitPyramid::build`]): the same answer but for rays that touch the
/// surface within rounding (see the module's notes). Maps traced with
/// repeating tiles, methods other than [`Method::Sphere`] and a pyramid of
/// another map's size take the distance-map tracer.
pub fn occluded_over(
    height: &HeightMap,
    distance: &DistanceMap,
    pyramid: &AnyHitPyramid,
    ray: &MapRay,
    opts: &TraceOptions,
) -> bool {
    if opts.method != Method::Sphere
        || opts.tiles != [1.0, 1.0]
        || !pyramid.fits(height)
        || pyramid.levels() > (STACK - 1) / 3
    {
        return super::occluded(height, distance, ray, opts);
    }
    let c = Constants::new(height, distance);
    let lane = match Lane::begin(height, &c, ray, opts, true) {
        Ok(lane) => lane,
        Err(out) => return !matches!(out, Outcome::Miss),
    };
    // The distance-map loop's `while t <= t_out` (a NaN ends it too).
    if lane.t.partial_cmp(&lane.t_out).is_none_or(|o| o.is_gt()) {
        return false;
    }
    (crossed_cells(&c, ray, lane.t, lane.t_out) >= PROBE_MIN_CELLS
        && probed_under(height, c.aspect, ray, lane.t, lane.t_out))
        || blocked(height, pyramid, &lane.grid, &c, ray, lane.t, lane.t_out)
        || leaves_through_floor(ray, lane.t_out)
}

/// Fractions of the clipped ray, in sixteenths, where [`probed_under`]
/// looks: the middle first, then the quarters, the eighths and the
/// sixteenths (bit-reversed order), so that a blocker anywhere on the ray
/// is met after few probes whatever its place, and a wide one after one.
const PROBES: [u8; 15] = [8, 4, 12, 2, 6, 10, 14, 1, 3, 5, 7, 9, 11, 13, 15];

/// Fewest height cells a ray must cross for [`probed_under`] to look: a
/// shorter one (a shadow ray from the surface towards a light above,
/// which leaves the shell within a few cells) is walked at once for less
/// than its fifteen probes cost, and mostly reaches its light, so the
/// probes would be paid for nothing (measured on the render benchmark's
/// shadow rays of the studded face through `DistanceMap.occluded`: 4-8%
/// slower with them).
const PROBE_MIN_CELLS: f64 = 16.0;

/// Height cells the ray crosses over `[t_in, t_out]` (across plus down,
/// an upper bound of the walk's count).
fn crossed_cells(c: &Constants, ray: &MapRay, t_in: f32, t_out: f32) -> f64 {
    let span = t_out as f64 - t_in as f64;
    span * (ray.dir.x.abs() as f64 * c.cells[0] + ray.dir.y.abs() as f64 * c.cells[1])
}

/// How far under the surface (map units of depth) a probe must find the
/// ray: far above the rounding of the ray's point and of the bilinear
/// sample (single precision, a few ten-millionths), so that the exact walk
/// surely finds the root that the probe proves.
const PROBE_MARGIN: f64 = 1e-4;

/// Whether one of a few points spread over `[t_in, t_out]` lies under the
/// surface: then the ray, above the surface where it enters (the tracer's
/// entry test), crosses it before that point, and the exact walk would
/// find that root. A line of sight over an elevation model is mostly
/// blocked by a ridge far from both ends, which the pyramid reaches only
/// after walking every leaf the ray comes near before it; a probe finds
/// most such ridges at once. The answer is [`blocked`]'s: a probe proves
/// only what the walk finds (the margin is far above both's rounding);
/// rays that no probe proves blocked are walked as before.
fn probed_under(height: &HeightMap, aspect: [f32; 2], ray: &MapRay, t_in: f32, t_out: f32) -> bool {
    let (o, d) = (ray.origin.as_dvec3(), ray.dir.as_dvec3());
    let (t_in, span) = (t_in as f64, t_out as f64 - t_in as f64);
    let [ax, ay] = aspect.map(f64::from);
    PROBES.iter().any(|&k| {
        let p = o + d * (t_in + span * (k as f64 / 16.0));
        let h = height.sample((p.x / ax) as f32, (p.y / ay) as f32) as f64;
        p.z < h - PROBE_MARGIN
    })
}

/// Whether the exact walk finds the ray under the surface anywhere on
/// `[t_in, t_out]`, walking only the leaves whose maximum the ray comes
/// down to, nearest first.
fn blocked(
    height: &HeightMap,
    pyramid: &AnyHitPyramid,
    grid: &Grid,
    c: &Constants,
    ray: &MapRay,
    t_in: f32,
    t_out: f32,
) -> bool {
    let [sx, sy] = c.cells;
    // Cell coordinates along the ray, as the walk's grid has them: texel
    // centres at integers, cell `k` spanning `[k, k + 1]`, stored at
    // level-0 index `k + 1`.
    let o = ray.origin.as_dvec3();
    let d = ray.dir.as_dvec3();
    let axes = [(o.x * sx - 0.5, d.x * sx), (o.y * sy - 0.5, d.y * sy)];
    let (t_in, t_out) = (t_in as f64, t_out as f64);
    // A node's column widened by this much (cells) and its maximum raised
    // by the walk's own margin: a node is skipped only where the walk
    // would solve none of its cells.
    const WIDEN: f64 = 1e-3;
    let margin = 1e-4 * (1.0 + t_out.abs());
    // Front to back: the child nearest the ray's start first.
    let near = [usize::from(d.x < 0.0), usize::from(d.y < 0.0)];
    // Levels counted from the leaves (`k`); a block of level `k` spans
    // `2^(k + LEAF_LEVEL)` cells a side.
    let top = pyramid.levels() - 1;
    let mut stack = [(0u8, 0u32, 0u32); STACK];
    stack[0] = (top as u8, 0, 0);
    let mut len = 1;
    while len > 0 {
        len -= 1;
        let (k, i, j) = stack[len];
        let k = k as usize;
        let level = k + LEAF_LEVEL;
        let mut lo = t_in;
        let mut hi = t_out;
        for ((oc, dc), n) in axes.iter().zip([i, j]) {
            let s0 = ((n as u64) << level) as f64 - 1.0 - WIDEN;
            let s1 = (((n as u64) + 1) << level) as f64 - 1.0 + WIDEN;
            if *dc == 0.0 {
                if *oc < s0 || *oc > s1 {
                    hi = f64::NEG_INFINITY;
                }
            } else {
                let (a, b) = ((s0 - oc) / dc, (s1 - oc) / dc);
                lo = lo.max(a.min(b));
                hi = hi.min(a.max(b));
            }
        }
        if lo > hi {
            continue;
        }
        let z_low = o.z + d.z * if d.z < 0.0 { hi } else { lo };
        if z_low > pyramid.node(k, i as usize, j as usize) as f64 + margin {
            continue;
        }
        if k == 0 {
            if let Walk::Hit(_) = walk::<true>(height, grid, c.cells, lo as f32, hi as f32) {
                return true;
            }
            continue;
        }
        let (w, h) = pyramid.dims[k - 1];
        // Pushed farthest first, so the nearest is split next.
        for (bx, by) in [(1, 1), (1, 0), (0, 1), (0, 0)] {
            let ci = 2 * i as usize + (near[0] ^ bx);
            let cj = 2 * j as usize + (near[1] ^ by);
            if ci < w && cj < h {
                stack[len] = ((k - 1) as u8, ci as u32, cj as u32);
                len += 1;
            }
        }
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::SplitMix64;
    use crate::Address;

    /// A probe proves only what the exact walk finds: on random maps and
    /// lines of sight between two points just over the surface, every ray
    /// a probe calls blocked is blocked to the exact reference walk, and
    /// the probes do prove most of the blocked ones (the test is not of
    /// rays no probe proves).
    #[test]
    fn a_probe_under_the_surface_is_a_blocker_the_exact_walk_finds() {
        let mut rng = SplitMix64::new(20261207);
        let (mut proven, mut blocked) = (0, 0);
        for case in 0..40 {
            let (w, h) = (8 + case * 3, 5 + case * 2);
            // Rough maps (a random value a texel) and smooth ones (rolling
            // hills), in turn.
            let rough = case % 2 == 0;
            let data = (0..w * h)
                .map(|k| {
                    if rough {
                        0.8 * rng.next_f32() + 0.1
                    } else {
                        let (x, y) = ((k % w) as f32, (k / w) as f32);
                        0.5 + 0.4 * (0.7 * x).sin() * (0.5 * y).cos()
                    }
                })
                .collect();
            let height = HeightMap::new(w, h, data, Address::Clamp).unwrap();
            let aspect = [w as f32 / h as f32, 1.0];
            let surface = |x: f32, y: f32| height.sample(x / aspect[0], y / aspect[1]);
            for _ in 0..500 {
                let mut point = || {
                    let (x, y) = (rng.next_f32() * aspect[0], rng.next_f32() * aspect[1]);
                    let lift = 1e-3 + 0.05 * rng.next_f32();
                    glam::Vec3::new(x, y, surface(x, y) + lift)
                };
                let (p, q) = (point(), point());
                let length = (q - p).length();
                if length < 1e-3 {
                    continue;
                }
                let ray = MapRay::new(p, (q - p) / length);
                let exact = crate::exact::walk(&height, aspect, ray.origin, ray.dir, 0.0, length);
                let under = !matches!(exact, Walk::Miss { .. });
                let probed = probed_under(&height, aspect, &ray, 0.0, length);
                assert!(
                    !probed || under,
                    "probed blocked, exact {exact:?}: {ray:?} to {length}"
                );
                blocked += usize::from(under);
                proven += usize::from(probed);
            }
        }
        assert!(blocked > 2000, "{blocked} blocked rays");
        assert!(
            2 * proven > blocked,
            "probes proved {proven} of {blocked} blocked rays"
        );
    }

    /// Every block holds exactly the largest corner of its cells (its
    /// address mode at the borders), each level the largest of its four
    /// children, and the memory check's estimate bounds what is held.
    #[test]
    fn blocks_hold_the_largest_corner_of_their_cells() {
        let mut rng = SplitMix64::new(0x5eed);
        for (w, h, address) in [
            (37, 23, Address::Clamp),
            (64, 9, Address::Repeat),
            (2, 2, Address::Clamp),
        ] {
            let data = (0..w * h).map(|_| rng.next_f32()).collect();
            let height = HeightMap::new(w, h, data, address).unwrap();
            let p = AnyHitPyramid::build(&height);
            assert!(p.fits(&height));
            assert!(p.bytes() as u128 <= AnyHitPyramid::bytes_for(w, h));
            let side = 1usize << LEAF_LEVEL;
            let (lw, lh) = p.dims[0];
            for j in 0..lh {
                for i in 0..lw {
                    let mut m = f32::NEG_INFINITY;
                    for cj in (j * side) as i64 - 1..(((j + 1) * side).min(h + 1)) as i64 - 1 {
                        for ci in (i * side) as i64 - 1..(((i + 1) * side).min(w + 1)) as i64 - 1 {
                            m = height.cell(ci, cj).into_iter().fold(m, f32::max);
                        }
                    }
                    assert_eq!(p.node(0, i, j), m, "block ({i}, {j}) of {w}x{h}");
                }
            }
            for k in 1..p.levels() {
                let (pw, ph) = p.dims[k - 1];
                for j in 0..p.dims[k].1 {
                    for i in 0..p.dims[k].0 {
                        let mut m = f32::NEG_INFINITY;
                        for y in 2 * j..(2 * j + 2).min(ph) {
                            for x in 2 * i..(2 * i + 2).min(pw) {
                                m = m.max(p.node(k - 1, x, y));
                            }
                        }
                        assert_eq!(p.node(k, i, j), m);
                    }
                }
            }
            assert_eq!(p.dims[p.levels() - 1], (1, 1));
        }
    }
}
