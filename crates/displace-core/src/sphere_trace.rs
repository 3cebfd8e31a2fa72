//! Map-space ray tracing as the GPU does it: Donnelly's sphere tracing of
//! the trilinearly sampled distance map (GPU Gems 2 ch. 8, section 8.3,
//! listing 8-2), an early-out variant (the chapter's future work, section
//! 8.7), refinement to the exact hit on the bilinear patches over the short
//! stretch the map cannot resolve, and the exact reference. The WGSL
//! tracers mirror this loop fetch for fetch, and `displace compare` charges
//! its fetches; the CPU renderer runs the same early-out method through
//! [`crate::cell_trace`], which finds the same hits with fewer loads.
//!
//! Rays live in map space ([`crate::convention`]): lengths in shell depths,
//! the shell of a face of `tiles` tiles is `[0, tiles.x * ax] x [0, tiles.y *
//! ay] x [0, 1]`. A ray that enters the shell under the surface (through a
//! side or the bottom) hits the solid at its entry point: a displaced face is
//! the top of a solid slab, so its silhouette is that of the slab.

use crate::convention::{TRACE_BAND_FACTOR, TRACE_STOP_VOXELS};
use crate::exact::{self, Walk};
use crate::{DistanceMap, Error, HeightMap, Result};
use glam::{Vec2, Vec3};

/// A ray in map space; `dir` is unit length in that metric.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapRay {
    /// Start of the ray, map space (depth units).
    pub origin: Vec3,
    /// Direction, unit length in map space ([`MapRay::new`] normalises it).
    pub dir: Vec3,
}

impl MapRay {
    /// Normalises `dir` (Donnelly's "normalization factor" is this step).
    pub fn new(origin: Vec3, dir: Vec3) -> Self {
        Self {
            origin,
            dir: dir.normalize(),
        }
    }
}

/// How the hit is found.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Method {
    /// Sphere tracing with early out when the stored distance says the ray is
    /// at the surface, then exact refinement: always the exact hit.
    #[default]
    Sphere,
    /// Donnelly's loop: a fixed number of steps, then the same refinement
    /// over the short segment the map cannot resolve. With too few steps the
    /// ray stops short and the hit is wrong, as in the paper.
    SphereFixed,
    /// The reference: every bilinear patch along the ray, solved exactly.
    Exact,
}

impl Method {
    /// Every method, in the order messages list them.
    pub const ALL: [Method; 3] = [Method::Sphere, Method::SphereFixed, Method::Exact];

    /// The name [`str::parse`] accepts (`sphere`, `sphere-fixed`, `exact`).
    pub fn name(self) -> &'static str {
        match self {
            Method::Sphere => "sphere",
            Method::SphereFixed => "sphere-fixed",
            Method::Exact => "exact",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        let choices = Method::ALL.map(|m| (m.name(), m));
        crate::names::parse_choice("method", s, &choices).map_err(Error::InvalidTrace)
    }
}

/// How a map-space ray is traced: the method, its step budget and the
/// interval of `t` that counts.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TraceOptions {
    /// Which intersector runs.
    pub method: Method,
    /// [`Method::SphereFixed`]: the number of steps. [`Method::Sphere`]: the
    /// most steps before the rest of the ray is walked exactly.
    pub iterations: u32,
    /// Only hits with `t` in `[t_min, t_max]` count.
    pub t_min: f32,
    /// Upper end of the hit interval (infinite by default).
    pub t_max: f32,
    /// How many tiles of the map the face spans (1 x 1 unless the map
    /// repeats).
    pub tiles: [f32; 2],
}

impl Default for TraceOptions {
    fn default() -> Self {
        Self {
            method: Method::Sphere,
            iterations: 64,
            t_min: 0.0,
            t_max: f32::INFINITY,
            tiles: [1.0, 1.0],
        }
    }
}

/// What the ray hit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HitKind {
    /// The displaced surface.
    Surface,
    /// A side or the bottom of the shell, entered under the surface.
    Wall,
}

/// A map-space hit: where, with which normal, and what it cost.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MapHit {
    /// Ray parameter of the hit: distance from the origin in depth units.
    pub t: f32,
    /// Map space, depth units.
    pub position: Vec3,
    /// Texture coordinate of the hit (in tiles: `[0, tiles]`).
    pub uv: Vec2,
    /// Geometric normal in map space, unit length.
    pub normal: Vec3,
    /// Whether the surface or the shell's wall was hit.
    pub kind: HitKind,
    /// Distance-map steps plus patches walked.
    pub iterations: u32,
    /// False only for [`Method::SphereFixed`] when its steps ran out before
    /// the ray reached the surface.
    pub converged: bool,
}

/// The shell's box, and where the ray crosses it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Clip {
    /// Ray parameter where the ray enters the box (`t_min` if it starts inside).
    pub t_in: f32,
    /// Ray parameter where the ray leaves the box.
    pub t_out: f32,
    /// Outward normal of the face the ray entered through (zero if the ray
    /// starts inside).
    pub entry_normal: Vec3,
}

/// Where `ray` crosses the box `[0, hi]` within `[t_min, t_max]` (slabs), or
/// `None` when it misses it. Every map-space tracer clips with this.
#[inline]
pub fn clip(ray: &MapRay, hi: Vec3, t_min: f32, t_max: f32) -> Option<Clip> {
    let mut t_in = t_min;
    let mut t_out = t_max;
    let mut entry_normal = Vec3::ZERO;
    // One slab per axis, in the order x, y, z (a later axis takes the entry
    // only when it enters strictly later), unrolled: indexing a `Vec3` by a
    // loop variable is a branch per access.
    let mut slab = |o: f32, d: f32, hi: f32, axis: Vec3| -> bool {
        if d == 0.0 {
            return (0.0..=hi).contains(&o);
        }
        let (t0, t1) = ((0.0 - o) / d, (hi - o) / d);
        let (t0, t1, n) = if t0 > t1 {
            (t1, t0, axis)
        } else {
            (t0, t1, -axis)
        };
        if t0 > t_in {
            t_in = t0;
            entry_normal = n;
        }
        t_out = t_out.min(t1);
        true
    };
    let inside = slab(ray.origin.x, ray.dir.x, hi.x, Vec3::X)
        && slab(ray.origin.y, ray.dir.y, hi.y, Vec3::Y)
        && slab(ray.origin.z, ray.dir.z, hi.z, Vec3::Z);
    (inside && t_in <= t_out).then_some(Clip {
        t_in,
        t_out,
        entry_normal,
    })
}

/// Traces `ray` against the displaced surface of `height` (aspect `aspect`),
/// with `distance` as the conservative distance map; also returns the
/// fetches it made (distance samples plus patches walked) on a miss as on a
/// hit: what `displace compare` charges.
pub fn trace_counted(
    height: &HeightMap,
    distance: &DistanceMap,
    ray: &MapRay,
    opts: &TraceOptions,
) -> (Option<MapHit>, u32) {
    let aspect = distance.aspect();
    let hi = Vec3::new(aspect[0] * opts.tiles[0], aspect[1] * opts.tiles[1], 1.0);
    let Some(clip) = clip(ray, hi, opts.t_min, opts.t_max) else {
        return (None, 0);
    };
    let hit = |h: MapHit| (Some(h), h.iterations);
    let at = |t: f32| ray.origin + ray.dir * t;
    let surface = |t: f64, normal: Vec3, iterations: u32, converged: bool| {
        surface_hit(ray, aspect, t as f32, normal, iterations, converged)
    };
    let wall = |t: f32, iterations: u32| wall_hit(ray, aspect, &clip, t, iterations);
    let walk = |t0: f32, t1: f32| exact::walk(height, aspect, ray.origin, ray.dir, t0, t1);
    // A hit where the ray stands, shaded by the height field's own normal.
    let here = |t: f32, iterations: u32, converged: bool| {
        surface(
            t as f64,
            shading_normal(height, aspect, at(t)),
            iterations,
            converged,
        )
    };

    // Under the surface where the ray enters: the wall of the slab.
    let entry = at(clip.t_in);
    if entry.z < height.sample(entry.x / aspect[0], entry.y / aspect[1]) {
        return hit(wall(clip.t_in, 0));
    }
    if opts.method == Method::Exact {
        return match walk(clip.t_in, clip.t_out) {
            Walk::Hit(h) => hit(surface(h.t, h.normal, h.cells, true)),
            Walk::StartsInside { cells } => hit(wall(clip.t_in, cells)),
            Walk::Miss { cells } if leaves_through_floor(ray, clip.t_out) => {
                hit(surface(clip.t_out as f64, Vec3::Z, cells, true))
            }
            Walk::Miss { cells } => (None, cells),
        };
    }

    // Within `band` of the surface the stored distance cannot tell the ray
    // from it: walk that stretch exactly instead of crawling towards the
    // map's zero level set (which sits up to `max_underestimate` above the
    // surface).
    let voxel = distance.voxel_size();
    let tau = TRACE_STOP_VOXELS * voxel.min_element();
    let band = TRACE_BAND_FACTOR * distance.max_underestimate() + tau;
    let mut t = clip.t_in;
    let mut iterations = 0u32;
    let fixed = opts.method == Method::SphereFixed;
    let max_steps = opts.iterations.max(1);
    let mut steps = 0u32;
    while t <= clip.t_out {
        if steps >= max_steps {
            if fixed {
                // Donnelly's loop ends here: refine what the map can no longer
                // resolve, and accept an unconverged hit otherwise.
                return match walk(t, (t + band).min(clip.t_out)) {
                    Walk::Hit(h) => hit(surface(h.t, h.normal, iterations + h.cells, true)),
                    Walk::StartsInside { cells } | Walk::Miss { cells } => {
                        hit(here(t, iterations + cells, false))
                    }
                };
            }
            // Out of steps: finish exactly, which is always right.
            return match walk(t, clip.t_out) {
                Walk::Hit(h) => hit(surface(h.t, h.normal, iterations + h.cells, true)),
                Walk::StartsInside { cells } => hit(here(t, iterations + cells, true)),
                Walk::Miss { cells } => (None, iterations + cells),
            };
        }
        let s = distance.sample(at(t));
        steps += 1;
        iterations += 1;
        if !fixed && s < tau {
            let t1 = (t + band).min(clip.t_out);
            match walk(t, t1) {
                Walk::Hit(h) => return hit(surface(h.t, h.normal, iterations + h.cells, true)),
                Walk::StartsInside { cells } => return hit(here(t, iterations + cells, true)),
                Walk::Miss { cells } => {
                    iterations += cells;
                    if t1 >= clip.t_out {
                        return (None, iterations);
                    }
                    t = t1;
                }
            }
        } else {
            // A negative value steps back along the ray, over points already
            // known to be free: `t` never passes the first hit.
            t = (t + s).max(clip.t_in);
        }
    }
    (None, iterations)
}

/// Whether `ray` leaves the shell through its floor (`z = 0`) at `t_out`,
/// within the single-precision rounding of that exit (1e-6 of the ray's
/// scale: a few ulps of the origin's height and of the parameter, far
/// below any visible height). Heights never go below the floor, so such a
/// ray has met the surface by its exit: where a walk found no root there
/// (the exit at a cell boundary, on a patch the ray runs nearly parallel
/// to, where rounding puts the root past both cells' stretches), the exit
/// is the hit, within that rounding of the exact one. Both the exact
/// reference and the CPU tracer ([`crate::cell_trace`]) end so.
#[inline]
pub(crate) fn leaves_through_floor(ray: &MapRay, t_out: f32) -> bool {
    let (oz, dz) = (ray.origin.z, ray.dir.z);
    let z = oz + dz * t_out;
    dz < 0.0 && z <= 1e-6 * (1.0 + oz.abs() + t_out.abs())
}

/// The hit on the displaced surface at `t` along `ray`.
pub(crate) fn surface_hit(
    ray: &MapRay,
    aspect: [f32; 2],
    t: f32,
    normal: Vec3,
    iterations: u32,
    converged: bool,
) -> MapHit {
    hit_at(
        ray,
        aspect,
        t,
        (normal, HitKind::Surface),
        iterations,
        converged,
    )
}

/// The hit on the shell's side or bottom at `t`, entered under the
/// surface: its normal is the face the ray entered through (`-dir` for a
/// ray that starts inside the solid).
pub(crate) fn wall_hit(
    ray: &MapRay,
    aspect: [f32; 2],
    clip: &Clip,
    t: f32,
    iterations: u32,
) -> MapHit {
    let normal = if clip.entry_normal == Vec3::ZERO {
        -ray.dir
    } else {
        clip.entry_normal
    };
    hit_at(ray, aspect, t, (normal, HitKind::Wall), iterations, true)
}

/// The hit at `t` along `ray`, its map coordinates from the position.
fn hit_at(
    ray: &MapRay,
    aspect: [f32; 2],
    t: f32,
    (normal, kind): (Vec3, HitKind),
    iterations: u32,
    converged: bool,
) -> MapHit {
    let position = ray.origin + ray.dir * t;
    let uv = Vec2::new(position.x / aspect[0], position.y / aspect[1]);
    MapHit {
        t,
        position,
        uv,
        normal,
        kind,
        iterations,
        converged,
    }
}

/// Normal of the bilinear surface at map-space point `p` (used where a hit
/// has no patch of its own: an unconverged fixed-step hit).
fn shading_normal(height: &HeightMap, aspect: [f32; 2], p: Vec3) -> Vec3 {
    let g = height.gradient(p.x / aspect[0], p.y / aspect[1]);
    Vec3::new(-g[0] / aspect[0], -g[1] / aspect[1], 1.0).normalize()
}
