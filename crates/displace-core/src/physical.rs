//! Ray queries against one displaced face in its physical frame: the
//! frame users measure in (metres of terrain, millimetres of a part), so
//! that batch tools (`displace trace`, the Python package) answer in the
//! units their rays were given in, and all of them answer alike.
//!
//! **Frames.** A physical point `(x, y, z)` (x along u in `[0, SX]`, y
//! along v in `[0, SY]`, z up, the shell in `[0, SZ]`) is map-space point
//! `(x, y, z) / SZ` (lengths in shell depths, Donnelly, GPU Gems 2 section
//! 8.3: the distance map spans a unit-depth slab). The scale is uniform, so
//! a direction keeps its orientation: the map-space direction is the
//! physical one normalised, and a map-space distance `t_m` along it is
//! `t_m * SZ` physical length. The `t` reported is the ray parameter for
//! the direction *as given*: `hit = origin + t * dir`, i.e. `t = t_m * SZ /
//! |dir|` (the physical distance when `dir` is unit length), and `t_max`
//! is read in the same units.

use crate::sphere_trace::{MapRay, TraceOptions};
use crate::{DisplacementMap, DistanceMap, Error, Extent, HeightMap, Result};
use glam::{Vec2, Vec3};

/// Largest magnitude of a ray's origin or direction component: past it the
/// direction's squared length overflows float32, and a ray of direction
/// 1e30 would be reported as having no length.
pub const MAX_RAY_COMPONENT: f32 = 1e18;

/// What a ray query reads of a displaced face: the heights its hits are
/// refined on, the distance map it steps through, and the tile's physical
/// size. Not the shading normals, which a query never reads, so that a
/// caller answering queries only (the Python package) need not hold them.
#[derive(Clone, Copy, Debug)]
pub struct Face<'a> {
    /// The bilinear height surface.
    pub height: &'a HeightMap,
    /// The conservative distance map.
    pub distance: &'a DistanceMap,
    /// One tile's physical size.
    pub extent: Extent,
}

impl<'a> From<&'a DisplacementMap> for Face<'a> {
    fn from(map: &'a DisplacementMap) -> Self {
        Face {
            height: &map.height,
            distance: &map.distance,
            extent: map.extent,
        }
    }
}

/// A hit on the displaced face, in the face's physical frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PhysicalHit {
    /// Ray parameter for the direction as given: `position = origin + t
    /// dir`.
    pub t: f32,
    /// The hit point, physical units.
    pub position: Vec3,
    /// Unit geometric normal of the bilinear surface (or of the shell's
    /// wall) at the hit, physical frame (the map's scale is uniform, so
    /// map-space normals are physical ones).
    pub normal: Vec3,
    /// Texture coordinate of the hit, in tiles (`[0, 1]` on a clamped map).
    pub uv: Vec2,
    /// The height-map texel cell hit, row-major (`j * width + i`): the
    /// face's analogue of a mesh's triangle index.
    pub cell: u32,
    /// Distance-map steps plus patches walked (Donnelly's cost, section
    /// 8.6).
    pub iterations: u32,
}

/// Whether `ray` passes [`check_ray`], as a predicate: the same
/// conditions without a message, cheap enough to run on each ray in the
/// loop that traces it, so that rays given in bulk are read once; the
/// message comes from [`check_ray`] for a ray that fails.
#[inline]
pub fn ray_is_valid(ray: &[f32; 7]) -> bool {
    // NaN compares false: a NaN limit or component fails each test.
    let t_max_ok = ray[6] > 0.0;
    let bounded = ray[..6].iter().all(|v| v.abs() <= MAX_RAY_COMPONENT);
    // The squared length decides as the length does (its square root is
    // positive and finite exactly where it is), without the root.
    let len2 = Vec3::new(ray[3], ray[4], ray[5]).length_squared();
    t_max_ok && bounded && len2 > 0.0 && len2.is_finite()
}

/// Checks one ray as given by a user: `ray` is origin xyz, direction xyz,
/// and `t_max` (positive, or infinite for an unbounded ray). `what` names
/// the ray in the message (such as "rays rays.npy: ray 12"); it is called
/// only for a bad ray, so that checking millions costs no formatting.
///
/// # Errors
///
/// [`Error::InvalidRay`] naming the first bad component: not finite,
/// larger than [`MAX_RAY_COMPONENT`], a direction of no length, or a
/// `t_max` that is NaN or not positive.
pub fn check_ray(what: impl FnOnce() -> String, ray: &[f32; 7]) -> Result<()> {
    if ray_is_valid(ray) {
        return Ok(());
    }
    diagnose(what, ray)
}

/// [`check_ray`]'s message: the first condition `ray` fails, one test per
/// condition (a test checks that it fails exactly where [`ray_is_valid`]
/// does).
fn diagnose(what: impl FnOnce() -> String, ray: &[f32; 7]) -> Result<()> {
    if ray[6].is_nan() || ray[6] <= 0.0 {
        return Err(Error::InvalidRay(format!(
            "{} has t_max {} in column 6, which must be positive (or inf)",
            what(),
            ray[6]
        )));
    }
    if let Some(c) = ray[..6].iter().position(|v| !v.is_finite()) {
        return Err(Error::InvalidRay(format!(
            "{} has {} in column {c}",
            what(),
            ray[c]
        )));
    }
    if let Some(c) = ray[..6].iter().position(|v| v.abs() > MAX_RAY_COMPONENT) {
        return Err(Error::InvalidRay(format!(
            "{} has {} in column {c}: values must be at most {MAX_RAY_COMPONENT:e} in magnitude (squared lengths must fit in float32)",
            what(),
            ray[c]
        )));
    }
    let d = Vec3::new(ray[3], ray[4], ray[5]);
    if !(d.length() > 0.0 && d.length().is_finite()) {
        return Err(Error::InvalidRay(format!(
            "{} has direction {d}, which has no length",
            what()
        )));
    }
    Ok(())
}

/// The map-space ray of a physical one, and its options with `t_max` (in
/// units of the direction's length, as given) carried over.
fn map_ray(face: Face<'_>, opts: &TraceOptions, ray: &[f32; 7]) -> (MapRay, TraceOptions, f32) {
    let sz = face.extent.sz;
    let dir = Vec3::new(ray[3], ray[4], ray[5]);
    let len = dir.length();
    let origin = Vec3::new(ray[0], ray[1], ray[2]);
    let mut opts = *opts;
    if ray[6] < f32::INFINITY {
        opts.t_max = opts.t_max.min(ray[6] * len / sz);
    }
    (MapRay::new(origin / sz, dir), opts, len)
}

/// The first hit of a checked physical ray ([`check_ray`]) on `face`:
/// [`DisplacementMap::trace`]'s hit, in physical units.
#[inline]
pub fn intersect(face: Face<'_>, opts: &TraceOptions, ray: &[f32; 7]) -> Option<PhysicalHit> {
    let (mray, opts, len) = map_ray(face, opts, ray);
    crate::cell_trace::trace(face.height, face.distance, &mray, &opts)
        .map(|hit| physical_hit(face, &hit, len))
}

/// Rays [`intersect_many`] and [`occluded_many`] map and trace at once: a
/// few packets' worth, so that the map-space rays stay in the first-level
/// cache between the two.
const BATCH: usize = 64;

/// [`intersect`] of every ray of `rays` (each checked, [`check_ray`]) into
/// `out`: the rays traced in packets ([`crate::cell_trace::trace_many`],
/// eight in AVX2 lanes where the CPU has them), `out[k]` bit for bit what
/// [`intersect`] finds for `rays[k]`. For callers with many rays
/// (`displace trace`, the Python binding), where one ray at a time leaves
/// the lanes idle.
///
/// Not generic, so that the tracer's loops are compiled once, here, and
/// every caller runs the same machine code (a closure argument would have
/// them compiled in each calling crate, under its own code generation).
///
/// # Panics
/// When `out` and `rays` differ in length.
pub fn intersect_many(
    face: Face<'_>,
    opts: &TraceOptions,
    rays: &[[f32; 7]],
    out: &mut [Option<PhysicalHit>],
) {
    assert_eq!(rays.len(), out.len());
    out.fill(None);
    let mut mapped = MappedRays::default();
    for (chunk, out) in rays.chunks(BATCH).zip(out.chunks_mut(BATCH)) {
        let m = mapped.of(face, opts, chunk);
        crate::cell_trace::trace_each(face.height, face.distance, m.rays(), m.opts(), |k, h| {
            out[k] = Some(physical_hit(face, &h, m.lens[k]))
        });
    }
}

/// [`occluded`] of every ray of `rays` (each checked) into `out`, traced
/// in packets as [`intersect_many`]'s: `out[k]` is exactly
/// `occluded(face, opts, &rays[k])`.
///
/// # Panics
/// When `out` and `rays` differ in length.
pub fn occluded_many(face: Face<'_>, opts: &TraceOptions, rays: &[[f32; 7]], out: &mut [bool]) {
    assert_eq!(rays.len(), out.len());
    let mut mapped = MappedRays::default();
    for (chunk, out) in rays.chunks(BATCH).zip(out.chunks_mut(BATCH)) {
        let m = mapped.of(face, opts, chunk);
        crate::cell_trace::occluded_many(face.height, face.distance, m.rays(), m.opts(), out);
    }
}

/// [`occluded_many`] answered over a maximum-height pyramid of the face's
/// heights ([`crate::cell_trace::occluded_over`]), one ray at a time: for
/// rays that run low over the surface for long (lines of sight over an
/// elevation model), whose distance-map steps stay short the whole way.
/// `out[k]` is `occluded(face, opts, &rays[k])` but for rays that touch the
/// surface within rounding.
///
/// # Panics
/// When `out` and `rays` differ in length.
pub fn occluded_many_over(
    face: Face<'_>,
    pyramid: &crate::cell_trace::AnyHitPyramid,
    opts: &TraceOptions,
    rays: &[[f32; 7]],
    out: &mut [bool],
) {
    assert_eq!(rays.len(), out.len());
    for (ray, out) in rays.iter().zip(out) {
        let (mray, opts, _) = map_ray(face, opts, ray);
        *out = crate::cell_trace::occluded_over(face.height, face.distance, pyramid, &mray, &opts);
    }
}

/// One batch of physical rays as [`map_ray`] maps them, in the columns the
/// packet tracer reads. Fixed arrays on the stack, not vectors: the Python
/// binding calls [`intersect_many`] for every 64 rays, and three vectors
/// grown per call were a tenth of a query of misses on two threads, most
/// of it the allocator's lock contended between them.
struct MappedRays {
    rays: [MapRay; BATCH],
    opts: [TraceOptions; BATCH],
    /// Each direction's length as given.
    lens: [f32; BATCH],
    /// How many of the slots hold this batch.
    len: usize,
}

impl Default for MappedRays {
    fn default() -> Self {
        let ray = MapRay {
            origin: Vec3::ZERO,
            dir: Vec3::Z,
        };
        Self {
            rays: [ray; BATCH],
            opts: [TraceOptions::default(); BATCH],
            lens: [0.0; BATCH],
            len: 0,
        }
    }
}

impl MappedRays {
    /// `rays` (at most [`BATCH`]) mapped, in place of the batch before.
    fn of(&mut self, face: Face<'_>, opts: &TraceOptions, rays: &[[f32; 7]]) -> &Self {
        assert!(rays.len() <= BATCH, "a batch is at most {BATCH} rays");
        for (k, ray) in rays.iter().enumerate() {
            (self.rays[k], self.opts[k], self.lens[k]) = map_ray(face, opts, ray);
        }
        self.len = rays.len();
        self
    }

    /// The mapped rays.
    fn rays(&self) -> &[MapRay] {
        &self.rays[..self.len]
    }

    /// Each ray's options.
    fn opts(&self) -> &[TraceOptions] {
        &self.opts[..self.len]
    }
}

/// A map-space hit of a ray whose direction had length `len`, in physical
/// units.
#[inline]
fn physical_hit(face: Face<'_>, hit: &crate::sphere_trace::MapHit, len: f32) -> PhysicalHit {
    let sz = face.extent.sz;
    let (w, h) = (face.height.width(), face.height.height());
    let fract = |x: f32| x - x.floor();
    let (u, v) = (fract(hit.uv.x), fract(hit.uv.y));
    let i = ((u * w as f32) as usize).min(w - 1);
    let j = ((v * h as f32) as usize).min(h - 1);
    PhysicalHit {
        t: hit.t * sz / len,
        position: hit.position * sz,
        normal: hit.normal,
        uv: hit.uv,
        cell: (j * w + i) as u32,
        iterations: hit.iterations,
    }
}

/// Whether anything of `face`'s displaced solid lies on a checked physical
/// ray within `(0, t_max]`: the shadow-ray query
/// ([`DisplacementMap::occluded`]).
#[inline]
pub fn occluded(face: Face<'_>, opts: &TraceOptions, ray: &[f32; 7]) -> bool {
    let (mray, opts, _) = map_ray(face, opts, ray);
    crate::cell_trace::occluded(face.height, face.distance, &mray, &opts)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{bake, BakeOptions};

    #[test]
    fn the_predicate_and_the_messages_refuse_the_same_rays() {
        let specials = [
            0.0,
            -0.0,
            1.0,
            -2.5,
            1e-30,
            f32::MIN_POSITIVE,
            1e-45,
            MAX_RAY_COMPONENT,
            -MAX_RAY_COMPONENT,
            2e18,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let mut pick = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            specials[(state % specials.len() as u64) as usize]
        };
        let (mut valid, mut invalid) = (0, 0);
        for _ in 0..200_000 {
            let ray: [f32; 7] = std::array::from_fn(|_| pick());
            let ok = ray_is_valid(&ray);
            assert_eq!(ok, diagnose(String::new, &ray).is_ok(), "{ray:?}");
            assert_eq!(ok, check_ray(String::new, &ray).is_ok(), "{ray:?}");
            if ok {
                valid += 1;
            } else {
                invalid += 1;
            }
        }
        assert!(
            valid > 1000 && invalid > 1000,
            "{valid} valid, {invalid} refused"
        );
    }

    fn flat_map(level: f32) -> DisplacementMap {
        let height = HeightMap::new(8, 8, vec![level; 64], crate::Address::Clamp).unwrap();
        let extent = Extent::new(2.0, 2.0, 0.5).unwrap();
        bake(&height, &BakeOptions::new([8, 8, 4], extent)).unwrap()
    }

    #[test]
    fn a_flat_face_is_hit_at_its_level_in_the_units_of_the_direction() {
        let map = flat_map(0.5);
        // The surface lies at z = 0.5 * SZ = 0.25; a direction of length 2
        // halves the parameter.
        let ray = [0.7, 1.1, 1.25, 0.0, 0.0, -2.0, f32::INFINITY];
        check_ray(|| "ray".into(), &ray).unwrap();
        let face = Face::from(&map);
        let hit = intersect(face, &TraceOptions::default(), &ray).unwrap();
        assert!((hit.t - 0.5).abs() < 1e-5, "{hit:?}");
        assert!((hit.position - Vec3::new(0.7, 1.1, 0.25)).length() < 1e-5);
        assert!((hit.normal - Vec3::Z).length() < 1e-5);
        assert_eq!(hit.cell, 4 * 8 + 2);
        assert!(occluded(face, &TraceOptions::default(), &ray));
        // Stopped short of the surface by t_max, in the same units.
        let short = [0.7, 1.1, 1.25, 0.0, 0.0, -2.0, 0.49];
        assert!(intersect(face, &TraceOptions::default(), &short).is_none());
        assert!(!occluded(face, &TraceOptions::default(), &short));
    }

    /// Many rays at once (packets) are each the one-ray query, bit for
    /// bit: first hits (every field), misses and any-hit answers, on a
    /// bumpy clamped face, with limits that cut some rays short, rays of
    /// unnormalised directions, from above, the sides and under the surface,
    /// in batches whose lengths are not multiples of a packet.
    #[test]
    fn many_rays_answer_as_one_ray_each() {
        let height =
            crate::generators::generate("gen:gaussian", 64, 48, crate::Address::Clamp).unwrap();
        let extent = Extent::new(2.0, 1.5, 0.4).unwrap();
        let map = bake(&height, &BakeOptions::new([32, 24, 8], extent)).unwrap();
        let face = Face::from(&map);
        let opts = TraceOptions::default();
        let mut rng = crate::random::SplitMix64::new(7);
        let (mut hits, mut blocked) = (0, 0);
        for n in [1usize, 7, 8, 63, 64, 65, 700] {
            let rays: Vec<[f32; 7]> = (0..n)
                .map(|_| {
                    let o = [
                        rng.range(-0.5, 2.5),
                        rng.range(-0.5, 2.0),
                        rng.range(-0.1, 0.8),
                    ];
                    let target = [
                        rng.range(0.0, 2.0),
                        rng.range(0.0, 1.5),
                        rng.range(0.0, 0.4),
                    ];
                    let s = rng.range(0.2, 3.0);
                    let d = [0, 1, 2].map(|a| (target[a] - o[a]) * s);
                    let t_max = if rng.next_f32() < 0.3 {
                        rng.range(0.05, 1.0) / s
                    } else {
                        f32::INFINITY
                    };
                    [o[0], o[1], o[2], d[0], d[1], d[2], t_max]
                })
                .filter(ray_is_valid)
                .collect();
            let mut many: Vec<Option<PhysicalHit>> = vec![None; rays.len()];
            intersect_many(face, &opts, &rays, &mut many);
            let mut any = vec![false; rays.len()];
            occluded_many(face, &opts, &rays, &mut any);
            for (k, ray) in rays.iter().enumerate() {
                let one = intersect(face, &opts, ray);
                assert_eq!(
                    format!("{:?}", many[k]),
                    format!("{one:?}"),
                    "ray {k} of {n}"
                );
                assert_eq!(any[k], occluded(face, &opts, ray), "ray {k} of {n}");
                hits += usize::from(one.is_some());
                blocked += usize::from(any[k]);
            }
        }
        assert!(
            hits > 200 && blocked > 200,
            "{hits} hits, {blocked} blocked"
        );
    }

    #[test]
    fn bad_rays_are_named() {
        let msg = |r: [f32; 7]| check_ray(|| "ray 3".into(), &r).unwrap_err().to_string();
        assert!(msg([0.0, f32::NAN, 0.0, 0.0, 0.0, 1.0, 1.0]).contains("NaN in column 1"));
        assert!(msg([0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]).contains("no length"));
        assert!(msg([0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]).contains("t_max 0"));
        assert!(msg([0.0, 0.0, 2e18, 0.0, 0.0, 1.0, 1.0]).contains("column 2"));
    }
}
