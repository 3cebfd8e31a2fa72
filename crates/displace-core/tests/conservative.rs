//! The bake's promise: the interpolated stored value never exceeds the true
//! signed distance to the continuous bilinear surface, anywhere in the shell
//! and after quantisation, and neither does the value of the one voxel that
//! contains a point (what the CPU tracer steps by); and it is not uselessly
//! small either.

mod common_ref;

use common_ref::{bake_map, random_height, random_point, true_signed_distance, Rng};
use displace_core::distance_map::Format;
use displace_core::{bake, Address, BakeOptions, Extent};
use glam::{DVec3, Vec3};
use proptest::prelude::*;

proptest! {
    #![proptest_config(ProptestConfig::with_cases(displace_core::random::property_cases(48)))]

    #[test]
    fn interpolated_distance_never_exceeds_the_truth(
        kind in 0u8..3,
        hw in 2usize..10, hh in 2usize..10,
        dw in 2usize..10, dh in 2usize..10, dd in 2usize..6,
        sx in 0.3f32..4.0, sy in 0.3f32..4.0, sz in 0.1f32..1.5,
        repeat: bool,
        seed in any::<u64>(),
    ) {
        let address = if repeat { Address::Repeat } else { Address::Clamp };
        let height = random_height(kind, hw, hh, seed, address);
        let map = bake_map(&height, [dw, dh, dd], [sx, sy, sz]);
        let aspect = map.aspect();
        let tiles = if repeat { [-1, 2, -1, 2] } else { [0, 1, 0, 1] };
        let quantized = [Format::R8, Format::R16F].map(|f| map.distance.quantized(f).0);
        let mut rng = Rng(seed.wrapping_mul(31) | 1);
        for _ in 0..24 {
            let p = random_point(&mut rng, aspect);
            let truth = true_signed_distance(&height, aspect, p, tiles);
            let pf = p.as_vec3();
            let stored = map.distance.sample(pf) as f64;
            prop_assert!(stored <= truth + 1e-4, "stored {stored} > true {truth} at {p:?}");
            // The CPU tracer's one-voxel step: the value of the voxel that
            // contains the point bounds the distance too.
            let cell = map.distance.cell_bound(pf) as f64;
            prop_assert!(cell <= truth + 1e-4, "cell bound {cell} > true {truth} at {p:?}");
            for q in &quantized {
                let s = q.sample(pf) as f64;
                prop_assert!(s <= truth + 1e-4, "quantised {s} > true {truth} at {p:?}");
                let c = q.cell_bound(pf) as f64;
                prop_assert!(c <= truth + 1e-4, "quantised cell bound {c} > true {truth} at {p:?}");
                prop_assert!(truth - s <= q.max_underestimate() as f64 + 1e-4, "quantised bound {} < {}", q.max_underestimate(), truth - s);
            }
            // Not uselessly conservative: within the stated bound, which is
            // the column radius twice plus the trilinear slack twice: at most
            // two voxel diagonals, about one for typical flat voxels.
            prop_assert!(truth - stored <= map.distance.max_underestimate() as f64 + 1e-4,
                "underestimate {} above bound {}", truth - stored, map.distance.max_underestimate());
            let diag = map.distance.voxel_size().length() as f64;
            prop_assert!(map.distance.data_underestimate() as f64 <= 2.0 * diag + 1e-6);
        }
    }
}

/// The ray-tracer paper's flaw (section 2.3): at a sharp step the interpolated surface passes closer
/// to a voxel than any texel does, and a map baked from texel points lets
/// rays through. Points right next to the step must still be safe.
#[test]
fn sharp_steps_are_safe() {
    let (w, h) = (16, 16);
    let data: Vec<f32> = (0..w * h)
        .map(|k| if (k % w) / 4 % 2 == 0 { 1.0 } else { 0.0 })
        .collect();
    let height = displace_core::HeightMap::new(w, h, data, Address::Clamp).unwrap();
    let map = bake_map(&height, [16, 16, 8], [1.0, 1.0, 0.1]);
    let aspect = map.aspect();
    let mut worst = f64::INFINITY;
    for a in 0..200 {
        let x = a as f64 / 200.0 * aspect[0] as f64;
        for z in [0.2, 0.5, 0.9] {
            let p = DVec3::new(x, 0.5 * aspect[1] as f64, z);
            let truth = true_signed_distance(&height, aspect, p, [0, 1, 0, 1]);
            let stored = map
                .distance
                .sample(Vec3::new(x as f32, p.y as f32, z as f32)) as f64;
            worst = worst.min(truth - stored);
        }
    }
    assert!(
        worst >= -1e-4,
        "stored exceeded the true distance by {}",
        -worst
    );
}

/// A tiling height map bakes to a tiling distance map: baking a circularly
/// shifted map gives the shifted bake.
#[test]
fn repeat_bakes_are_periodic() {
    let n = 16;
    let height = random_height(2, n, n, 7, Address::Repeat);
    let shift = 5;
    let shifted: Vec<f32> = (0..n * n)
        .map(|k| height.texel(((k % n + shift) % n) as i64, (k / n) as i64))
        .collect();
    let shifted = displace_core::HeightMap::new(n, n, shifted, Address::Repeat).unwrap();
    let opts = BakeOptions::new([n, n, 4], Extent::new(2.0, 2.0, 0.5).unwrap());
    let a = bake(&height, &opts).unwrap();
    let b = bake(&shifted, &opts).unwrap();
    for k in 0..4 {
        for j in 0..n {
            for i in 0..n {
                let va = a.distance.voxel((i + shift) % n, j, k);
                let vb = b.distance.voxel(i, j, k);
                assert!((va - vb).abs() < 1e-5, "({i},{j},{k}) {va} vs {vb}");
            }
        }
    }
    // And the faces of the volume agree across the wrap: sampling just inside
    // u = 0 and just inside u = 1 interpolates between the same voxels.
    let aspect = a.aspect();
    for k in 0..4 {
        let z = (k as f32 + 0.5) / 4.0;
        for j in 0..n {
            let y = (j as f32 + 0.5) / n as f32 * aspect[1];
            let left = a.distance.sample(Vec3::new(0.0, y, z));
            let right = a.distance.sample(Vec3::new(aspect[0], y, z));
            assert!((left - right).abs() < 1e-5);
        }
    }
}

/// A map much coarser than its height map (an 8K height map traced
/// with a 2K map that fits GPU 3D-texture limits) still bounds the distance
/// to the full-resolution surface: column ranges are exact over each
/// column's footprint, however many texels it covers. Eight texels per
/// column here, on sharp and noisy maps, clamped and tiling.
#[test]
fn a_coarse_map_is_conservative_against_the_full_resolution_surface() {
    for kind in 0..3u8 {
        for address in [Address::Clamp, Address::Repeat] {
            let height = random_height(kind, 32, 24, 7 + kind as u64, address);
            let map = bake_map(&height, [4, 3, 4], [1.0, 0.75, 0.2]);
            let aspect = map.aspect();
            let tiles = if address == Address::Repeat {
                [-1, 2, -1, 2]
            } else {
                [0, 1, 0, 1]
            };
            let r8 = map.distance.quantized(Format::R8).0;
            let mut rng = Rng(99 + kind as u64);
            for _ in 0..24 {
                let p = random_point(&mut rng, aspect);
                let truth = true_signed_distance(&height, aspect, p, tiles);
                let pf = p.as_vec3();
                for (what, v) in [
                    ("stored", map.distance.sample(pf)),
                    ("cell bound", map.distance.cell_bound(pf)),
                    ("r8", r8.sample(pf)),
                ] {
                    assert!(
                        v as f64 <= truth + 1e-4,
                        "kind {kind} {address:?}: {what} {v} > true {truth} at {p:?}"
                    );
                }
            }
        }
    }
}
