//! Every technique's WGSL version agrees with its CPU version
//! (`displace_core::techniques`) on random rays against random height maps:
//! the same hit or miss on at least 99.9% of rays, hit points within 1e-3
//! shell depths, and the same fetch count on at least 99.9% of rays (every
//! technique here is deterministic; only a rounding difference at a
//! layer or cell boundary may change one decision).
//!
//! Maximum mipmaps are the exception on fetch counts: their walk starts the
//! exact patch solve (`exact::walk`, double precision on the CPU, single in
//! WGSL) exactly on a cell boundary, and which side of it the two land on
//! decides whether a zero-length cell is counted. Out of budget, where the
//! walk stopped is the answer, so such rays may answer differently. What
//! must hold: with budget to spare the hits agree as strictly as every other
//! technique's; within a budget, the answers agree on at least 90% of rays;
//! and the fetch counts agree on most rays and within 2% on average.

mod common;

use common::{random_map, random_rays, HitAgreement, Rng};
use displace_core::techniques::{ConeKind, ConeMap, Maps, MaxPyramid, Technique, Traced};
use displace_core::Address;
use displace_gpu::test_support::test_context;
use displace_gpu::TechniqueTracer;
use glam::Vec3;

#[derive(Default, Debug)]
struct Tally {
    h: HitAgreement,
    fetches_differ: usize,
    cpu_fetches: u64,
    gpu_fetches: u64,
}

impl Tally {
    fn add(&mut self, cpu: &Traced, gpu: &Traced) {
        self.cpu_fetches += cpu.fetches as u64;
        self.gpu_fetches += gpu.fetches as u64;
        if cpu.fetches != gpu.fetches {
            self.fetches_differ += 1;
        }
        let at = |t: &Traced| t.hit.map(|h| h.position);
        self.h.add(at(cpu), at(gpu));
    }

    /// Maximum mipmaps' fetch counts (see the module documentation): equal
    /// on most rays, within 2% on average.
    fn check_boundary_counts(&self, what: &str) {
        assert!(
            self.fetches_differ * 2 <= self.h.rays,
            "{what}: fetch counts differ on half the rays: {self:?}"
        );
        let (c, g) = (self.cpu_fetches as f64, self.gpu_fetches as f64);
        assert!(
            (c - g).abs() <= 0.02 * c,
            "{what}: mean fetches differ by more than 2%: {self:?}"
        );
    }

    /// Maximum mipmaps within a budget: the same answer on 90% of rays.
    fn check_budget_limited(&self, what: &str) {
        eprintln!("{what}: {self:?}");
        assert!(
            self.h.hits * 3 > self.h.rays,
            "{what}: too few hits: {self:?}"
        );
        assert!(
            (self.h.hit_miss_differ + self.h.far) * 10 <= self.h.rays,
            "{what}: answers differ on more than 10% of rays: {self:?}"
        );
        self.check_boundary_counts(what);
    }

    fn check(&self, what: &str, exact_counts: bool) {
        eprintln!("{what}: {self:?}");
        let allowed = self.h.rays / 1000;
        assert!(
            self.h.hits * 3 > self.h.rays,
            "{what}: too few hits to mean anything: {self:?}"
        );
        assert!(
            self.cpu_fetches >= self.h.hits as u64,
            "{what}: hits that cost nothing: {self:?}"
        );
        self.h.check(what, self);
        if exact_counts {
            assert!(
                self.fetches_differ <= allowed,
                "{what}: fetch counts differ on more than 0.1% of rays: {self:?}"
            );
        } else {
            self.check_boundary_counts(what);
        }
    }
}

/// A random map with every precomputation, and rays over its one tile.
fn random_maps(rng: &mut Rng, address: Address) -> Maps {
    let displacement = random_map(rng, address);
    let aspect = displacement.aspect();
    let height = displacement.height.clone();
    Maps {
        cones: Some(ConeMap::build(&height, aspect, ConeKind::Conservative)),
        relaxed: Some(ConeMap::build(&height, aspect, ConeKind::Relaxed)),
        pyramid: Some(MaxPyramid::build(&height)),
        displacement: Some(displacement),
        ..Maps::new(height, aspect)
    }
}

/// Maximum mipmaps never run out of this budget on the test's maps (at
/// most 33x33 cells): their hits must then agree like every other
/// technique's.
const AMPLE: u32 = 4096;

fn agreement(techniques: &[Technique], address: Address, seed: u64) {
    agreement_at(techniques, &[4, 16, 64], address, seed);
}

fn agreement_at(techniques: &[Technique], budgets: &[u32], address: Address, seed: u64) {
    let Some(ctx) = test_context() else { return };
    let mut rng = Rng::new(seed);
    let mut tallies: Vec<Vec<Tally>> = techniques
        .iter()
        .map(|_| budgets.iter().map(|_| Tally::default()).collect())
        .collect();
    for _ in 0..5 {
        let maps = random_maps(&mut rng, address);
        let [ax, ay] = maps.aspect;
        let rays = random_rays(&mut rng, Vec3::new(ax, ay, 1.0), 500);
        let tracer = TechniqueTracer::new(ctx, &maps).unwrap();
        for (t, row) in techniques.iter().zip(&mut tallies) {
            for (&budget, tally) in budgets.iter().zip(row.iter_mut()) {
                let gpu = tracer.trace(ctx, &rays, *t, budget).unwrap();
                assert_eq!(gpu.len(), rays.len());
                for (ray, g) in rays.iter().zip(&gpu) {
                    tally.add(&t.trace(&maps, ray, budget).unwrap(), g);
                }
            }
        }
    }
    for (t, row) in techniques.iter().zip(&tallies) {
        for (&budget, tally) in budgets.iter().zip(row) {
            let what = format!("{} {budget} {}", t.name(), address.name());
            match (*t == Technique::MaxMip, budget < AMPLE) {
                (true, true) => tally.check_budget_limited(&what),
                (true, false) => tally.check(&what, false),
                (false, _) => tally.check(&what, true),
            }
        }
    }
}

#[test]
fn parallax_and_linear_searches_agree() {
    // Parallax, steep parallax, POM, Bevy's two and relief mapping: the
    // first six of `Technique::ALL`.
    let searches = &Technique::ALL[..6];
    assert_eq!(searches[0], Technique::Parallax);
    assert_eq!(searches[5], Technique::Relief);
    agreement(searches, Address::Clamp, 51);
}

#[test]
fn cones_and_max_mipmaps_agree() {
    agreement(
        &[Technique::Cone, Technique::RelaxedCone, Technique::MaxMip],
        Address::Clamp,
        52,
    );
}

#[test]
fn max_mipmaps_with_ample_budget_agree_on_every_hit() {
    agreement_at(&[Technique::MaxMip], &[AMPLE], Address::Clamp, 57);
    agreement_at(&[Technique::MaxMip], &[AMPLE], Address::Repeat, 58);
}

#[test]
fn distance_mapping_agrees() {
    agreement(
        &[Technique::DistanceFixed, Technique::Distance],
        Address::Clamp,
        53,
    );
}

#[test]
fn repeat_addressing_agrees() {
    agreement(
        &[
            Technique::Pom,
            Technique::Relief,
            Technique::MaxMip,
            Technique::Distance,
        ],
        Address::Repeat,
        54,
    );
}

#[test]
fn missing_precomputations_and_bad_rays_are_refused() {
    let Some(ctx) = test_context() else { return };
    let mut rng = Rng::new(55);
    let full = random_maps(&mut rng, Address::Clamp);
    let bare = Maps::new(full.height.clone(), full.aspect);
    let tracer = TechniqueTracer::new(ctx, &bare).unwrap();
    let ray = displace_core::MapRay::new(Vec3::new(0.3, 0.3, 2.0), Vec3::new(0.1, 0.2, -1.0));
    for t in Technique::ALL {
        let cpu = t.trace(&bare, &ray, 8);
        let gpu = tracer.trace(ctx, &[ray], t, 8);
        assert_eq!(cpu.is_ok(), gpu.is_ok(), "{}", t.name());
        if let (Ok(c), Ok(g)) = (cpu, gpu) {
            assert_eq!(c.fetches, g[0].fetches, "{}", t.name());
        }
    }
    let nan = displace_core::MapRay {
        origin: Vec3::new(0.0, f32::NAN, 0.0),
        dir: Vec3::Z,
    };
    let e = tracer
        .trace(ctx, &[ray, nan], Technique::Pom, 8)
        .unwrap_err();
    assert!(e.to_string().starts_with("ray 1:"), "{e}");
    let mut other = full.clone();
    other.aspect = [other.aspect[0] * 2.0, other.aspect[1]];
    assert!(
        TechniqueTracer::new(ctx, &other).is_err(),
        "a distance map baked for another extent"
    );
    assert!(tracer
        .trace(ctx, &[], Technique::Relief, 8)
        .unwrap()
        .is_empty());
}

#[test]
fn gpu_cost_is_measured_for_every_technique() {
    let Some(ctx) = test_context() else { return };
    let mut rng = Rng::new(56);
    let maps = random_maps(&mut rng, Address::Clamp);
    let [ax, ay] = maps.aspect;
    let rays = random_rays(&mut rng, Vec3::new(ax, ay, 1.0), 4096);
    let runs: Vec<_> = Technique::ALL.iter().map(|&t| (t, 16)).collect();
    let costs = displace_gpu::technique_costs(ctx, &maps, &rays, &runs, 2).unwrap();
    assert_eq!(costs.len(), runs.len());
    for c in &costs {
        eprintln!(
            "{} 16: {:.3} ms per 1M rays ({})",
            c.technique.name(),
            c.ms_per_mray(),
            if c.timing.gpu_timestamps {
                "timestamps"
            } else {
                "wall clock"
            }
        );
        assert!(c.timing.wall_ms_per_frame > 0.0, "{c:?}");
        assert!(
            c.ms_per_mray().is_finite() && c.ms_per_mray() >= 0.0,
            "{c:?}"
        );
        assert_eq!(c.rays, rays.len());
    }
}
