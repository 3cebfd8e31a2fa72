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
use crate::techniques::MaxPyramid;
use crate::{DistanceMap, HeightMap};

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

/// [`super::occluded`] answered over `pyramid` (built from `height` by
/// [`MaxPyramid::build`]): the same answer but for rays that touch the
/// surface within rounding (see the module's notes). Maps traced with
/// repeating tiles, methods other than [`Method::Sphere`] and a pyramid of
/// another map's size take the distance-map tracer.
pub fn occluded_over(
    height: &HeightMap,
    distance: &DistanceMap,
    pyramid: &MaxPyramid,
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
    blocked(height, pyramid, &lane.grid, &c, ray, lane.t, lane.t_out)
        || leaves_through_floor(ray, lane.t_out)
}

/// Whether the exact walk finds the ray under the surface anywhere on
/// `[t_in, t_out]`, walking only the leaves whose maximum the ray comes
/// down to, nearest first.
fn blocked(
    height: &HeightMap,
    pyramid: &MaxPyramid,
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
    let top = pyramid.levels() - 1;
    let mut stack = [(0u8, 0u32, 0u32); STACK];
    stack[0] = (top as u8, 0, 0);
    let mut len = 1;
    while len > 0 {
        len -= 1;
        let (level, i, j) = stack[len];
        let level = level as usize;
        let mut lo = t_in;
        let mut hi = t_out;
        for ((oc, dc), k) in axes.iter().zip([i, j]) {
            let s0 = ((k as u64) << level) as f64 - 1.0 - WIDEN;
            let s1 = (((k as u64) + 1) << level) as f64 - 1.0 + WIDEN;
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
        if z_low > pyramid.node(level, i as usize, j as usize) as f64 + margin {
            continue;
        }
        if level <= LEAF_LEVEL {
            if let Walk::Hit(_) = walk::<true>(height, grid, c.cells, lo as f32, hi as f32) {
                return true;
            }
            continue;
        }
        let (w, h) = pyramid.dims(level - 1);
        // Pushed farthest first, so the nearest is split next.
        for (bx, by) in [(1, 1), (1, 0), (0, 1), (0, 0)] {
            let ci = 2 * i as usize + (near[0] ^ bx);
            let cj = 2 * j as usize + (near[1] ^ by);
            if ci < w && cj < h {
                stack[len] = ((level - 1) as u8, ci as u32, cj as u32);
                len += 1;
            }
        }
    }
    false
}
