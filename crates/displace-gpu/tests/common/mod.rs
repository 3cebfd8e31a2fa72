//! Seeded random height maps, bakes and rays shared by the GPU tests.

#![allow(dead_code)]

use displace_core::random::SplitMix64;
use displace_core::{bake, Address, BakeOptions, DisplacementMap, Extent, HeightMap, MapRay};
use glam::Vec3;

/// The project's seeded generator ([`SplitMix64`]), so every run sees the
/// same cases, with the draws the GPU tests need.
pub struct Rng(SplitMix64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(SplitMix64::new(seed))
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }
    /// Uniform in [0, 1).
    pub fn f32(&mut self) -> f32 {
        self.0.next_f32()
    }
    pub fn range(&mut self, lo: f32, hi: f32) -> f32 {
        self.0.range(lo, hi)
    }
    pub fn unit(&mut self) -> Vec3 {
        loop {
            let v = Vec3::new(
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
                self.range(-1.0, 1.0),
            );
            let l = v.length();
            if l > 0.05 && l <= 1.0 {
                return v / l;
            }
        }
    }
}

/// A random height map: white noise, smoothed a random number of times, so
/// both jagged and gentle surfaces are covered.
pub fn random_height(rng: &mut Rng, address: Address) -> HeightMap {
    let w = 4 + (rng.next_u64() % 29) as usize;
    let h = 4 + (rng.next_u64() % 29) as usize;
    let mut data: Vec<f32> = (0..w * h).map(|_| rng.f32()).collect();
    for _ in 0..rng.next_u64() % 3 {
        let prev = data.clone();
        for j in 0..h {
            for i in 0..w {
                let at = |di: i64, dj: i64| {
                    let ii = address.texel_index(i as i64 + di, w);
                    let jj = address.texel_index(j as i64 + dj, h);
                    prev[jj * w + ii]
                };
                data[j * w + i] =
                    (at(0, 0) * 4.0 + at(1, 0) + at(-1, 0) + at(0, 1) + at(0, -1)) / 8.0;
            }
        }
    }
    HeightMap::new(w, h, data, address).unwrap()
}

pub fn random_map(rng: &mut Rng, address: Address) -> DisplacementMap {
    let height = random_height(rng, address);
    let size = [
        4 + (rng.next_u64() % 29) as usize,
        4 + (rng.next_u64() % 29) as usize,
        2 + (rng.next_u64() % 11) as usize,
    ];
    let extent = Extent::new(
        rng.range(0.5, 2.0),
        rng.range(0.5, 2.0),
        rng.range(0.05, 0.6),
    )
    .unwrap();
    bake(&height, &BakeOptions::new(size, extent)).unwrap()
}

/// Rays from around and above the shell `[0, hi.x] x [0, hi.y] x [0, 1]`,
/// aimed at a random point of it, so most of them cross it: from above
/// (surface hits), from the sides (walls and grazing hits) and a few from
/// below.
pub fn random_rays(rng: &mut Rng, hi: Vec3, n: usize) -> Vec<MapRay> {
    (0..n)
        .map(|_| {
            let target = Vec3::new(
                rng.range(0.0, hi.x),
                rng.range(0.0, hi.y),
                rng.range(0.0, 1.0),
            );
            let spread = hi.max_element().max(1.0) * 1.5;
            let origin = match rng.next_u64() % 10 {
                0 => target + rng.unit() * spread,
                1..=2 => Vec3::new(
                    rng.range(-0.5, hi.x + 0.5),
                    rng.range(-0.5, hi.y + 0.5),
                    rng.range(0.0, 1.2),
                ),
                _ => Vec3::new(
                    rng.range(-0.5, hi.x + 0.5),
                    rng.range(-0.5, hi.y + 0.5),
                    rng.range(1.0, 3.0),
                ),
            };
            let dir = target - origin;
            if dir.length() < 1e-3 {
                MapRay::new(origin, Vec3::new(0.0, 0.0, -1.0))
            } else {
                MapRay::new(origin, dir)
            }
        })
        .collect()
}

/// The clamped map of seed `seed`: what a test that needs one map and no
/// rays draws.
pub fn clamped_map(seed: u64) -> DisplacementMap {
    random_map(&mut Rng::new(seed), Address::Clamp)
}

/// The map of seed `seed` (clamped) and `n` rays around its one tile, drawn
/// in that order from the one generator.
pub fn clamped_case(seed: u64, n: usize) -> (DisplacementMap, Vec<MapRay>) {
    let mut rng = Rng::new(seed);
    let map = random_map(&mut rng, Address::Clamp);
    let [ax, ay] = map.aspect();
    let rays = random_rays(&mut rng, Vec3::new(ax, ay, 1.0), n);
    (map, rays)
}

/// How a GPU query's answers agree with the CPU's over a batch of rays:
/// hit or miss, and how far apart the hit points lie; every GPU-against-CPU
/// tally counts these the same way and holds them to the same bounds.
#[derive(Default, Debug)]
pub struct HitAgreement {
    /// Rays counted.
    pub rays: usize,
    /// Rays both sides hit.
    pub hits: usize,
    /// Rays one side hits and the other misses.
    pub hit_miss_differ: usize,
    /// Rays both hit at points more than 1e-3 apart.
    pub far: usize,
    /// The largest distance between two hit points.
    pub worst: f32,
}

impl HitAgreement {
    /// Counts one ray the CPU and the GPU hit at `cpu` and `gpu` (`None`: a
    /// miss).
    pub fn add(&mut self, cpu: Option<Vec3>, gpu: Option<Vec3>) {
        self.rays += 1;
        match (cpu, gpu) {
            (Some(c), Some(g)) => {
                self.hits += 1;
                let e = (c - g).length();
                self.worst = self.worst.max(e);
                if e > 1e-3 {
                    self.far += 1;
                }
            }
            (None, None) => {}
            _ => self.hit_miss_differ += 1,
        }
    }

    /// At most 0.1% of the rays differ in hit or miss, and at most 0.1% in
    /// where they hit; a failure prints `tally` whole.
    pub fn check(&self, what: &str, tally: &impl std::fmt::Debug) {
        let allowed = self.rays / 1000;
        assert!(
            self.hit_miss_differ <= allowed,
            "{what}: hit/miss differs on more than 0.1% of rays: {tally:?}"
        );
        assert!(
            self.far <= allowed,
            "{what}: hit points further than 1e-3 apart on more than 0.1% of rays: {tally:?}"
        );
    }
}
