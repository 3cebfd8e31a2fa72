//! The any-hit query over the maximum-height pyramid
//! (`cell_trace::occluded_over`) against the distance-map tracer's
//! (`cell_trace::occluded`) on random maps and rays, grazing ones and
//! shadow rays from the surface included: the same answer, except on a ray
//! that touches the surface within rounding (a ridge grazed to 1e-7), which
//! either may call blocked or clear as the cell boundaries of its walks
//! round; there the two must disagree only because the ray touches, which
//! the test shows by moving it: lifted a little it is clear, lowered a
//! little it is blocked.

mod common_ref;

use common_ref::{downward, face_case, random_face, Rng};
use displace_core::cell_trace::{occluded, occluded_over, AnyHitPyramid};
use displace_core::sphere_trace::HitKind;
use displace_core::{MapRay, Method, TraceOptions};
use glam::Vec3;
use proptest::prelude::*;

/// A ray of one of the kinds an any-hit query meets, in a shell of
/// `span`: from above towards the face (any elevation), grazing from a
/// point just over or on the surface (a line of sight over terrain), or
/// from anywhere in the slab in any direction.
fn random_ray(rng: &mut Rng, span: [f32; 2], surface: impl Fn(f32, f32) -> f32) -> MapRay {
    let x = rng.next_f64() as f32 * span[0];
    let y = rng.next_f64() as f32 * span[1];
    let azimuth = (rng.next_f64() * std::f64::consts::TAU) as f32;
    match rng.next_f64() {
        k if k < 0.35 => {
            let target = Vec3::new(x, y, rng.next_f64() as f32);
            let elevation = (0.5 + rng.next_f64() * 89.0).to_radians() as f32;
            let dir = downward(elevation, azimuth);
            MapRay::new(target - dir * 3.0, dir)
        }
        k if k < 0.8 => {
            // Within a few degrees of horizontal, up or down, from a
            // ten-thousandth to a hundredth of the depth above the surface.
            // Not from on it: a ray from a surface point is blocked at its
            // start to the exact walk (and to the pyramid, which walks
            // from there) while the distance map's first step may carry it
            // past (either is right within rounding; shadow rays start off
            // the surface, as the renderer's do).
            let lift = 1e-4 + rng.next_f64() as f32 * 1e-2;
            let elevation = ((rng.next_f64() - 0.3) * 6.0).to_radians() as f32;
            let dir = -downward(elevation, azimuth);
            MapRay::new(Vec3::new(x, y, surface(x, y) + lift), dir)
        }
        _ => {
            let dir = Vec3::new(
                rng.next_f64() as f32 - 0.5,
                rng.next_f64() as f32 - 0.5,
                rng.next_f64() as f32 - 0.5,
            );
            MapRay::new(Vec3::new(x, y, rng.next_f64() as f32), dir)
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(displace_core::random::property_cases(40)))]

    #[test]
    fn the_pyramid_answers_every_any_hit_query_as_the_distance_map_does(
        face in face_case(40, 12),
        seed in any::<u64>(),
    ) {
        let (map, tiles, _) = random_face(&face, seed);
        let pyramid = AnyHitPyramid::build(&map.height);
        let aspect = map.aspect();
        let surface = |x: f32, y: f32| map.height.sample(x / aspect[0], y / aspect[1]);
        let mut rng = Rng(seed ^ 0x2545_f491_4f6c_dd1d);
        let mut blocked = 0;
        let mut touching = 0;
        let n = 200;
        for _ in 0..n {
            // One tile, where the pyramid answers (a repeating map's
            // pyramid wraps as its heights do); the face's own tiles too,
            // which the pyramid hands to the distance map.
            let ray = random_ray(&mut rng, aspect, surface);
            let t_max = if rng.next_f64() < 0.5 { f32::INFINITY } else { rng.next_f64() as f32 * 4.0 };
            let iterations = if rng.next_f64() < 0.2 { 1 + (rng.next_f64() * 8.0) as u32 } else { TraceOptions::default().iterations };
            for tiles in [[1.0, 1.0], tiles] {
                let opts = TraceOptions { tiles, t_max, iterations, ..TraceOptions::default() };
                let want = occluded(&map.height, &map.distance, &ray, &opts);
                let got = occluded_over(&map.height, &map.distance, &pyramid, &ray, &opts);
                if got != want {
                    prop_assert!(touches(&map, &ray, &opts), "ray {:?}, t_max {}, tiles {:?}: pyramid {} distance map {}", ray, t_max, tiles, got, want);
                    touching += 1;
                }
                blocked += usize::from(want);
            }
            // A shadow ray from just above an exact hit.
            let opts = TraceOptions { method: Method::Exact, ..TraceOptions::default() };
            if let Some(e) = map.trace(&ray, &opts).filter(|e| e.kind == HitKind::Surface) {
                let up = Vec3::new(rng.next_f64() as f32 - 0.5, rng.next_f64() as f32 - 0.5, rng.next_f64() as f32 + 0.02);
                let shadow = MapRay::new(e.position + e.normal * 1e-3, up);
                let opts = TraceOptions::default();
                let got = occluded_over(&map.height, &map.distance, &pyramid, &shadow, &opts);
                if got != occluded(&map.height, &map.distance, &shadow, &opts) {
                    prop_assert!(touches(&map, &shadow, &opts), "shadow ray {:?}: pyramid {}", shadow, got);
                    touching += 1;
                }
            }
        }
        // Both answers occur: the comparison is not of misses alone.
        prop_assert!(blocked > 0 && blocked < 2 * n, "{blocked} of {} blocked", 2 * n);
        // Touching rays are rare: a handful in many thousands.
        prop_assert!(touching <= 2, "{touching} touching rays of {}", 3 * n);
    }
}

/// Whether `ray` touches the surface within rounding: clear when lifted
/// by a ten-thousandth of the depth, blocked when lowered by as much (to
/// the distance-map tracer).
fn touches(map: &displace_core::DisplacementMap, ray: &MapRay, opts: &TraceOptions) -> bool {
    let moved = |dz: f32| MapRay::new(ray.origin + Vec3::Z * dz, ray.dir);
    !occluded(&map.height, &map.distance, &moved(1e-4), opts)
        && occluded(&map.height, &map.distance, &moved(-1e-4), opts)
}

/// A pyramid of another map's size is not read: the distance map answers.
#[test]
fn a_pyramid_of_another_map_is_not_used() {
    let (map, _, _) = random_face(&face_of(16), 7);
    let (other, _, _) = random_face(&face_of(9), 7);
    let pyramid = AnyHitPyramid::build(&other.height);
    let ray = MapRay::new(Vec3::new(0.3, 0.2, 2.0), Vec3::new(0.1, 0.05, -1.0));
    let opts = TraceOptions::default();
    assert_eq!(
        occluded_over(&map.height, &map.distance, &pyramid, &ray, &opts),
        occluded(&map.height, &map.distance, &ray, &opts)
    );
}

fn face_of(side: usize) -> common_ref::FaceCase {
    common_ref::FaceCase {
        kind: 1,
        height: [side, side],
        size: [side, side, 8],
        scale: [1.0, 0.3],
        repeat: false,
    }
}
