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
use crate::exact::{floor_f64, over_patch, patch_hit, SurfaceHit, Walk};
use crate::horizon::HorizonMap;
use crate::sphere_trace::{clip, leaves_through_floor, surface_hit, wall_hit, MapHit, MapRay};
use crate::sphere_trace::{Method, TraceOptions};
use crate::{DistanceMap, HeightMap};
use glam::Vec3;

/// First hit of `ray` on the displaced surface, as
/// [`crate::sphere_trace::trace_counted`] finds it with [`Method::Sphere`] (other
/// methods are traced there). `iterations` counts voxel steps plus patches
/// visited.
pub fn trace(
    height: &HeightMap,
    distance: &DistanceMap,
    ray: &MapRay,
    opts: &TraceOptions,
) -> Option<MapHit> {
    if opts.method != Method::Sphere {
        return crate::sphere_trace::trace_counted(height, distance, ray, opts).0;
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
        return crate::sphere_trace::trace_counted(height, distance, ray, opts)
            .0
            .is_some();
    }
    !matches!(run::<true>(height, distance, ray, opts), Outcome::Miss)
}

mod packet;
mod pyramid;

pub use pyramid::{occluded_over, AnyHitPyramid};

pub use packet::{with_kernel, Kernel, LANES, WIDE_LANES};

/// [`trace`] for many rays, each with its own options, eight at a time
/// where the CPU allows (packets of [`LANES`] rays in AVX2 lanes): `out[i]`
/// is exactly what `trace(height, distance, &rays[i], &opts[i])` returns.
///
/// # Panics
/// When the three slices differ in length.
pub fn trace_many(
    height: &HeightMap,
    distance: &DistanceMap,
    rays: &[MapRay],
    opts: &[TraceOptions],
    out: &mut [Option<MapHit>],
) {
    assert!(rays.len() == opts.len() && rays.len() == out.len());
    packet::run_all::<false>(height, distance, rays, opts, |i, o| {
        out[i] = match o {
            Outcome::Hit(h) => Some(h),
            Outcome::Blocked | Outcome::Miss => None,
        }
    });
}

/// [`trace_many`] handing each hit to `hit(i, ..)` as it is found (misses
/// say nothing), for callers that keep their own answers: a batch query
/// that would otherwise fill and read back a slice of `Option<MapHit>`.
pub fn trace_each(
    height: &HeightMap,
    distance: &DistanceMap,
    rays: &[MapRay],
    opts: &[TraceOptions],
    mut hit: impl FnMut(usize, MapHit),
) {
    assert_eq!(rays.len(), opts.len());
    packet::run_all::<false>(height, distance, rays, opts, |i, o| {
        if let Outcome::Hit(h) = o {
            hit(i, h)
        }
    });
}

/// [`occluded`] for many rays, eight at a time where the CPU allows:
/// `out[i]` is exactly `occluded(height, distance, &rays[i], &opts[i])`.
///
/// # Panics
/// When the three slices differ in length.
pub fn occluded_many(
    height: &HeightMap,
    distance: &DistanceMap,
    rays: &[MapRay],
    opts: &[TraceOptions],
    out: &mut [bool],
) {
    assert!(rays.len() == opts.len() && rays.len() == out.len());
    packet::run_all::<true>(height, distance, rays, opts, |i, o| {
        out[i] = !matches!(o, Outcome::Miss)
    });
}

/// A ray traced by a method other than [`Method::Sphere`], as [`trace`]
/// and [`occluded`] trace it.
fn run_other(
    height: &HeightMap,
    distance: &DistanceMap,
    ray: &MapRay,
    opts: &TraceOptions,
    any: bool,
) -> Outcome {
    match crate::sphere_trace::trace_counted(height, distance, ray, opts).0 {
        Some(_) if any => Outcome::Blocked,
        Some(h) => Outcome::Hit(h),
        None => Outcome::Miss,
    }
}

#[derive(Clone, Copy)]
enum Outcome {
    Hit(MapHit),
    /// An any-hit query found a blocker (no hit worked out).
    Blocked,
    Miss,
}

/// How far over the surface (shell depths, the patch evaluated in double
/// precision as the solve does) an any-hit ray must start for the horizon
/// bounds to answer it: far over that evaluation's rounding, so that a ray
/// the first-hit query finds touching the surface at its start is traced
/// and answered alike.
const HORIZON_CLEARANCE: f64 = 1e-6;

/// Whether height `z` stands more than [`HORIZON_CLEARANCE`] over the
/// surface at cell coordinates `(x, y)`, as the patch solve has it
/// ([`over_patch`]: double precision at the cell's own coordinates). The
/// single-precision sample is off by its coordinates' rounding times the
/// slope, more than the clearance on a steep, wide map.
#[inline]
fn over_surface(height: &HeightMap, x: f64, y: f64, z: f32) -> bool {
    let (ci, cj) = (floor_f64(x), floor_f64(y));
    let corners = height.cell_fast(ci, cj).map(f64::from);
    over_patch(corners, x - ci as f64, y - cj as f64, z as f64) > HORIZON_CLEARANCE
}

/// What every ray traced through one map shares: its tile box, the
/// early-out threshold of the steps and the exact band walked below it.
pub(crate) struct Constants<'a> {
    aspect: [f32; 2],
    tau: f32,
    band: f32,
    /// Height cells per map unit across and down ([`Grid`]).
    cells: [f64; 2],
    /// The height map's horizon bounds, where they were built and kept
    /// ([`crate::DisplacementMap::prepare_horizon`]): any-hit queries that
    /// leave the surface more steeply end at once.
    horizon: Option<&'a HorizonMap>,
}

impl<'a> Constants<'a> {
    fn new(height: &'a HeightMap, distance: &DistanceMap) -> Self {
        let voxel = distance.voxel_size();
        let tau = TRACE_STOP_VOXELS * voxel.min_element();
        let aspect = distance.aspect();
        Constants {
            aspect,
            cells: [
                height.width() as f64 / aspect[0] as f64,
                height.height() as f64 / aspect[1] as f64,
            ],
            tau,
            // The values read are unrounded: their bound is the data's,
            // without the 8-bit codes' quantum.
            band: TRACE_BAND_FACTOR * distance.data_underestimate() + tau,
            horizon: height.horizon(),
        }
    }
}

/// One ray's trace in progress: where along the ray it stands, the steps
/// it has taken and the patches it has walked. The scalar loop ([`run`])
/// and the packet loop ([`packet`]) drive the same lanes through
/// [`Lane::check`], [`Lane::take_step`] and [`Lane::walked`], so a ray's hit does not
/// depend on which of them traced it, nor on its packet's other rays.
pub(crate) struct Lane {
    ray: MapRay,
    t_out: f32,
    max_steps: u32,
    grid: Grid,
    t: f32,
    steps: u32,
    /// Patches walked so far (`iterations` = steps + walked).
    walked: u32,
}

impl Lane {
    /// Clips `ray` to the shell, or says how the trace ends at once.
    /// Inlined into its callers so that the lane is built where it is kept
    /// (returned through memory, its copy stalled on store forwarding).
    #[inline(always)]
    fn begin(
        height: &HeightMap,
        c: &Constants,
        ray: &MapRay,
        opts: &TraceOptions,
        any: bool,
    ) -> Result<Lane, Outcome> {
        let aspect = c.aspect;
        let hi = Vec3::new(aspect[0] * opts.tiles[0], aspect[1] * opts.tiles[1], 1.0);
        let Some(clip) = clip(ray, hi, opts.t_min, opts.t_max) else {
            return Err(Outcome::Miss);
        };
        // Under the surface where the ray enters: the wall of the slab. A
        // ray that enters through the top (z = 1) cannot be, as heights are
        // at most 1: most camera rays skip the look-up.
        let entry = ray.origin + ray.dir * clip.t_in;
        let through_top = clip.entry_normal == Vec3::Z;
        if !through_top {
            let ground = height.sample(entry.x / aspect[0], entry.y / aspect[1]);
            if entry.z < ground {
                return Err(if any {
                    Outcome::Blocked
                } else {
                    Outcome::Hit(wall_hit(ray, aspect, &clip, clip.t_in, 0))
                });
            }
            // A shadow ray leaving the surface more steeply than the
            // horizon around its start meets nothing on the map
            // (`crate::horizon`; a ray entering through the top descends,
            // so it never is one). Only from strictly over the surface: a
            // ray that starts on it (or enters the shell through the floor
            // where the surface lies on it) has its first hit at its start.
            if any && opts.tiles == [1.0, 1.0] {
                if let Some(horizon) = c.horizon {
                    let [sx, sy] = c.cells;
                    let (x, y) = (entry.x as f64 * sx - 0.5, entry.y as f64 * sy - 0.5);
                    let (dx, dy) = (ray.dir.x as f64 * sx, ray.dir.y as f64 * sy);
                    if horizon.clears(x as f32, y as f32, dx as f32, dy as f32, ray.dir.z)
                        && over_surface(height, x, y, entry.z)
                    {
                        return Err(Outcome::Miss);
                    }
                }
            }
        }
        Ok(Lane {
            ray: *ray,
            t_out: clip.t_out,
            max_steps: opts.iterations.max(1),
            grid: Grid::new(c.cells, ray),
            t: clip.t_in,
            steps: 0,
            walked: 0,
        })
    }

    #[inline(always)]
    fn at(&self) -> Vec3 {
        self.ray.origin + self.ray.dir * self.t
    }

    /// A hit of a walk ends the trace (this walk reports only hits and
    /// misses: a ray under its first patch is that patch's root at the
    /// walk's start).
    fn settle<const ANY: bool>(&self, c: &Constants, w: Walk) -> Option<Outcome> {
        match w {
            Walk::Hit(_) if ANY => Some(Outcome::Blocked),
            Walk::Hit(h) => Some(Outcome::Hit(surface_hit(
                &self.ray,
                c.aspect,
                h.t as f32,
                h.normal,
                self.steps + self.walked + h.cells,
                true,
            ))),
            Walk::StartsInside { .. } | Walk::Miss { .. } => None,
        }
    }

    /// Before reading the next step: the end of the trace when the ray is
    /// past the shell, or, out of steps, the walk of the rest of it
    /// (`final`: the walk's miss ends the trace), which is always right.
    #[inline(always)]
    fn check(&self) -> Next {
        // The scalar loop's `while t <= t_out`: a NaN ends it too.
        if self.t.partial_cmp(&self.t_out).is_none_or(|o| o.is_gt()) {
            Next::Done(Outcome::Miss)
        } else if self.steps >= self.max_steps {
            Next::Walk {
                t1: self.t_out,
                last: true,
            }
        } else {
            Next::Step
        }
    }

    /// Takes step `s` read at the lane's point: a sphere step, or, where
    /// the stored distance can no longer tell the ray from the surface, the
    /// exact walk of the band ahead.
    #[inline(always)]
    fn take_step(&mut self, c: &Constants, s: f32) -> Next {
        self.steps += 1;
        if s >= c.tau {
            self.t += s;
            Next::Step
        } else {
            Next::Walk {
                t1: (self.t + c.band).min(self.t_out),
                last: false,
            }
        }
    }

    /// After walking `[self.t, t1]`: the end of the trace on a hit, on the
    /// last walk, or at the shell's exit; otherwise the steps resume at
    /// `t1`.
    #[inline(always)]
    fn walked<const ANY: bool>(
        &mut self,
        c: &Constants,
        w: Walk,
        t1: f32,
        last: bool,
    ) -> Option<Outcome> {
        if let Some(out) = self.settle::<ANY>(c, w) {
            return Some(out);
        }
        if let Walk::Miss { cells } = w {
            self.walked += cells;
        }
        if last || t1 >= self.t_out {
            return Some(self.floor_exit::<ANY>(c));
        }
        self.t = t1;
        None
    }

    /// The end of a trace whose walks found nothing up to the shell's exit:
    /// a hit at the exit where the ray [`leaves_through_floor`] (the
    /// single-precision stretches and the double-precision patch disagree
    /// by the rounding of the cell coordinates, so such a root can fall
    /// past both cells' stretches), else a miss.
    #[inline(always)]
    fn floor_exit<const ANY: bool>(&self, c: &Constants) -> Outcome {
        if !leaves_through_floor(&self.ray, self.t_out) {
            return Outcome::Miss;
        }
        if ANY {
            return Outcome::Blocked;
        }
        Outcome::Hit(surface_hit(
            &self.ray,
            c.aspect,
            self.t_out,
            Vec3::Z,
            self.steps + self.walked,
            true,
        ))
    }

    /// Runs a transition to its end on this lane alone: the walk, if one is
    /// due. `None` when the lane steps on.
    #[inline(always)]
    fn resolve<const ANY: bool>(
        &mut self,
        height: &HeightMap,
        c: &Constants,
        next: Next,
    ) -> Option<Outcome> {
        match next {
            Next::Step => None,
            Next::Done(out) => Some(out),
            Next::Walk { t1, last } => {
                let w = walk::<ANY>(height, &self.grid, c.cells, self.t, t1);
                self.walked::<ANY>(c, w, t1, last)
            }
        }
    }
}

/// What a lane does next.
#[derive(Clone, Copy)]
enum Next {
    /// Read a step at its point.
    Step,
    /// Walk `[t, t1]` exactly; `last`: a miss of that walk ends the trace.
    Walk {
        t1: f32,
        last: bool,
    },
    Done(Outcome),
}

fn run<const ANY: bool>(
    height: &HeightMap,
    distance: &DistanceMap,
    ray: &MapRay,
    opts: &TraceOptions,
) -> Outcome {
    let c = Constants::new(height, distance);
    let mut lane = match Lane::begin(height, &c, ray, opts, ANY) {
        Ok(lane) => lane,
        Err(out) => return out,
    };
    lane.finish::<ANY>(height, distance, &c)
}

impl Lane {
    /// The one-ray loop: steps and walks this lane to the end of its
    /// trace. (A walk that [`Lane::check`] hands out is always the last,
    /// so it ends the trace.)
    fn finish<const ANY: bool>(
        &mut self,
        height: &HeightMap,
        distance: &DistanceMap,
        c: &Constants,
    ) -> Outcome {
        loop {
            let next = self.check();
            if let Some(out) = self.resolve::<ANY>(height, c, next) {
                return out;
            }
            let s = distance.cell_bound(self.at());
            let next = self.take_step(c, s);
            if let Some(out) = self.resolve::<ANY>(height, c, next) {
                return out;
            }
        }
    }
}

/// What every walk of one ray shares: the height map's cell grid in map
/// units (texel centres at integers, cell `c` spanning `[c, c + 1]`, as the
/// reference has them) and the ray's per-axis stepping through it, worked
/// out once per ray rather than once per walk (a shadow ray leaving the
/// surface walks several bands; the divisions were a fifth of a walk), the
/// cell scale once per map ([`Constants`]).
pub(crate) struct Grid {
    o: Vec3,
    d: Vec3,
    x: Axis,
    y: Axis,
}

/// One axis of the cell walk: cell coordinate `o + d t` (already scaled to
/// cells), the step direction, and `1 / |d|`, the parameter per cell.
///
/// `o` and `d` are worked out in double precision at the solve's own scale
/// and rounded once: with the scale rounded to single precision first, a
/// map thousands of cells wide (an 8K height map, a floor of many
/// repeating tiles) put cell boundaries ten-thousandths of a cell away from
/// where the double-precision patch solve has them. What rounding is left
/// (a few ulps of the coordinate) moves a hit by as much and loses none:
/// inside the shell the next cell's solve finds a root the gap hid, and at
/// the shell's floor [`Lane::floor_exit`] stands in.
struct Axis {
    o: f32,
    d: f32,
    step: i64,
    dt: f32,
}

impl Axis {
    #[inline(always)]
    fn new(o: f32, d: f32, s: f64) -> Self {
        let ds = (d as f64 * s) as f32;
        let (step, dt) = if ds > 0.0 {
            (1, 1.0 / ds)
        } else if ds < 0.0 {
            (-1, -1.0 / ds)
        } else {
            (0, f32::INFINITY)
        };
        Axis {
            o: (o as f64 * s - 0.5) as f32,
            d: ds,
            step,
            dt,
        }
    }

    /// The cell containing the ray at `t0` and the parameter at which the
    /// ray leaves it along this axis.
    #[inline(always)]
    fn start(&self, t0: f32) -> (i64, f32) {
        let x0 = self.o + self.d * t0;
        let c = floor_i64(x0);
        match self.step {
            1 => (c, t0 + ((c + 1) as f32 - x0) * self.dt),
            -1 => (c, t0 + (x0 - c as f32) * self.dt),
            _ => (c, f32::INFINITY),
        }
    }
}

impl Grid {
    #[inline(always)]
    fn new([sx, sy]: [f64; 2], ray: &MapRay) -> Self {
        let (o, d) = (ray.origin, ray.dir);
        Grid {
            o,
            d,
            x: Axis::new(o.x, d.x, sx),
            y: Axis::new(o.y, d.y, sy),
        }
    }
}

/// The exact walk of [`crate::exact::walk`] over `[t0, t1]`, built for
/// speed where the reference is built for plainness:
/// - the cells are stepped in single precision ([`Axis`]; a ray crosses a
///   few dozen cells here, so the boundaries drift by well under a
///   micro-cell; the stretches stay contiguous, each shared boundary one
///   value, so no root falls between two cells), and only the patch solve
///   runs in double;
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
fn walk<const ANY: bool>(height: &HeightMap, g: &Grid, cells: [f64; 2], t0: f32, t1: f32) -> Walk {
    if t1 < t0 {
        return Walk::Miss { cells: 0 };
    }
    walk_from::<ANY>(height, g, cells, Cursor::start(g, t0), t1)
}

/// Where a walk stands: the cell it is in, the parameters at which the
/// ray leaves it across and down, where the ray entered it, and the cells
/// counted so far (this one not yet).
#[derive(Clone, Copy, Default)]
pub(crate) struct Cursor {
    pub(crate) ci: i64,
    pub(crate) cj: i64,
    pub(crate) tx: f32,
    pub(crate) ty: f32,
    pub(crate) ta: f32,
    pub(crate) cells: u32,
}

impl Cursor {
    /// The walk's start: the cell holding the ray at `t0`, none counted.
    #[inline(always)]
    fn start(g: &Grid, t0: f32) -> Self {
        let (ci, tx) = g.x.start(t0);
        let (cj, ty) = g.y.start(t0);
        Cursor {
            ci,
            cj,
            tx,
            ty,
            ta: t0,
            cells: 0,
        }
    }

    /// Where the ray leaves the cell (or the walk ends).
    #[inline(always)]
    fn tb(&self, t1: f32) -> f32 {
        min(min(self.tx, self.ty), t1)
    }

    /// Into the next cell: across where the ray leaves through an x side
    /// first, down otherwise.
    #[inline(always)]
    fn advance(&mut self, g: &Grid, tb: f32) {
        self.ta = tb;
        if self.tx < self.ty {
            self.ci += g.x.step;
            self.tx += g.x.dt;
        } else {
            self.cj += g.y.step;
            self.ty += g.y.dt;
        }
    }
}

/// The walk from the cell at `at` to `t1` ([`walk`]'s loop).
#[inline]
fn walk_from<const ANY: bool>(
    height: &HeightMap,
    g: &Grid,
    [sx, sy]: [f64; 2],
    mut at: Cursor,
    t1: f32,
) -> Walk {
    let margin = 1e-4 * (1.0 + t1.abs());
    let (oz, dz) = (g.o.z, g.d.z);
    let descending = dz < 0.0;
    loop {
        let (ta, tb) = (at.ta, at.tb(t1));
        at.cells += 1;
        let cells = at.cells;
        let corners = height.cell_fast(at.ci, at.cj);
        let [h00, h10, h01, h11] = corners;
        let z_low = oz + dz * if descending { tb } else { ta };
        if ANY && z_low < min(min(h00, h10), min(h01, h11)) - margin {
            return Walk::Hit(SurfaceHit {
                t: if descending { tb } else { ta } as f64,
                normal: Vec3::ZERO,
                cells,
            });
        }
        if z_low - margin <= max(max(h00, h10), max(h01, h11)) {
            let (od, dd) = (g.o.as_dvec3(), g.d.as_dvec3());
            if let Some((t, normal)) =
                patch_hit(corners, at.ci, at.cj, od, dd, sx, sy, ta as f64, tb as f64)
            {
                return Walk::Hit(SurfaceHit { t, normal, cells });
            }
        }
        if tb >= t1 {
            return Walk::Miss { cells };
        }
        let (tx, ty) = (at.tx, at.ty);
        at.advance(g, tb);
        if at.tx == tx && at.ty == ty {
            // A step of one cell no longer moves the ray's parameter (more
            // cells from its origin than single precision counts; scenes
            // are held far below that, `MAX_CELL_SPAN`): the rest cannot be
            // walked, and looping here would never end.
            return Walk::Miss { cells };
        }
    }
}

/// The walk on from the cell after the one at `at` (counted already),
/// whose solve found nothing: what [`walk_from`] does after such a cell.
pub(crate) fn walk_after<const ANY: bool>(
    height: &HeightMap,
    g: &Grid,
    cells: [f64; 2],
    mut at: Cursor,
    t1: f32,
) -> Walk {
    let tb = at.tb(t1);
    if tb >= t1 {
        return Walk::Miss { cells: at.cells };
    }
    at.advance(g, tb);
    walk_from::<ANY>(height, g, cells, at, t1)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::random::SplitMix64;
    use crate::Address;

    /// The packet kernel defers a crossing cell's solve and, should it find
    /// no root, walks on with [`walk_after`]: from any cell whose solve
    /// finds nothing, that must be the rest of the walk the scalar loop
    /// takes, cell for cell.
    #[test]
    fn the_walk_goes_on_after_a_rootless_cell_as_the_whole_walk_does() {
        let mut rng = SplitMix64::new(7);
        let (w, h) = (16, 12);
        let data = (0..w * h).map(|_| rng.next_f32()).collect();
        let height = HeightMap::new(w, h, data, Address::Clamp).unwrap();
        let aspect = [2.0f64, 1.5];
        let cells = [w as f64 / aspect[0], h as f64 / aspect[1]];
        let mut checked = 0;
        for _ in 0..2000 {
            let o = Vec3::new(rng.next_f32() * 2.0, rng.next_f32() * 1.5, 1.0);
            let d = Vec3::new(
                rng.next_f32() - 0.5,
                rng.next_f32() - 0.5,
                -0.05 - rng.next_f32(),
            )
            .normalize();
            let ray = MapRay::new(o, d);
            let g = Grid::new(cells, &ray);
            let t1 = (1.0 / -d.z).min(3.0);
            let whole = walk::<false>(&height, &g, cells, 0.0, t1);
            // Cell by cell along the walk, as the scalar loop goes: at each
            // cell before the one that ends it, the walk after that cell is
            // what is left of the whole walk.
            let mut at = Cursor::start(&g, 0.0);
            let end = match whole {
                Walk::Hit(hit) => hit.cells,
                Walk::Miss { cells } | Walk::StartsInside { cells, .. } => cells,
            };
            for _ in 1..end {
                at.cells += 1;
                assert_eq!(walk_after::<false>(&height, &g, cells, at, t1), whole);
                at.advance(&g, at.tb(t1));
                checked += 1;
            }
        }
        assert!(checked > 2000, "only {checked} cells checked");
    }
}
