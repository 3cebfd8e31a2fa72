//! Sphere tracing built for a CPU's throughput: the same exact hit as
//! [`crate::sphere_trace`]'s early-out method, found with fewer and cheaper
//! memory accesses.
//!
//! A GPU samples the distance map through its texture unit, where a
//! trilinear fetch costs what a point fetch does, so the GPU tracer (and the
//! CPU tracer that mirrors it for `displace compare`) interpolates eight
//! voxels per step as Donnelly's listing 8-2 does (GPU Gems 2 ch. 8, section
//! 8.3). A CPU pays for each of the eight loads and their addressing. Here:
//!
//! - **Steps from one voxel.** Every stored value bounds the distance over
//!   its whole voxel ([`DistanceMap::cell_bound`]), so a step reads the one
//!   voxel that contains the ray's point.
//! - **Culled patches.** Where the stored distance can no longer tell the
//!   ray from the surface, the exact walk ([`crate::exact`]) solves only the
//!   cells whose highest corner the ray comes down to; the rest cost a
//!   comparison.
//! - **Any-hit queries** ([`occluded`]) stop at the first proof of a
//!   blocker: a ray below a cell's lowest corner is blocked without a
//!   solve.
//!
//! Sphere tracing itself is Hart's (1996) and Donnelly's: a step of the
//! stored distance never crosses the surface, so the first hit is never
//! passed, and every hit comes from the exact patch solve.

use crate::convention::{floor_i64, TRACE_BAND_FACTOR, TRACE_STOP_VOXELS};
use crate::exact::{patch_hit, SurfaceHit, Walk};
use crate::sphere_trace::{clip, surface_hit, wall_hit, MapHit, MapRay};
use crate::sphere_trace::{Method, TraceOptions};
use crate::{DistanceMap, HeightMap};
use glam::Vec3;

/// First hit of `ray` on the displaced surface, as
/// [`crate::sphere_trace::trace`] finds it with [`Method::Sphere`] (other
/// methods are traced there). `iterations` counts voxel steps plus patches
/// visited.
pub fn trace(
    height: &HeightMap,
    distance: &DistanceMap,
    ray: &MapRay,
    opts: &TraceOptions,
) -> Option<MapHit> {
    if opts.method != Method::Sphere {
        return crate::sphere_trace::trace(height, distance, ray, opts);
    }
    match run::<false>(height, distance, ray, opts) {
        Outcome::Hit(h) => Some(h),
        Outcome::Blocked | Outcome::Miss => None,
    }
}

/// Whether `ray` meets the surface (or enters the solid) with `t` in
/// `[opts.t_min, opts.t_max]`: the shadow-ray query, which stops at the
/// first proof of a blocker instead of finding the first hit. Agrees with
/// `trace(..).is_some()` for every method; [`Method::Sphere`] takes the fast
/// path.
pub fn occluded(
    height: &HeightMap,
    distance: &DistanceMap,
    ray: &MapRay,
    opts: &TraceOptions,
) -> bool {
    if opts.method != Method::Sphere {
        return crate::sphere_trace::trace(height, distance, ray, opts).is_some();
    }
    !matches!(run::<true>(height, distance, ray, opts), Outcome::Miss)
}

enum Outcome {
    Hit(MapHit),
    /// An any-hit query found a blocker (no hit worked out).
    Blocked,
    Miss,
}

fn run<const ANY: bool>(
    height: &HeightMap,
    distance: &DistanceMap,
    ray: &MapRay,
    opts: &TraceOptions,
) -> Outcome {
    let aspect = distance.aspect();
    let hi = Vec3::new(aspect[0] * opts.tiles[0], aspect[1] * opts.tiles[1], 1.0);
    let Some(clip) = clip(ray, hi, opts.t_min, opts.t_max) else {
        return Outcome::Miss;
    };
    let at = |t: f32| ray.origin + ray.dir * t;
    let found = |h: MapHit| {
        if ANY {
            Outcome::Blocked
        } else {
            Outcome::Hit(h)
        }
    };
    // Under the surface where the ray enters: the wall of the slab. A ray
    // that enters through the top (z = 1) cannot be, as heights are at
    // most 1: most camera rays skip the look-up.
    let entry = at(clip.t_in);
    let through_top = clip.entry_normal == Vec3::Z;
    if !through_top && entry.z < height.sample(entry.x / aspect[0], entry.y / aspect[1]) {
        return found(wall_hit(ray, aspect, &clip, clip.t_in, 0));
    }
    let walk = |t0: f32, t1: f32| walk::<ANY>(height, aspect, ray, t0, t1);
    // A hit of the walk ends the trace (this walk reports only hits and
    // misses: a ray under its first patch is that patch's root at the
    // walk's start).
    let settle = |w: Walk, iterations: u32| -> Option<Outcome> {
        match w {
            Walk::Hit(h) => Some(found(surface_hit(
                ray,
                aspect,
                h.t as f32,
                h.normal,
                iterations + h.cells,
                true,
            ))),
            Walk::StartsInside { .. } | Walk::Miss { .. } => None,
        }
    };
    let voxel = distance.voxel_size();
    let tau = TRACE_STOP_VOXELS * voxel.min_element();
    // The values read are unrounded: their bound is the data's, without the
    // 8-bit codes' quantum.
    let band = TRACE_BAND_FACTOR * distance.data_underestimate() + tau;
    let max_steps = opts.iterations.max(1);
    let mut t = clip.t_in;
    let mut steps = 0u32;
    let mut iterations = 0u32;
    while t <= clip.t_out {
        if steps >= max_steps {
            // Out of steps: finish exactly, which is always right.
            return settle(walk(t, clip.t_out), iterations).unwrap_or(Outcome::Miss);
        }
        let s = distance.cell_bound(at(t));
        steps += 1;
        iterations += 1;
        if s >= tau {
            t += s;
            continue;
        }
        let t1 = (t + band).min(clip.t_out);
        let w = walk(t, t1);
        if let Some(out) = settle(w, iterations) {
            return out;
        }
        if let Walk::Miss { cells } = w {
            iterations += cells;
        }
        if t1 >= clip.t_out {
            break;
        }
        t = t1;
    }
    Outcome::Miss
}

/// The exact walk of [`crate::exact::walk`] over `[t0, t1]`, built for
/// speed where the reference is built for plainness:
/// - the cells are stepped in single precision (a ray crosses a few dozen
///   cells here, so the boundaries drift by well under a micro-cell; the
///   stretches stay contiguous, each shared boundary one value, so no root
///   falls between two cells), and only the patch solve runs in double;
/// - a cell is solved only when the ray's lowest point over its stretch
///   comes within `margin` of the cell's highest corner (a bilinear patch
///   never rises above its corners); the margin, `1e-4 (1 + t1)` shell
///   depths, is far wider than the rounding of the stretch's ends and the
///   solver's tolerance past them;
/// - no separate test that the ray starts under the surface: a ray under
///   the first cell's patch is caught by its solve, whose root is then the
///   start itself;
/// - with `ANY`, a ray that goes below a cell's lowest corner by `margin`
///   is blocked without a solve (the returned hit then carries a point of
///   that stretch and no normal).
#[inline]
fn walk<const ANY: bool>(
    height: &HeightMap,
    aspect: [f32; 2],
    ray: &MapRay,
    t0: f32,
    t1: f32,
) -> Walk {
    let (o, d) = (ray.origin, ray.dir);
    if t1 < t0 {
        return Walk::Miss { cells: 0 };
    }
    // Cell coordinates as the reference has them: texel centres at
    // integers, cell c spanning [c, c + 1].
    let sx = height.width() as f64 / aspect[0] as f64;
    let sy = height.height() as f64 / aspect[1] as f64;
    let axis = |o: f32, d: f32, s: f64| {
        let (s, x0) = (s as f32, (o + d * t0) * s as f32 - 0.5);
        let c = floor_i64(x0);
        let ds = d * s;
        if ds > 0.0 {
            (c, 1, t0 + ((c + 1) as f32 - x0) / ds, 1.0 / ds)
        } else if ds < 0.0 {
            (c, -1, t0 + (c as f32 - x0) / ds, -1.0 / ds)
        } else {
            (c, 0, f32::INFINITY, f32::INFINITY)
        }
    };
    let (mut ci, step_i, mut tx, dtx) = axis(o.x, d.x, sx);
    let (mut cj, step_j, mut ty, dty) = axis(o.y, d.y, sy);
    let margin = 1e-4 * (1.0 + t1.abs());
    let descending = d.z < 0.0;
    let (od, dd) = (o.as_dvec3(), d.as_dvec3());
    let mut ta = t0;
    let mut cells = 0u32;
    loop {
        let tb = min(min(tx, ty), t1);
        cells += 1;
        let corners = height.cell_fast(ci, cj);
        let [h00, h10, h01, h11] = corners;
        let z_low = o.z + d.z * if descending { tb } else { ta };
        if ANY && z_low < min(min(h00, h10), min(h01, h11)) - margin {
            return Walk::Hit(SurfaceHit {
                t: if descending { tb } else { ta } as f64,
                normal: Vec3::ZERO,
                cells,
            });
        }
        if z_low - margin <= max(max(h00, h10), max(h01, h11)) {
            if let Some((t, normal)) =
                patch_hit(corners, ci, cj, od, dd, sx, sy, ta as f64, tb as f64)
            {
                return Walk::Hit(SurfaceHit { t, normal, cells });
            }
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

/// `f32::min` without its NaN rule (one instruction, not four): the
/// walk's values are finite.
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}
