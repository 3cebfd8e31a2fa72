//! What a located point of a curved shell costs, one at a time and in
//! lanes: the measurement behind the curved tracer's packet design
//! (docs/curved-tracer.md, "The designs left, measured").
//!
//! ```text
//! cargo run --release -p displace-scene --example locate_chains
//! ```
//!
//! Three ways over the same four million points of a sphere's shell:
//! - **chained:** each point nudged by the last one's answer, as a
//!   refinement's probes wait on each other;
//! - **independent:** [`CurvedShell::locate`] on each point;
//! - **eight lanes:** the same algebra (the level from the distance to the
//!   base plane, three Newton steps on the cubic, the barycentrics on that
//!   level) written over eight points at a time in `f64` arrays, which the
//!   compiler turns into vector instructions (AVX-512 where the CPU has
//!   it); the lanes' answers are compared with `locate`'s first.

use displace_scene::curved_shell::{frame, lambda_for_depth, min_normal_length, CurvedShell};
use glam::{DVec2, DVec3, Vec3};
use std::time::Instant;

const LANES: usize = 8;

/// A shell's frame as [`CurvedShell`] keeps it: corner 0, its normal, the
/// edges and normal differences from it, the level triangle's normal
/// coefficients, and the depth.
struct Frame {
    p0: DVec3,
    n0: DVec3,
    e: [DVec3; 2],
    f: [DVec3; 2],
    c: [DVec3; 3],
    depth: f64,
}

impl Frame {
    fn new(p: [Vec3; 3], n: [Vec3; 3], depth: f64) -> Self {
        let (p, n, e, f, c) = frame(&p, &n);
        Self {
            p0: p[0],
            n0: n[0],
            e,
            f,
            c,
            depth,
        }
    }
}

/// `(b, w)` of eight points, each lane as `locate` finds an inside point:
/// each step a loop over the lanes, which the compiler vectorises.
#[inline(always)]
fn locate8(fr: &Frame, inv_slice: f64, x: &[[f64; LANES]; 3]) -> [[f64; LANES]; 3] {
    type L = [f64; LANES];
    let dotc = |v: &[L; 3], c: DVec3| -> L {
        std::array::from_fn(|l| v[0][l] * c.x + v[1][l] * c.y + v[2][l] * c.z)
    };
    let r: [L; 3] = [0, 1, 2].map(|a| std::array::from_fn(|l| x[a][l] - fr.p0[a]));
    let (n0c0, n0c1, k3) = (fr.n0.dot(fr.c[0]), fr.n0.dot(fr.c[1]), -fr.n0.dot(fr.c[2]));
    let k0 = dotc(&r, fr.c[0]);
    let k1: L = dotc(&r, fr.c[1]).map(|v| v - n0c0);
    let k2: L = dotc(&r, fr.c[2]).map(|v| v - n0c1);
    let mut lambda: L = k0.map(|v| v * inv_slice);
    for _ in 0..3 {
        for l in 0..LANES {
            let x = lambda[l];
            let f = ((k3 * x + k2[l]) * x + k1[l]) * x + k0[l];
            let df = (3.0 * k3 * x + 2.0 * k2[l]) * x + k1[l];
            lambda[l] = x - f / df;
        }
    }
    let lin = |base: DVec3, step: DVec3, a: usize| -> L {
        std::array::from_fn(|l| base[a] + lambda[l] * step[a])
    };
    let a: [L; 3] = [0, 1, 2].map(|k| std::array::from_fn(|l| r[k][l] - lambda[l] * fr.n0[k]));
    let b1: [L; 3] = [0, 1, 2].map(|k| lin(fr.e[0], fr.f[0], k));
    let b2: [L; 3] = [0, 1, 2].map(|k| lin(fr.e[1], fr.f[1], k));
    let cross = |u: &[L; 3], v: &[L; 3]| -> [L; 3] {
        [
            std::array::from_fn(|l| u[1][l] * v[2][l] - u[2][l] * v[1][l]),
            std::array::from_fn(|l| u[2][l] * v[0][l] - u[0][l] * v[2][l]),
            std::array::from_fn(|l| u[0][l] * v[1][l] - u[1][l] * v[0][l]),
        ]
    };
    let dot = |u: &[L; 3], v: &[L; 3]| -> L {
        std::array::from_fn(|l| u[0][l] * v[0][l] + u[1][l] * v[1][l] + u[2][l] * v[2][l])
    };
    let n = cross(&b1, &b2);
    let nn = dot(&n, &n);
    let u = dot(&cross(&a, &b2), &n);
    let v = dot(&cross(&b1, &a), &n);
    let mut out = [[0.0; LANES]; 3];
    for l in 0..LANES {
        let inv = 1.0 / nn[l];
        let (bx, by) = (u[l] * inv, v[l] * inv);
        let nb = fr.n0 + bx * fr.f[0] + by * fr.f[1];
        out[0][l] = bx;
        out[1][l] = by;
        out[2][l] = lambda[l] * nb.length() / fr.depth;
    }
    out
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx512f,avx512dq,avx512vl,avx2,fma")]
fn locate8_avx512(fr: &Frame, inv_slice: f64, x: &[[f64; LANES]; 3]) -> [[f64; LANES]; 3] {
    locate8(fr, inv_slice, x)
}

fn main() {
    let n = [
        Vec3::new(0.1, 0.1, 1.0).normalize(),
        Vec3::new(0.4, 0.1, 1.0).normalize(),
        Vec3::new(0.1, 0.4, 1.0).normalize(),
    ];
    // The shell keeps its depth as given, in single precision.
    let (p, depth) = (n, 0.05f32 as f64);
    let top = lambda_for_depth(depth, min_normal_length(&n).expect("normals"));
    let s = CurvedShell::new(p, n, depth as f32, top).expect("a shell");
    let fr = Frame::new(p, n, depth);
    let normals = frame(&p, &n).1;
    let inv_slice = 3.0 / fr.c[0].dot(normals[0] + normals[1] + normals[2]);
    let count = 4_000_000usize;
    let mut seed = 1u64;
    let mut unit = move || {
        seed = seed
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (seed >> 11) as f64 / (1u64 << 53) as f64
    };
    let pts: Vec<DVec3> = (0..count)
        .map(|_| s.point(DVec2::new(unit() * 0.5, unit() * 0.5), unit()))
        .collect();
    let lanes: Vec<[[f64; LANES]; 3]> = pts
        .chunks_exact(LANES)
        .map(|c| [0, 1, 2].map(|a| std::array::from_fn(|l| c[l][a])))
        .collect();
    let avx512 = cfg!(target_arch = "x86_64") && std::arch::is_x86_feature_detected!("avx512f");
    // Every lane where `locate` finds it.
    let mut worst = 0.0f64;
    for (group, pts) in lanes.iter().zip(pts.chunks_exact(LANES)).take(10_000) {
        let got = locate8(&fr, inv_slice, group);
        for (l, x) in pts.iter().enumerate() {
            let loc = s.locate(*x, 0.0).expect("inside");
            let off = (loc.b - DVec2::new(got[0][l], got[1][l]))
                .length()
                .max((loc.w - got[2][l]).abs());
            worst = worst.max(off);
        }
    }
    println!("eight lanes against locate: largest difference {worst:.1e}");
    assert!(worst < 1e-12, "the lanes must locate as `locate` does");
    for _ in 0..3 {
        let time = |f: &mut dyn FnMut() -> f64| {
            let start = Instant::now();
            let acc = f();
            (start.elapsed().as_secs_f64() / count as f64 * 1e9, acc)
        };
        let (chained, _) = time(&mut || {
            let (mut carry, mut acc) = (0.0f64, 0.0);
            for x in &pts {
                carry = s
                    .locate(*x + DVec3::splat(carry * 1e-30), 0.0)
                    .map_or(0.0, |l| l.w);
                acc += carry;
            }
            acc
        });
        let (independent, _) = time(&mut || {
            pts.iter()
                .map(|x| s.locate(*x, 0.0).map_or(0.0, |l| l.w))
                .sum()
        });
        let (in_lanes, _) = time(&mut || {
            lanes
                .iter()
                .map(|g| {
                    // SAFETY: only reached where the CPU has the features.
                    let out = if avx512 {
                        unsafe { locate8_avx512(&fr, inv_slice, g) }
                    } else {
                        locate8(&fr, inv_slice, g)
                    };
                    out[2].iter().sum::<f64>()
                })
                .sum()
        });
        println!(
            "ns a point: chained {chained:.1}, independent {independent:.1}, eight lanes{} {in_lanes:.1}",
            if avx512 { " (AVX-512)" } else { "" }
        );
    }
}
