//! The competing techniques against the exact reference: they
//! converge on smooth maps as their budget grows, fixed-step searches miss a
//! thin wall that distance mapping and maximum mipmaps find (Donnelly fig.
//! 8-2), conservative cones never step past the hit, and relaxed cones with
//! their binary search converge.

mod common_ref;

use common_ref::{random_height, Rng};
use displace_core::techniques::{ConeKind, ConeMap, Maps, MaxPyramid, Technique};
use displace_core::{
    bake, generators, Address, BakeOptions, Extent, HeightMap, MapRay, Method, TraceOptions,
};
use glam::Vec3;
use proptest::prelude::*;

/// Every precomputation for `height` on a face of `extent`.
fn all_maps(height: HeightMap, extent: Extent, distance: [usize; 3]) -> Maps {
    let aspect = extent.aspect();
    let mut maps = Maps::new(height.clone(), aspect);
    maps.cones = Some(ConeMap::build(&height, aspect, ConeKind::Conservative));
    maps.relaxed = Some(ConeMap::build(&height, aspect, ConeKind::Relaxed));
    maps.pyramid = Some(MaxPyramid::build(&height));
    maps.displacement = Some(bake(&height, &BakeOptions::new(distance, extent)).unwrap());
    maps
}

/// A ray entering the top of the face at a random point, `elevation`
/// degrees above the face, random azimuth.
fn ray_from_top(rng: &mut Rng, aspect: [f32; 2], elevation: f32) -> MapRay {
    let origin = Vec3::new(
        rng.next_f64() as f32 * aspect[0],
        rng.next_f64() as f32 * aspect[1],
        1.0,
    );
    let e = elevation.to_radians();
    let a = (rng.next_f64() * std::f64::consts::TAU) as f32;
    MapRay::new(
        origin,
        Vec3::new(e.cos() * a.cos(), e.cos() * a.sin(), -e.sin()),
    )
}

/// Exact first hit (`Method::Exact`), its texture coordinate.
/// A random height map (`kind` of [`random_height`]) with every technique's
/// maps, and 32 rays from the top at random elevations with the exact
/// reference's `t` for each: the shared set-up of the property tests.
/// A [`random_case`] drawn by proptest, shown by its inputs (height kind,
/// size, tile width and depth, seed) when a property fails.
struct RandomCase {
    inputs: (u8, [usize; 2], [f32; 2], u64),
    maps: Maps,
    cases: Vec<(MapRay, Option<f32>)>,
}

impl std::fmt::Debug for RandomCase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "random_case{:?}", self.inputs)
    }
}

/// The [`RandomCase`]s of the techniques' properties: any height kind, 2
/// to 19 texels a side, tiles 0.5 to 3 wide and 0.05 to 0.5 deep, rays
/// drawn with `ray_salt`.
fn random_cases(ray_salt: u64) -> impl Strategy<Value = RandomCase> {
    let inputs = (
        0u8..3,
        2usize..20,
        2usize..20,
        0.5f32..3.0,
        0.05f32..0.5,
        any::<u64>(),
    );
    inputs.prop_map(move |(kind, w, h, sx, sz, seed)| {
        let (maps, cases) = random_case(kind, [w, h], [sx, sz], seed, ray_salt);
        RandomCase {
            inputs: (kind, [w, h], [sx, sz], seed),
            maps,
            cases,
        }
    })
}

fn random_case(
    kind: u8,
    [w, h]: [usize; 2],
    [sx, sz]: [f32; 2],
    seed: u64,
    ray_salt: u64,
) -> (Maps, Vec<(MapRay, Option<f32>)>) {
    let height = random_height(kind, w, h, seed, Address::Clamp);
    let extent = Extent::new(sx, sx * 0.8, sz).unwrap();
    let maps = all_maps(height, extent, [8, 8, 4]);
    let mut rng = Rng(seed ^ ray_salt);
    let exact_opts = TraceOptions {
        method: Method::Exact,
        ..TraceOptions::default()
    };
    let cases = (0..32)
        .map(|_| {
            let elevation = 3.0 + rng.next_f64() as f32 * 87.0;
            let ray = ray_from_top(&mut rng, maps.aspect, elevation);
            let want = maps
                .displacement
                .as_ref()
                .unwrap()
                .trace(&ray, &exact_opts)
                .map(|h| h.t);
            (ray, want)
        })
        .collect();
    (maps, cases)
}

fn exact_hit(maps: &Maps, ray: &MapRay) -> Option<glam::Vec2> {
    let opts = TraceOptions {
        method: Method::Exact,
        ..TraceOptions::default()
    };
    maps.displacement
        .as_ref()
        .unwrap()
        .trace(ray, &opts)
        .map(|h| h.uv)
}

/// Over `rays`: the fraction with the wrong hit/miss and the 99th
/// percentile of the hit error in texels.
fn score(maps: &Maps, tech: Technique, budget: u32, rays: &[MapRay]) -> (f64, f32) {
    let (w, h) = (maps.height.width() as f32, maps.height.height() as f32);
    let mut wrong = 0;
    let mut errors = Vec::new();
    for ray in rays {
        let got = tech.trace(maps, ray, budget).unwrap().hit;
        match (exact_hit(maps, ray), got) {
            (Some(want), Some(got)) => {
                let d = (got.uv - want) * glam::Vec2::new(w, h);
                errors.push(d.length());
            }
            (None, None) => {}
            _ => wrong += 1,
        }
    }
    errors.sort_by(f32::total_cmp);
    let p99 = errors
        .get(((errors.len() as f64 * 0.99) as usize).min(errors.len().saturating_sub(1)))
        .copied()
        .unwrap_or(0.0);
    (wrong as f64 / rays.len() as f64, p99)
}

/// The bound BENCHMARKS.md states: at the top budget (128) every technique with a
/// budget has its 99th-percentile hit error below half a texel and at most
/// 1% of rays with the wrong hit/miss, on smooth maps at 20 to 90 degrees;
/// and a small budget (4) is no better, so the test sees convergence, not
/// luck. The one exception is Donnelly's fixed loop (`distance-fixed`): it
/// stops where the stored distance vanishes, which a conservative map puts
/// up to its underestimate above the surface, so more steps do not help
/// (about 6-8 texels at p99 here, whatever the budget); it is only held to
/// "no worse with more steps".
#[test]
fn every_technique_converges_on_smooth_maps() {
    let extent = Extent::new(1.0, 1.0, 0.1).unwrap();
    for spec in ["gen:gaussian", "gen:noise?octaves=2&frequency=2"] {
        let height = generators::generate(spec, 64, 64, Address::Clamp).unwrap();
        let maps = all_maps(height, extent, [64, 64, 16]);
        let mut rng = Rng(7);
        let rays: Vec<MapRay> = (0..400)
            .map(|k| ray_from_top(&mut rng, maps.aspect, 20.0 + (k % 8) as f32 * 10.0))
            .collect();
        for tech in Technique::ALL.into_iter().filter(|t| t.uses_budget()) {
            let (wrong_hi, p99_hi) = score(&maps, tech, 128, &rays);
            let (wrong_lo, p99_lo) = score(&maps, tech, 4, &rays);
            assert!(
                p99_lo + wrong_lo as f32 >= p99_hi + wrong_hi as f32,
                "{spec} {}: budget 4 ({p99_lo}, {wrong_lo}) beats 128 ({p99_hi}, {wrong_hi})",
                tech.name()
            );
            if tech == Technique::DistanceFixed {
                continue;
            }
            assert!(
                p99_hi < 0.5 && wrong_hi <= 0.01,
                "{spec} {}: budget 128 gives p99 {p99_hi} texels, {wrong_hi} wrong",
                tech.name()
            );
        }
    }
}

/// Donnelly fig. 8-2: a wall one texel wide on a flat floor, seen at 10
/// degrees. Eight layers step over it; distance mapping and maximum mipmaps
/// find it on every ray.
#[test]
fn fixed_step_searches_miss_a_thin_wall() {
    let n = 64;
    let wall = 40;
    let data: Vec<f32> = (0..n * n)
        .map(|k| if k % n == wall { 1.0 } else { 0.0 })
        .collect();
    let height = HeightMap::new(n, n, data, Address::Clamp).unwrap();
    let extent = Extent::new(1.0, 1.0, 0.1).unwrap();
    let maps = all_maps(height, extent, [64, 64, 16]);
    let texel = maps.aspect[0] / n as f32;
    // Rays along +x that reach the wall's column half-way down or lower.
    let wall_x = (wall as f32 + 0.5) * texel;
    let e = 10f32.to_radians();
    let dir = Vec3::new(e.cos(), 0.0, -e.sin());
    let rays: Vec<MapRay> = (0..64)
        .map(|k| {
            let y = (k as f32 + 0.5) / 64.0 * maps.aspect[1];
            // Enter the top 0.5 / tan(e) before the wall: the ray is at
            // z = 0.5 over the wall's centre line.
            let x = wall_x - (0.5 + 0.1 * (k % 4) as f32) / e.tan();
            MapRay::new(Vec3::new(x, y, 1.0), dir)
        })
        .collect();
    let found = |tech: Technique, budget: u32| {
        rays.iter()
            .filter(|ray| {
                let want = exact_hit(&maps, ray).expect("every ray hits the wall");
                assert!((want.x * n as f32 - (wall as f32 + 0.5)).abs() < 1.0);
                tech.trace(&maps, ray, budget)
                    .unwrap()
                    .hit
                    .is_some_and(|h| ((h.uv - want) * n as f32).length() < 0.5)
            })
            .count()
    };
    for tech in [Technique::Steep, Technique::Pom, Technique::BevyOcclusion] {
        let got = found(tech, 8);
        assert!(
            got <= rays.len() / 2,
            "{} found the wall on {got} of {} rays",
            tech.name(),
            rays.len()
        );
    }
    for tech in [Technique::Distance, Technique::MaxMip] {
        assert_eq!(found(tech, 64), rays.len(), "{}", tech.name());
    }
}

/// The cone maps report what they are and how big.
#[test]
fn cone_maps_and_pyramid_sizes() {
    let height = generators::generate("gen:studded", 32, 16, Address::Clamp).unwrap();
    let cones = ConeMap::build(&height, [10.0, 5.0], ConeKind::Conservative);
    assert_eq!(
        (cones.width(), cones.height(), cones.bytes()),
        (32, 16, 32 * 16 * 4)
    );
    assert!(cones.data().iter().all(|&c| c > 0.0 && c.is_finite()));
    let pyramid = MaxPyramid::build(&height);
    // 33 x 17 cells, then 17 x 9, 9 x 5, 5 x 3, 3 x 2, 2 x 1, 1 x 1.
    assert_eq!(pyramid.levels(), 7);
    assert_eq!(pyramid.node(pyramid.levels() - 1, 0, 0), 1.0);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(displace_core::random::property_cases(32)))]

    /// Conservative cones: however few steps, cone stepping never stands
    /// past the exact hit, and never reports a hit on a ray that misses
    /// except where it is still above the surface inside the face.
    #[test]
    fn cone_steps_never_pass_the_hit(
        RandomCase { maps, cases, .. } in random_cases(0x5151),
    ) {
        for (ray, want) in cases {
            for budget in [1, 2, 3, 5, 8, 13, 21] {
                let got = Technique::Cone.trace(&maps, &ray, budget).unwrap();
                if let (Some(got), Some(want)) = (got.hit, want) {
                    prop_assert!(got.t <= want + 1e-4 * (1.0 + want), "budget {budget}: cone at {} past the hit at {want}", got.t);
                }
                if let (Some(got), None) = (got.hit, want) {
                    let p = got.position;
                    prop_assert!(p.z >= maps.height.sample(p.x / maps.aspect[0], p.y / maps.aspect[1]) - 1e-4);
                }
            }
        }
    }

    /// The two exact techniques on random maps (sharp ones included): with
    /// budget to spare, maximum mipmaps and distance mapping return the
    /// exact hit (or miss) on every ray.
    #[test]
    fn exact_techniques_match_the_reference_on_random_maps(
        RandomCase { maps, cases, .. } in random_cases(0xabcd),
    ) {
        for (ray, want) in cases {
            for tech in [Technique::MaxMip, Technique::Distance] {
                let got = tech.trace(&maps, &ray, 10_000).unwrap().hit.map(|h| h.t);
                match (want, got) {
                    (Some(a), Some(b)) => prop_assert!((a - b).abs() < 1e-4 * (1.0 + a), "{}: {b} vs {a}", tech.name()),
                    (None, None) => {}
                    other => prop_assert!(false, "{}: {other:?}", tech.name()),
                }
            }
        }
    }
}
