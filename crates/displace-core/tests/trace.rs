//! The tracer against the exact reference on random rays and random maps.

mod common_ref;

use common_ref::{bake_map, downward, face_case, random_face, random_height, Rng};
use displace_core::sphere_trace::HitKind;
use displace_core::{Address, MapRay, Method, TraceOptions};
use glam::Vec3;
use proptest::prelude::*;

/// A ray from above the shell towards a random point of the face, at a
/// random elevation (grazing ones included).
fn random_ray(rng: &mut Rng, extent: [f32; 2]) -> MapRay {
    let target = Vec3::new(
        rng.next_f64() as f32 * extent[0],
        rng.next_f64() as f32 * extent[1],
        rng.next_f64() as f32,
    );
    let elevation = (2.0 + rng.next_f64() * 88.0).to_radians() as f32;
    let azimuth = (rng.next_f64() * std::f64::consts::TAU) as f32;
    let dir = downward(elevation, azimuth);
    MapRay::new(target - dir * 3.0, dir)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(displace_core::random::property_cases(40)))]

    #[test]
    fn sphere_tracing_finds_the_exact_hit(
        face in face_case(24, 12),
        seed in any::<u64>(),
    ) {
        let (map, tiles, span) = random_face(&face, seed);
        let mut rng = Rng(seed ^ 0x9e37_79b9_7f4a_7c15);
        let exact_opts = TraceOptions { method: Method::Exact, tiles, ..TraceOptions::default() };
        let mut agree = 0;
        let mut hits = 0;
        let n = 64;
        for _ in 0..n {
            let ray = random_ray(&mut rng, span);
            let exact = map.trace(&ray, &exact_opts);
            let sphere = map.trace(&ray, &TraceOptions { method: Method::Sphere, tiles, ..TraceOptions::default() });
            match (exact, sphere) {
                (Some(e), Some(s)) => {
                    prop_assert!((e.t - s.t).abs() <= 1e-3, "exact t {} sphere t {} ray {ray:?}", e.t, s.t);
                    prop_assert!((e.position - s.position).length() <= 1e-3);
                    agree += 1;
                    hits += 1;
                }
                (None, None) => agree += 1,
                (e, s) => prop_assert!(false, "hit/miss disagree: exact {e:?} sphere {s:?} ray {ray:?}"),
            }
            // The GPU-mirroring trilinear loop (`displace compare`'s and
            // the WGSL tracer's) finds the same hit.
            let (mirror, _) = map.trace_counted(&ray, &TraceOptions { method: Method::Sphere, tiles, ..TraceOptions::default() });
            prop_assert_eq!(mirror.is_some(), exact.is_some(), "trilinear loop {:?} exact {:?}", mirror, exact);
            if let (Some(e), Some(m)) = (exact, mirror) {
                prop_assert!((e.t - m.t).abs() <= 1e-3, "exact t {} trilinear t {}", e.t, m.t);
            }
            // The any-hit query over a random stretch of the ray agrees with
            // the first hit (away from the stretch's ends, where rounding
            // may decide either way).
            let t_max = rng.next_f64() as f32 * 8.0;
            let blocked = map.occluded(&ray, &TraceOptions { tiles, t_max, ..TraceOptions::default() });
            if let Some(e) = exact {
                if (e.t - t_max).abs() > 1e-3 {
                    prop_assert_eq!(blocked, e.t < t_max, "any-hit {} exact t {} t_max {}", blocked, e.t, t_max);
                }
            } else {
                prop_assert!(!blocked, "any-hit blocked where the exact walk misses: {ray:?}");
            }
            // A shadow ray: from just above an exact hit, towards a random
            // direction of the upper half space.
            if let Some(e) = exact.filter(|e| e.kind == HitKind::Surface) {
                let up = Vec3::new(rng.next_f64() as f32 - 0.5, rng.next_f64() as f32 - 0.5, rng.next_f64() as f32 + 0.05);
                let shadow = MapRay::new(e.position + e.normal * 1e-3, up);
                let first = map.trace(&shadow, &exact_opts);
                let any = map.occluded(&shadow, &TraceOptions { tiles, ..TraceOptions::default() });
                prop_assert_eq!(any, first.is_some(), "shadow ray {:?}: any-hit {} exact {:?}", shadow, any, first);
            }
            // Donnelly's fixed loop, any step count, never passes the hit.
            let steps = 1 + (rng.next_f64() * 24.0) as u32;
            let fixed = map.trace(&ray, &TraceOptions { method: Method::SphereFixed, iterations: steps, tiles, ..TraceOptions::default() });
            if let (Some(e), Some(f)) = (exact, fixed) {
                prop_assert!(f.t <= e.t + 1e-4, "fixed loop ({steps} steps) passed the surface: {} > {}", f.t, e.t);
                if f.converged {
                    prop_assert!((f.t - e.t).abs() <= 1e-3);
                }
            }
        }
        prop_assert_eq!(agree, n);
        // Rays aim at the face from above: most of them must hit something.
        prop_assert!(hits >= n / 2, "only {hits} of {n} rays hit");
    }
}

#[test]
fn rays_entering_below_the_surface_hit_the_wall() {
    let height = displace_core::HeightMap::new(8, 8, vec![1.0; 64], Address::Clamp).unwrap();
    let map = bake_map(&height, [8, 8, 4], [1.0, 1.0, 0.5]);
    // From the side, at half height: the slab's wall at x = 0.
    let ray = MapRay::new(Vec3::new(-1.0, 1.0, 0.5), Vec3::X);
    let hit = map.trace(&ray, &TraceOptions::default()).unwrap();
    assert_eq!(hit.kind, HitKind::Wall);
    assert!((hit.t - 1.0).abs() < 1e-6);
    assert_eq!(hit.normal, -Vec3::X);
    // Above the slab, leaving through the far side: a miss.
    let ray = MapRay::new(Vec3::new(-1.0, 1.0, 1.0 + 1e-3), Vec3::new(1.0, 0.0, -1e-4));
    assert!(map.trace(&ray, &TraceOptions::default()).is_none());
}

#[test]
fn thin_features_are_not_stepped_over() {
    // One raised texel line in a flat map: a fixed-step march at grazing
    // angles jumps over it (Donnelly, fig. 8-2); sphere tracing may not.
    let n = 64;
    let data: Vec<f32> = (0..n * n)
        .map(|k| if k % n == 40 { 1.0 } else { 0.0 })
        .collect();
    let height = displace_core::HeightMap::new(n, n, data, Address::Clamp).unwrap();
    let map = bake_map(&height, [64, 64, 8], [1.0, 1.0, 0.05]);
    let aspect = map.aspect();
    let mut hits = 0;
    for k in 0..50 {
        let y = (k as f32 + 0.5) / 50.0 * aspect[1];
        let ray = MapRay::new(Vec3::new(0.0, y, 0.9), Vec3::new(1.0, 0.0, -0.02));
        let e = map
            .trace(
                &ray,
                &TraceOptions {
                    method: Method::Exact,
                    ..TraceOptions::default()
                },
            )
            .unwrap();
        let s = map.trace(&ray, &TraceOptions::default()).unwrap();
        assert!((e.t - s.t).abs() < 1e-3);
        // The wall of the line is at u = 40.5/64 - 1/64 .. the peak.
        assert!(
            e.position.x / aspect[0] > 39.0 / 64.0 && e.position.x / aspect[0] < 41.0 / 64.0,
            "{e:?}"
        );
        hits += 1;
    }
    assert_eq!(hits, 50);
}

/// Rays aimed at the floor of a two-level map meet the surface exactly on
/// the shell's bottom face, at the shell's exit parameter: a hit that single
/// precision puts a hair beyond the segment must still count.
#[test]
fn hits_on_the_shell_floor_are_found() {
    let n = 64;
    let data: Vec<f32> = (0..n * n)
        .map(|k| {
            if ((k % n) / 8 + (k / n) / 8) % 2 == 0 {
                1.0
            } else {
                0.0
            }
        })
        .collect();
    let height = displace_core::HeightMap::new(n, n, data, Address::Clamp).unwrap();
    let map = bake_map(&height, [64, 64, 8], [1.0, 1.0, 0.1]);
    let aspect = map.aspect();
    let mut rng = Rng(99);
    for _ in 0..20_000 {
        let target = Vec3::new(
            rng.next_f64() as f32 * aspect[0],
            rng.next_f64() as f32 * aspect[1],
            0.0,
        );
        let elevation = (5.0 + rng.next_f64() * 85.0).to_radians() as f32;
        let azimuth = (rng.next_f64() * std::f64::consts::TAU) as f32;
        let dir = downward(elevation, azimuth);
        let ray = MapRay::new(target - dir * (1.2 / elevation.sin()), dir);
        for method in [Method::Exact, Method::Sphere] {
            assert!(
                map.trace(
                    &ray,
                    &TraceOptions {
                        method,
                        ..TraceOptions::default()
                    }
                )
                .is_some(),
                "{method:?} missed {ray:?}"
            );
        }
    }
}

/// With a map eight times coarser than its height map, the tracer still
/// finds the exact hit on the full-resolution heights (it refines on them;
/// the coarse map only bounds the steps).
#[test]
fn a_coarse_map_traces_the_full_resolution_surface() {
    for kind in 0..3u8 {
        let height = random_height(kind, 64, 64, 5 + kind as u64, Address::Clamp);
        let map = bake_map(&height, [8, 8, 4], [1.0, 1.0, 0.1]);
        let aspect = map.aspect();
        let mut rng = Rng(17 + kind as u64);
        let mut hits = 0;
        for _ in 0..200 {
            let ray = random_ray(&mut rng, aspect);
            let exact = map.trace(
                &ray,
                &TraceOptions {
                    method: Method::Exact,
                    ..TraceOptions::default()
                },
            );
            let sphere = map.trace(
                &ray,
                &TraceOptions {
                    method: Method::Sphere,
                    ..TraceOptions::default()
                },
            );
            match (exact, sphere) {
                (Some(e), Some(s)) => {
                    assert!(
                        (e.t - s.t).abs() <= 1e-3,
                        "kind {kind}: exact t {} sphere t {}",
                        e.t,
                        s.t
                    );
                    hits += 1;
                }
                (None, None) => {}
                (e, s) => panic!("kind {kind}: exact {e:?} sphere {s:?} ray {ray:?}"),
            }
        }
        assert!(hits >= 100, "kind {kind}: only {hits} of 200 rays hit");
    }
}

/// A repeating map tiled over more height cells than the walk's single
/// precision steps is refused by the map's check, which every scene face
/// and `trace` command passes through (a walk 2^24 cells from its ray's
/// origin no longer moves a cell at a time: such a displaced mesh hung the
/// renderer), and the limit itself is accepted.
#[test]
fn tiles_spanning_more_cells_than_the_walk_counts_are_refused() {
    let n = 64;
    let heights = common_ref::random_height(0, n, n, 3, Address::Repeat);
    let map = bake_map(&heights, [16, 16, 4], [1.0, 1.0, 0.05]);
    let tiled = |x: f32, y: f32| TraceOptions {
        tiles: [x, y],
        ..TraceOptions::default()
    };
    let err = map.check_trace(&tiled(7.0e4, 1.0)).unwrap_err().to_string();
    assert!(err.contains("4480000 x 64 height cells"), "{err}");
    // 2^20 cells a side: 16384 tiles of 64 texels.
    map.check_trace(&tiled(16384.0, 16384.0)).unwrap();
    assert!(map.check_trace(&tiled(16385.0, 1.0)).is_err());
    assert!(map.check_trace(&tiled(1.0, 16385.0)).is_err());
}
