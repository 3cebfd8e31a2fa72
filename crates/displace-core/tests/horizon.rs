//! The horizon bounds (`displace_core::horizon`) against the surface they
//! bound, and the any-hit queries that use them against the exact walk.

mod common_ref;

use common_ref::{bake_map, random_height, Rng};
use displace_core::horizon::HorizonMap;
use displace_core::sphere_trace::HitKind;
use displace_core::{Address, HeightMap, MapRay, Method, TraceOptions};
use glam::Vec3;
use proptest::prelude::*;

/// Random heights of the kinds the tracer's tests use (white noise,
/// two-level studs, smooth waves), and a fourth: a few smooth round hills,
/// the field horizons are for.
fn heights(kind: u8, w: usize, h: usize, seed: u64, address: Address) -> HeightMap {
    if kind % 4 < 3 {
        return random_height(kind, w, h, seed, address);
    }
    let mut rng = Rng(seed | 1);
    let hills: Vec<[f64; 4]> = (0..1 + (rng.next_f64() * 4.0) as usize)
        .map(|_| {
            [
                rng.next_f64(),
                rng.next_f64(),
                0.05 + 0.3 * rng.next_f64(),
                rng.next_f64(),
            ]
        })
        .collect();
    let data = (0..w * h)
        .map(|k| {
            let x = (k % w) as f64 / w as f64;
            let y = (k / w) as f64 / h as f64;
            let z: f64 = hills
                .iter()
                .map(|[cx, cy, r, a]| a * (-((x - cx).powi(2) + (y - cy).powi(2)) / (r * r)).exp())
                .sum();
            z.min(1.0) as f32
        })
        .collect();
    HeightMap::new(w, h, data, address).unwrap()
}

/// The surface's height at cell coordinates `(x, y)` (texel centres at
/// integers), as the tracer reads it.
fn surface(height: &HeightMap, x: f64, y: f64) -> f64 {
    let u = (x + 0.5) / height.width() as f64;
    let v = (y + 0.5) / height.height() as f64;
    height.sample(u as f32, v as f32) as f64
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(displace_core::random::property_cases(48)))]

    /// Every ray the bounds clear, from a random point on or just over the
    /// surface in any direction and at any slope, stays over the surface,
    /// checked every fiftieth of a cell to the edge of the map; on the
    /// smooth kinds, some rays are cleared.
    #[test]
    fn a_cleared_ray_stays_over_the_surface(
        kind in 0u8..4,
        w in 2usize..40,
        h in 2usize..40,
        repeat in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let address = if repeat { Address::Repeat } else { Address::Clamp };
        let height = heights(kind, w, h, seed, address);
        let horizon = HorizonMap::build(&height).expect("a small map gets its bounds");
        let mut rng = Rng(seed ^ 0x5bd1_e995);
        let (mut cleared, tries) = (0, 400);
        for _ in 0..tries {
            let x = -0.5 + rng.next_f64() * w as f64;
            let y = -0.5 + rng.next_f64() * h as f64;
            let lift = if rng.next_f64() < 0.5 { 0.0 } else { 0.01 * rng.next_f64() };
            let z = surface(&height, x, y) + lift;
            let azimuth = rng.next_f64() * std::f64::consts::TAU;
            let slope = 2.0 * rng.next_f64().powi(2);
            let (dx, dy) = (azimuth.cos(), azimuth.sin());
            if !horizon.clears(x as f32, y as f32, dx as f32, dy as f32, slope as f32) {
                continue;
            }
            cleared += 1;
            // To where the ray leaves the map's box.
            let reach = |o: f64, d: f64, n: usize| {
                if d > 0.0 { (n as f64 - 0.5 - o) / d } else if d < 0.0 { (-0.5 - o) / d } else { f64::INFINITY }
            };
            let end = reach(x, dx, w).min(reach(y, dy, h));
            let mut r = 0.0;
            while r <= end {
                let ground = surface(&height, x + r * dx, y + r * dy);
                prop_assert!(
                    z + slope * r >= ground - 1e-5,
                    "cleared ray under the surface: from ({x}, {y}, {z}) azimuth {azimuth} slope {slope}: at {r} cells the ray is at {} and the surface at {ground}",
                    z + slope * r
                );
                r += 0.02;
            }
        }
        if kind % 4 >= 2 {
            prop_assert!(cleared > 0, "no ray of {tries} cleared on a smooth map");
        }
    }

    /// Shadow rays from the surface on smooth faces whose bounds the
    /// tracer uses: the any-hit answer, one ray at a time and in packets,
    /// is the exact walk's first hit, as it is without the bounds.
    #[test]
    fn any_hit_queries_with_horizons_are_the_exact_walk(
        kind in 2u8..4,
        w in 4usize..40,
        h in 4usize..40,
        seed in any::<u64>(),
    ) {
        let height = heights(kind, w, h, seed, Address::Clamp);
        let without = bake_map(&height, [16, 16, 8], [2.0, 1.5, 0.03]);
        let with = without.clone();
        // The tracer keeps and tests the bounds where rays rising at 45
        // degrees clear a quarter of them at least: on this shallow face
        // they do, but for the steepest waves on the fewest texels.
        let per_cell = with.aspect()[0] / w as f32;
        let bounds = with.prepare_horizon();
        prop_assume!(bounds.is_some(), "waves too steep for bounds that pay");
        let share = bounds.map_or(0.0, |b| b.share_cleared_at(per_cell));
        prop_assert!(share >= 0.25, "share {}", share);
        prop_assert!(without.height.horizon().is_none());
        let mut rng = Rng(seed ^ 0x2545_f491);
        let aspect = with.aspect();
        let exact = TraceOptions { method: Method::Exact, ..TraceOptions::default() };
        let mut rays = Vec::new();
        while rays.len() < 96 {
            let target = Vec3::new(rng.next_f64() as f32 * aspect[0], rng.next_f64() as f32 * aspect[1], 0.0);
            let down = Vec3::new(rng.next_f64() as f32 - 0.5, rng.next_f64() as f32 - 0.5, -1.0);
            let Some(hit) = with.trace(&MapRay::new(target - down * 2.0, down), &exact) else { continue };
            if hit.kind != HitKind::Surface {
                continue;
            }
            let up = Vec3::new(rng.next_f64() as f32 - 0.5, rng.next_f64() as f32 - 0.5, rng.next_f64() as f32 * 0.6 + 0.02);
            let lift = [0.0, 1e-4, 1e-3][rays.len() % 3];
            rays.push(MapRay::new(hit.position + hit.normal * lift, up));
        }
        let opts = vec![TraceOptions::default(); rays.len()];
        let mut packets = vec![false; rays.len()];
        with.occluded_many(&rays, &opts, &mut packets);
        for (ray, &packet) in rays.iter().zip(&packets) {
            let one = with.occluded(ray, &TraceOptions::default());
            let before = without.occluded(ray, &TraceOptions::default());
            let first = with.trace(ray, &exact);
            prop_assert_eq!(one, packet, "one ray and packet differ on {:?}", ray);
            prop_assert_eq!(one, before, "bounds changed the answer on {:?}: exact {:?}", ray, first);
            // A ray that touches the surface where it starts (the exact
            // walk's root at its very start) is blocked or clear as rounding
            // decides; every other answer is the exact walk's.
            if first.is_some_and(|f| f.t <= 1e-3) {
                continue;
            }
            prop_assert_eq!(one, first.is_some(), "any-hit {} on {:?}: exact {:?}", one, ray, first);
        }
    }
}

/// The bounds' share of cleared sectors: few on a field of sheer steps
/// (which keeps none), all of them on a flat one (every rise is zero
/// there), and a ray straight up clears every cell of any map.
#[test]
fn flat_fields_clear_everything_and_steps_nothing_sloped() {
    let flat = HeightMap::new(8, 8, vec![0.5; 64], Address::Clamp).unwrap();
    let bounds = HorizonMap::build(&flat).unwrap();
    assert_eq!(bounds.share_cleared_at(1e-6), 1.0);
    assert!(bounds.clears(3.2, 4.1, 0.3, 0.7, 1e-3));
    let studs = random_height(1, 16, 16, 3, Address::Clamp);
    let bounds = HorizonMap::build(&studs).unwrap();
    assert!(
        bounds.share_cleared_at(0.2) < 0.2,
        "{}",
        bounds.share_cleared_at(0.2)
    );
    // Busy maps keep no bounds (they would cost every ray and answer none),
    // and are judged so before the build.
    let noise = random_height(0, 96, 96, 5, Address::Clamp);
    assert!(!HorizonMap::could_pay(&noise, 0.01));
    assert!(noise.prepare_horizon(0.01).is_none());
    assert!(HorizonMap::could_pay(&flat, 0.2));
    assert!(studs.prepare_horizon(0.2).is_none());
    assert!(studs.horizon().is_none());
    assert!(flat.prepare_horizon(0.2).is_some());
    for (x, y) in [(0.2, 0.3), (7.5, 7.5), (14.9, 2.0)] {
        assert!(bounds.clears(x, y, 0.0, 0.0, 1.0));
        assert!(
            !bounds.clears(x, y, 0.3, 0.4, -0.1),
            "a falling ray is never cleared"
        );
    }
}

/// Rays that enter a face with bounds from below its floor or through its
/// sides, where the surface lies on the floor (a hill on a flat plain): the
/// any-hit answer is the first-hit query's, so a ray crossing the surface
/// where it enters is blocked. (The bounds once cleared such rays, which
/// start on the surface, found by the Python tests' rays from around a
/// Cornell box with a gaussian floor.)
#[test]
fn rays_entering_where_the_surface_lies_on_the_floor_are_blocked() {
    let (w, h) = (48, 40);
    let data = (0..w * h)
        .map(|k| {
            let (x, y) = (
                (k % w) as f64 / w as f64 - 0.5,
                (k / w) as f64 / h as f64 - 0.5,
            );
            let z = (-(x * x + y * y) / 0.02).exp();
            if z < 1e-3 {
                0.0
            } else {
                z as f32
            }
        })
        .collect();
    let height = HeightMap::new(w, h, data, Address::Clamp).unwrap();
    let map = bake_map(&height, [24, 20, 8], [2.0, 1.5, 0.1]);
    let aspect = map.aspect();
    assert!(map.prepare_horizon().is_some());
    let mut rng = Rng(11);
    let (mut blocked, mut checked) = (0, 0);
    for k in 0..4000 {
        let target = Vec3::new(
            rng.next_f64() as f32 * aspect[0],
            rng.next_f64() as f32 * aspect[1],
            rng.next_f64() as f32 * 0.5,
        );
        let origin = match k % 3 {
            // From under the floor.
            0 => {
                target
                    + Vec3::new(
                        rng.next_f64() as f32 - 0.5,
                        rng.next_f64() as f32 - 0.5,
                        -1.0,
                    )
            }
            // From outside a side wall, low.
            1 => Vec3::new(-0.5, target.y, target.z * 0.2),
            _ => Vec3::new(aspect[0] + 0.5, target.y, target.z * 0.2),
        };
        let ray = MapRay::new(origin, target - origin);
        let opts = TraceOptions {
            t_max: 1.0,
            ..TraceOptions::default()
        };
        let first = map.trace(&ray, &opts);
        let any = map.occluded(&ray, &opts);
        assert_eq!(
            any,
            first.is_some(),
            "{ray:?}: any-hit {any}, first hit {first:?}"
        );
        blocked += usize::from(any);
        checked += 1;
    }
    assert!(
        blocked > checked / 10,
        "only {blocked} of {checked} blocked"
    );
}

/// A ray the exploration found (kind 2 waves, 28 x 21 texels, on a face 2
/// wide and 0.03 deep): it starts where the patch solve has it on the
/// surface, and the single-precision height sample, off by its
/// coordinates' rounding times the steep slope, had it 5e-6 over it. The
/// bounds must leave it to the trace, which finds it blocked at its start.
#[test]
fn a_ray_on_a_steep_surface_by_the_solve_is_left_to_the_trace() {
    let height = heights(2, 28, 21, 17981517361609617048, Address::Clamp);
    let without = bake_map(&height, [16, 16, 8], [2.0, 1.5, 0.03]);
    let with = without.clone();
    assert!(with.prepare_horizon().is_some());
    let ray = MapRay::new(
        Vec3::new(64.35247, 22.91942, 0.5059476),
        Vec3::new(-0.8508552, 0.32465336, 0.4130928),
    );
    let opts = TraceOptions::default();
    assert!(without.occluded(&ray, &opts));
    assert_eq!(with.occluded(&ray, &opts), without.occluded(&ray, &opts));
}

/// A flat floor with studs on it (disks one height tall, radius 4, every
/// 16 cells): most of its cells are flat around them, so their own 3x3
/// neighbourhood says nothing, yet every wedge reaches a stud and the
/// built bounds would clear a 45-degree ray in under a fifth of the cells
/// and sectors. The pre-check's marches across the wedges see the studs and
/// spare the build; a smooth hill, whose bounds pay, is still built.
#[test]
fn a_floor_between_studs_is_judged_busy_before_the_build() {
    let n = 128;
    let stud = |x: usize, y: usize| {
        let (dx, dy) = ((x % 16) as f32 - 8.0, (y % 16) as f32 - 8.0);
        if dx * dx + dy * dy <= 16.0 {
            1.0
        } else {
            0.0
        }
    };
    let studs = HeightMap::new(
        n,
        n,
        (0..n * n).map(|k| stud(k % n, k / n)).collect(),
        Address::Clamp,
    )
    .unwrap();
    let rise = 0.05;
    let flat_around = (1..n - 1)
        .flat_map(|y| (1..n - 1).map(move |x| (x, y)))
        .filter(|&(x, y)| (0..3).all(|j| (0..3).all(|i| stud(x + i - 1, y + j - 1) == stud(x, y))))
        .count();
    assert!(flat_around > n * n / 2, "{flat_around} locally flat cells");
    let built = HorizonMap::build(&studs).unwrap();
    assert!(
        built.share_cleared_at(rise) < 0.2,
        "{}",
        built.share_cleared_at(rise)
    );
    assert!(!HorizonMap::could_pay(&studs, rise));
    assert!(studs.prepare_horizon(rise).is_none());

    let hill = HeightMap::new(
        n,
        n,
        (0..n * n)
            .map(|k| {
                let (x, y) = (
                    (k % n) as f32 / n as f32 - 0.5,
                    (k / n) as f32 / n as f32 - 0.5,
                );
                (-(x * x + y * y) * 8.0).exp()
            })
            .collect(),
        Address::Clamp,
    )
    .unwrap();
    assert!(HorizonMap::build(&hill).unwrap().pays_at(rise));
    assert!(HorizonMap::could_pay(&hill, rise));
    assert!(hill.prepare_horizon(rise).is_some());
}
