//! Reference geometry for the tests: the true distance from a point to the
//! continuous bilinear surface, found by brute force over every patch
//! (dense sampling, then Newton-projected refinement), independent of the
//! bake's reasoning.

#![allow(dead_code)]

use displace_core::{bake, Address, BakeOptions, DisplacementMap, Extent, HeightMap};
use glam::{DVec2, DVec3, Vec3};
use proptest::prelude::{any, Strategy};

/// Surface point of cell `(ci, cj)` at local coordinates `(fx, fy)`, map
/// space (depth units).
fn patch_point(h: &HeightMap, aspect: [f64; 2], ci: i64, cj: i64, f: DVec2) -> DVec3 {
    let [h00, h10, h01, h11] = h.cell(ci, cj).map(|v| v as f64);
    let z = h00 * (1.0 - f.x) * (1.0 - f.y)
        + h10 * f.x * (1.0 - f.y)
        + h01 * (1.0 - f.x) * f.y
        + h11 * f.x * f.y;
    let u = (ci as f64 + 0.5 + f.x) / h.width() as f64;
    let v = (cj as f64 + 0.5 + f.y) / h.height() as f64;
    DVec3::new(u * aspect[0], v * aspect[1], z)
}

/// Unsigned distance from `p` to the surface over the tiles `[tu0, tu1) x
/// [tv0, tv1)` (clamped maps: exactly `[0, 1]^2`).
pub fn true_distance(h: &HeightMap, aspect: [f32; 2], p: DVec3, tiles: [i64; 4]) -> f64 {
    let aspect = [aspect[0] as f64, aspect[1] as f64];
    let (w, hh) = (h.width() as i64, h.height() as i64);
    let mut best = f64::INFINITY;
    let (ci0, ci1, cj0, cj1) = match h.address() {
        Address::Clamp => (-1, w - 1, -1, hh - 1),
        Address::Repeat => (
            tiles[0] * w - 1,
            tiles[1] * w - 1,
            tiles[2] * hh - 1,
            tiles[3] * hh - 1,
        ),
    };
    for cj in cj0..=cj1 {
        for ci in ci0..=ci1 {
            // The part of the cell inside the face (clamped maps stop at 0 and 1).
            let lo = DVec2::new(
                if h.address() == Address::Clamp && ci == -1 {
                    0.5
                } else {
                    0.0
                },
                if h.address() == Address::Clamp && cj == -1 {
                    0.5
                } else {
                    0.0
                },
            );
            let hi = DVec2::new(
                if h.address() == Address::Clamp && ci == w - 1 {
                    0.5
                } else {
                    1.0
                },
                if h.address() == Address::Clamp && cj == hh - 1 {
                    0.5
                } else {
                    1.0
                },
            );
            let n = 12;
            let mut local_best = (f64::INFINITY, DVec2::ZERO);
            for b in 0..=n {
                for a in 0..=n {
                    let f = lo + (hi - lo) * DVec2::new(a as f64 / n as f64, b as f64 / n as f64);
                    let d = (patch_point(h, aspect, ci, cj, f) - p).length_squared();
                    if d < local_best.0 {
                        local_best = (d, f);
                    }
                }
            }
            // Refine: projected gradient descent with a shrinking step.
            let (mut d, mut f) = local_best;
            let mut step = (hi - lo).max_element() / n as f64;
            while step > 1e-7 {
                let mut improved = false;
                for dir in [
                    DVec2::X,
                    -DVec2::X,
                    DVec2::Y,
                    -DVec2::Y,
                    DVec2::ONE,
                    -DVec2::ONE,
                    DVec2::new(1.0, -1.0),
                    DVec2::new(-1.0, 1.0),
                ] {
                    let g = (f + dir * step).clamp(lo, hi);
                    let dd = (patch_point(h, aspect, ci, cj, g) - p).length_squared();
                    if dd < d {
                        d = dd;
                        f = g;
                        improved = true;
                    }
                }
                if !improved {
                    step *= 0.5;
                }
            }
            best = best.min(d);
        }
    }
    best.sqrt()
}

/// Signed: negative under the surface.
pub fn true_signed_distance(h: &HeightMap, aspect: [f32; 2], p: DVec3, tiles: [i64; 4]) -> f64 {
    let d = true_distance(h, aspect, p, tiles);
    let hs = h.sample(
        (p.x / aspect[0] as f64) as f32,
        (p.y / aspect[1] as f64) as f32,
    ) as f64;
    if p.z < hs {
        -d
    } else {
        d
    }
}

/// The tests' generator: the random height maps are seeded by proptest,
/// and everything downstream of the seed is deterministic.
pub use displace_core::random::Xorshift64 as Rng;

/// Random height maps of three kinds: smooth noise, sharp two-level
/// (studded-like) and white noise.
pub fn random_height(kind: u8, w: usize, h: usize, seed: u64, address: Address) -> HeightMap {
    let mut rng = Rng(seed | 1);
    let data: Vec<f32> = match kind % 3 {
        0 => (0..w * h).map(|_| rng.next_f64() as f32).collect(),
        1 => {
            let period = 1 + (rng.next_f64() * 3.0) as usize;
            (0..w * h)
                .map(|k| {
                    if ((k % w) / period + (k / w) / period).is_multiple_of(2) {
                        1.0
                    } else {
                        0.0
                    }
                })
                .collect()
        }
        _ => {
            let (a, b, c) = (rng.next_f64() * 6.0, rng.next_f64() * 6.0, rng.next_f64());
            (0..w * h)
                .map(|k| {
                    let x = (k % w) as f64 / w as f64;
                    let y = (k / w) as f64 / h as f64;
                    (0.5 + 0.5
                        * ((a * x + c) * std::f64::consts::TAU).sin()
                        * ((b * y) * std::f64::consts::TAU).cos()) as f32
                })
                .collect()
        }
    };
    HeightMap::new(w, h, data, address).unwrap()
}

/// `height` baked to `size` voxels on a face of `sx x sy x sz`: the bake
/// every test here makes, with the default options otherwise.
pub fn bake_map(height: &HeightMap, size: [usize; 3], [sx, sy, sz]: [f32; 3]) -> DisplacementMap {
    bake(
        height,
        &BakeOptions::new(size, Extent::new(sx, sy, sz).unwrap()),
    )
    .unwrap()
}

/// What a face of the tracer's property tests is made of ([`random_face`]).
#[derive(Clone, Copy, Debug)]
pub struct FaceCase {
    /// The kind of random height map ([`random_height`]).
    pub kind: u8,
    /// Height-map texels `[W, H]`.
    pub height: [usize; 2],
    /// Distance-map voxels `[W, H, D]`.
    pub size: [usize; 3],
    /// The face's width `sx` and depth `sz`.
    pub scale: [f32; 2],
    /// Repeating, or clamped.
    pub repeat: bool,
}

/// Random [`FaceCase`]s: height maps and distance maps of 2 and 4 to
/// `side - 1` texels or voxels a side, maps 2 to `depth - 1` voxels deep,
/// faces 0.5 to 4 wide and 0.05 to 1 deep, clamped or repeating. Drawn
/// one after the other in that order, as the tests' own parameters were
/// (so that their persisted regression seeds replay the same faces).
pub fn face_case(side: usize, depth: usize) -> impl Strategy<Value = FaceCase> {
    (
        0u8..3,
        2usize..side,
        2usize..side,
        4usize..side,
        4usize..side,
        2usize..depth,
        0.5f32..4.0,
        0.05f32..1.0,
        any::<bool>(),
    )
        .prop_map(|(kind, hw, hh, dw, dh, dd, sx, sz, repeat)| FaceCase {
            kind,
            height: [hw, hh],
            size: [dw, dh, dd],
            scale: [sx, sz],
            repeat,
        })
}

/// The face of the tracer's property tests: a random height map of `kind`
/// (see [`random_height`]) baked to `size` on a face `sx` wide, `0.75 sx`
/// high and `sz` deep; clamped, or repeating and traced over 2 x 2 tiles.
/// Returns the map, its tiles and what they span in map space.
pub fn random_face(face: &FaceCase, seed: u64) -> (DisplacementMap, [f32; 2], [f32; 2]) {
    let FaceCase {
        kind,
        height: [hw, hh],
        size,
        scale: [sx, sz],
        repeat,
    } = *face;
    let address = if repeat {
        Address::Repeat
    } else {
        Address::Clamp
    };
    let height = random_height(kind, hw, hh, seed, address);
    let map = bake_map(&height, size, [sx, sx * 0.75, sz]);
    let tiles = if repeat { [2.0, 2.0] } else { [1.0, 1.0] };
    let aspect = map.aspect();
    let span = [aspect[0] * tiles[0], aspect[1] * tiles[1]];
    (map, tiles, span)
}

/// A uniform point of one tile of the shell, `x` first.
pub fn random_point(rng: &mut Rng, aspect: [f32; 2]) -> DVec3 {
    DVec3::new(
        rng.next_f64() * aspect[0] as f64,
        rng.next_f64() * aspect[1] as f64,
        rng.next_f64(),
    )
}

/// The direction of a ray coming down onto the face from `elevation`
/// radians above it, at `azimuth`.
pub fn downward(elevation: f32, azimuth: f32) -> Vec3 {
    -Vec3::new(
        elevation.cos() * azimuth.cos(),
        elevation.cos() * azimuth.sin(),
        elevation.sin(),
    )
}
