//! The exact reference intersector: the ray against each bilinear patch of
//! the height map, solved in closed form, walking the patches the ray crosses
//! with a 2D DDA. It is the ground truth that tests and benchmarks compare
//! the sphere tracer against, and the sphere tracer's refinement step
//! ([`crate::sphere_trace`]: after Donnelly's march, section 8.5.2, has
//! brought the ray to a thin band above the surface) over the short segment
//! where the distance map can no longer tell the ray from the surface.

use crate::HeightMap;
use glam::{DVec3, Vec3};

/// A hit found on the bilinear surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    /// Ray parameter of the hit, in double precision as the patch is solved.
    pub t: f64,
    /// Geometric normal of the bilinear patch, map space, unit length.
    pub normal: Vec3,
    /// Patches visited (the cost of the walk).
    pub cells: u32,
}

/// Outcome of walking a segment.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Walk {
    /// The first surface point on the segment.
    Hit(SurfaceHit),
    /// The ray was already under the surface at the segment's start.
    StartsInside {
        /// Patches visited: 0, since the start is tested before the walk.
        cells: u32,
    },
    /// The segment stays above the surface.
    Miss {
        /// Patches visited.
        cells: u32,
    },
}

/// First point of `o + t d`, `t` in `[t0, t1]`, on the surface
/// `z = h(x / aspect.x, y / aspect.y)` (map space, depth units).
pub fn walk(height: &HeightMap, aspect: [f32; 2], o: Vec3, d: Vec3, t0: f32, t1: f32) -> Walk {
    let o = o.as_dvec3();
    let d = d.as_dvec3();
    let (w, h) = (height.width() as f64, height.height() as f64);
    // Cell coordinates: s = u * n - 0.5, so texel centres sit at integers
    // and cell c spans [c, c + 1].
    let sx = w / aspect[0] as f64;
    let sy = h / aspect[1] as f64;
    let cx = |t: f64| (o.x + d.x * t) * sx - 0.5;
    let cy = |t: f64| (o.y + d.y * t) * sy - 0.5;
    let (t0, t1) = (t0 as f64, t1 as f64);
    if t1 < t0 {
        return Walk::Miss { cells: 0 };
    }
    let p0 = o + d * t0;
    if p0.z
        < height.sample(
            (p0.x / aspect[0] as f64) as f32,
            (p0.y / aspect[1] as f64) as f32,
        ) as f64
            - 1e-7
    {
        return Walk::StartsInside { cells: 0 };
    }
    let mut ci = floor_f64(cx(t0));
    let mut cj = floor_f64(cy(t0));
    let dsx = d.x * sx;
    let dsy = d.y * sy;
    let step_i: i64 = if dsx > 0.0 { 1 } else { -1 };
    let step_j: i64 = if dsy > 0.0 { 1 } else { -1 };
    let next_boundary = |c: i64, ds: f64, at: &dyn Fn(f64) -> f64| -> f64 {
        if ds == 0.0 {
            return f64::INFINITY;
        }
        let b = if ds > 0.0 { (c + 1) as f64 } else { c as f64 };
        t0 + (b - at(t0)) / ds
    };
    let mut tx = next_boundary(ci, dsx, &cx);
    let mut ty = next_boundary(cj, dsy, &cy);
    let dtx = if dsx == 0.0 {
        f64::INFINITY
    } else {
        1.0 / dsx.abs()
    };
    let dty = if dsy == 0.0 {
        f64::INFINITY
    } else {
        1.0 / dsy.abs()
    };
    let mut ta = t0;
    let mut cells = 0u32;
    loop {
        let tb = tx.min(ty).min(t1);
        cells += 1;
        let corners = height.cell(ci, cj);
        if let Some((t, n)) = patch_hit(corners, ci, cj, o, d, sx, sy, ta, tb) {
            return Walk::Hit(SurfaceHit {
                t,
                normal: n,
                cells,
            });
        }
        if tb >= t1 {
            return Walk::Miss { cells };
        }
        ta = tb;
        if tx < ty {
            ci += step_i;
            tx += dtx;
        } else {
            cj += step_j;
            ty += dty;
        }
    }
}

/// `floor` without a libm call (see [`crate::convention::floor_i64`]).
#[inline]
pub(crate) fn floor_f64(x: f64) -> i64 {
    let i = x as i64;
    if (i as f64) > x {
        i - 1
    } else {
        i
    }
}

/// First root of `z(t) - h(x(t), y(t))` in `[ta, tb]` on bilinear cell
/// `(ci, cj)` whose corner heights are `corners` (`h00, h10, h01, h11`, as
/// [`HeightMap::cell`] gives them): a quadratic in `t`, solved relative to
/// `ta` in double precision. Shared by this reference walk and the
/// throughput tracer's ([`crate::cell_trace`]), so both solve every patch
/// alike.
#[allow(clippy::too_many_arguments)]
pub(crate) fn patch_hit(
    corners: [f32; 4],
    ci: i64,
    cj: i64,
    o: DVec3,
    d: DVec3,
    sx: f64,
    sy: f64,
    ta: f64,
    tb: f64,
) -> Option<(f64, Vec3)> {
    let [h00, h10, h01, h11] = corners.map(|v| v as f64);
    let a = h10 - h00;
    let b = h01 - h00;
    let c = h00 - h10 - h01 + h11;
    let p = o + d * ta;
    let px = p.x * sx - 0.5 - ci as f64;
    let py = p.y * sy - 0.5 - cj as f64;
    let qx = d.x * sx;
    let qy = d.y * sy;
    // f(s) = k0 + k1 s + k2 s^2, s = t - ta.
    let k0 = over_patch([h00, h10, h01, h11], px, py, p.z);
    let k1 = d.z - a * qx - b * qy - c * (px * qy + qx * py);
    let k2 = -c * qx * qy;
    let len = tb - ta;
    // Segment ends come from single-precision ray parameters (the shell's
    // exit, a band's end): a root a few f32 ulps past the end is this
    // segment's, or a hit exactly on the shell's floor is lost.
    let eps = 1e-6 * (1.0 + tb.abs());
    let root = smallest_root(k0, k1, k2, -eps, len + eps)?;
    let s = root.clamp(0.0, len);
    let fx = (px + qx * s).clamp(0.0, 1.0);
    let fy = (py + qy * s).clamp(0.0, 1.0);
    let dhdx = (a + c * fy) * sx;
    let dhdy = (b + c * fx) * sy;
    // The root needs double precision; its normal, returned in single, is
    // normalised in single (a double square root and division cost more
    // than the rest of a hit's solve).
    let n = Vec3::new(-dhdx as f32, -dhdy as f32, 1.0).normalize();
    Some((ta + s, n))
}

/// How far height `z` stands over the bilinear patch with corners `h00,
/// h10, h01, h11` at `(px, py)` in the cell's own coordinates (`[0, 1]`
/// across it): the constant term of [`patch_hit`]'s quadratic, in the
/// precision and order the solve has it, so that a caller asking whether a
/// point is over the surface gets the solve's own answer.
#[inline(always)]
pub(crate) fn over_patch([h00, h10, h01, h11]: [f64; 4], px: f64, py: f64, z: f64) -> f64 {
    let (a, b, c) = (h10 - h00, h01 - h00, h00 - h10 - h01 + h11);
    z - h00 - a * px - b * py - c * px * py
}

/// Smallest root of `k0 + k1 s + k2 s^2` in `[lo, hi]`, where the function
/// goes from non-negative to non-positive (a ray entering the surface from
/// above, or touching it).
fn smallest_root(k0: f64, k1: f64, k2: f64, lo: f64, hi: f64) -> Option<f64> {
    if k0 <= 0.0 {
        return Some(0.0f64.max(lo));
    }
    // Non-decreasing from s = 0 on and still positive at `lo`: no root (the
    // common case of a ray rising away from a patch, decided without the
    // square root).
    if k1 >= 0.0 && k2 >= 0.0 && k0 > k1 * (-lo).max(0.0) {
        return None;
    }
    // Positive at both ends of the interval and nowhere below zero between
    // them: a concave quadratic (k2 <= 0) has its minimum at an end, a
    // convex one either at an end or at its vertex, where it is negative
    // only with a positive discriminant. Decided without the square root
    // or a division: the common case of a ray passing just over a patch.
    let f = |x: f64| k0 + x * (k1 + x * k2);
    if f(hi) > 0.0 && f(lo) > 0.0 {
        // Vertex -k1 / (2 k2) inside [lo, hi], for k2 > 0.
        let inside = k2 > 0.0 && -k1 > 2.0 * k2 * lo && -k1 < 2.0 * k2 * hi;
        if !inside || k1 * k1 - 4.0 * k2 * k0 < 0.0 {
            return None;
        }
    }
    let scale = k0.abs().max(k1.abs()).max(k2.abs());
    if k2.abs() <= 1e-12 * scale {
        if k1 >= 0.0 {
            return None;
        }
        let s = -k0 / k1;
        return (s >= lo && s <= hi).then_some(s);
    }
    let disc = k1 * k1 - 4.0 * k2 * k0;
    if disc < 0.0 {
        return None;
    }
    // Numerically stable pair (Numerical Recipes 5.6).
    let q = -0.5 * (k1 + k1.signum() * disc.sqrt());
    let r1 = q / k2;
    let r2 = if q != 0.0 { k0 / q } else { r1 };
    let (r1, r2) = if r1 < r2 { (r1, r2) } else { (r2, r1) };
    [r1, r2].into_iter().find(|&s| s >= lo && s <= hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Address;

    #[test]
    fn roots_in_order() {
        // (s - 1)(s - 2) = 2 - 3s + s^2
        assert_eq!(smallest_root(2.0, -3.0, 1.0, 0.0, 5.0), Some(1.0));
        assert!((smallest_root(2.0, -3.0, 1.0, 1.5, 5.0).unwrap() - 2.0).abs() < 1e-12);
        assert_eq!(smallest_root(2.0, -3.0, 1.0, 2.5, 5.0), None);
        assert_eq!(smallest_root(1.0, 0.0, 1.0, 0.0, 5.0), None);
        assert_eq!(smallest_root(1.0, -1.0, 0.0, 0.0, 5.0), Some(1.0));
    }

    #[test]
    fn vertical_ray_lands_on_the_bilinear_surface() {
        let m = HeightMap::new(
            4,
            4,
            (0..16).map(|k| (k % 5) as f32 / 4.0).collect(),
            Address::Clamp,
        )
        .unwrap();
        let aspect = [2.0, 3.0];
        for &(x, y) in &[(0.3f32, 0.4f32), (1.0, 1.5), (1.9, 2.9), (0.01, 0.01)] {
            let o = Vec3::new(x, y, 1.5);
            match walk(&m, aspect, o, Vec3::new(0.0, 0.0, -1.0), 0.0, 2.0) {
                Walk::Hit(h) => {
                    let want = 1.5 - m.sample(x / aspect[0], y / aspect[1]) as f64;
                    assert!((h.t - want).abs() < 1e-5, "{} vs {want}", h.t);
                }
                other => panic!("{other:?}"),
            }
        }
    }
}
