//! The packet tracer (eight or sixteen rays at a time, each kernel the CPU
//! runs forced in turn) against the scalar one: every
//! ray's first hit and any-hit answer are the same, bit for bit, whatever
//! the packet's other rays do (mixed starts, directions, ranges, methods
//! and budgets in one packet, and packets cut short).

mod common_ref;

use common_ref::{face_case, random_face, Rng};
use displace_core::cell_trace::{with_kernel, Kernel};
use displace_core::{MapRay, Method, TraceOptions};
use glam::Vec3;
use proptest::prelude::*;

/// A ray of one of the kinds the renderer casts: from above towards the
/// face (camera rays, grazing ones included), from inside the shell in any
/// direction (shadow and reflection rays leave the surface), or from beside
/// the shell through its walls.
fn random_ray(rng: &mut Rng, span: [f32; 2]) -> MapRay {
    let mut unit = || rng.next_f64() as f32;
    let target = Vec3::new(unit() * span[0], unit() * span[1], unit());
    let kind = (unit() * 3.0) as u32;
    let dir = Vec3::new(unit() - 0.5, unit() - 0.5, unit() - 0.5);
    match kind {
        0 => {
            let down = Vec3::new(dir.x, dir.y, -0.05 - dir.z.abs());
            MapRay::new(target - down.normalize() * 3.0, down)
        }
        1 => MapRay::new(target, dir + Vec3::new(0.0, 0.0, 1e-3)),
        _ => MapRay::new(
            target - dir.normalize() * 2.0,
            dir + Vec3::new(0.0, 0.0, 1e-3),
        ),
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(displace_core::random::property_cases(64)))]

    #[test]
    fn packets_agree_with_the_scalar_tracer_bit_for_bit(
        face in face_case(40, 16),
        n in 1usize..70,
        seed in any::<u64>(),
    ) {
        let (map, tiles, span) = random_face(&face, seed);
        let mut rng = Rng(seed ^ 0x2545_f491_4f6c_dd1d);
        let rays: Vec<MapRay> = (0..n).map(|_| random_ray(&mut rng, span)).collect();
        let opts: Vec<TraceOptions> = (0..n)
            .map(|_| {
                let r = rng.next_f64();
                TraceOptions {
                    // Mostly the throughput tracer, with budgets that run
                    // out; now and then a method the packet hands back.
                    method: if r < 0.1 { Method::Exact } else { Method::Sphere },
                    iterations: if r < 0.3 { 1 + (r * 20.0) as u32 } else { 64 },
                    t_min: if r > 0.8 { (r as f32 - 0.8) * 5.0 } else { 0.0 },
                    t_max: if r > 0.5 { (r as f32) * 6.0 } else { f32::INFINITY },
                    tiles,
                }
            })
            .collect();
        // Every kernel this CPU runs, each forced in turn (AVX-512's
        // sixteen-lane packets, AVX2's eight, one ray at a time).
        for kernel in Kernel::available() {
            let (hits, blocked) = with_kernel(kernel, || {
                let mut hits = vec![None; n];
                map.trace_many(&rays, &opts, &mut hits);
                let mut blocked = vec![false; n];
                map.occluded_many(&rays, &opts, &mut blocked);
                (hits, blocked)
            });
            let mut found = 0;
            for i in 0..n {
                let one = map.trace(&rays[i], &opts[i]);
                prop_assert_eq!(hits[i], one, "{:?}: ray {} {:?} {:?}", kernel, i, rays[i], opts[i]);
                prop_assert_eq!(
                    blocked[i],
                    map.occluded(&rays[i], &opts[i]),
                    "{:?}: any-hit ray {}", kernel, i
                );
                found += usize::from(one.is_some());
            }
            // The cases are not all misses: the comparison means something.
            prop_assert!(n < 16 || found > 0, "no ray of {} hit", n);
        }
    }
}
