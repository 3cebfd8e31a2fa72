//! The precomputations of the compared techniques, built and timed: the
//! cost a technique pays before its first ray, reported beside its cost
//! per ray (cone maps: Dummer 2006, and Policarpo and Oliveira's relaxed ones, GPU
//! Gems 3 ch. 18; maximum
//! mipmaps: Tevs et al. 2008; the distance map: Donnelly, GPU Gems 2 ch. 8,
//! section 8.4).

use super::CompareError;
use displace_core::techniques::{ConeKind, ConeMap, Maps, MaxPyramid, Needs, Technique};
use displace_core::{bake, BakeOptions, Extent, HeightMap};
use std::sync::atomic::AtomicBool;
use std::sync::Arc;
use std::time::Instant;

/// Time and memory of one precomputation: a row of `precompute.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct Precompute {
    /// What was built (`cone map`, `relaxed cone map`, `max pyramid`,
    /// `distance map`).
    pub name: &'static str,
    /// Wall time of the build.
    pub seconds: f64,
    /// Bytes it holds.
    pub bytes: usize,
}

/// Builds every precomputation `techniques` need from `height`, timed. The
/// distance map is always baked at `depth` slices, since the exact
/// reference traces through it, and reported only when a distance technique
/// is compared. Each build stops when `cancel` is raised (relaxed cones of
/// a large map take minutes), in [`displace_core::Error::Cancelled`].
pub fn prepare(
    height: HeightMap,
    extent: Extent,
    depth: usize,
    techniques: &[Technique],
    cancel: &Arc<AtomicBool>,
) -> Result<(Maps, Vec<Precompute>), CompareError> {
    let aspect = extent.aspect();
    let mut maps = Maps::new(height.clone(), aspect);
    let mut report = Vec::new();
    let needs = |n: Needs| techniques.iter().any(|t| t.needs() == n);
    if needs(Needs::ConservativeCones) {
        let build = || {
            ConeMap::build_with(
                &height,
                aspect,
                ConeKind::Conservative,
                None,
                Some(&**cancel),
            )
        };
        let cones = timed(&mut report, "cone map", build, cone_bytes);
        maps.cones = Some(cones.map_err(CompareError::Bake)?);
    }
    if needs(Needs::RelaxedCones) {
        let build =
            || ConeMap::build_with(&height, aspect, ConeKind::Relaxed, None, Some(&**cancel));
        let cones = timed(&mut report, "relaxed cone map", build, cone_bytes);
        maps.relaxed = Some(cones.map_err(CompareError::Bake)?);
    }
    if needs(Needs::Pyramid) {
        let build = || MaxPyramid::build(&height);
        maps.pyramid = Some(timed(&mut report, "max pyramid", build, MaxPyramid::bytes));
    }
    let mut opts = BakeOptions::new([height.width(), height.height(), depth], extent);
    opts.cancel = Some(Arc::clone(cancel));
    let start = Instant::now();
    let baked = bake(&height, &opts).map_err(CompareError::Bake)?;
    let seconds = start.elapsed().as_secs_f64();
    if needs(Needs::DistanceMap) {
        report.push(Precompute {
            name: "distance map",
            seconds,
            bytes: baked.distance.data().len() * 4,
        });
    }
    maps.displacement = Some(baked);
    Ok((maps, report))
}

/// Builds one precomputation and reports the time it took and its size.
fn cone_bytes(c: &displace_core::Result<ConeMap>) -> usize {
    c.as_ref().map_or(0, ConeMap::bytes)
}

fn timed<T>(
    report: &mut Vec<Precompute>,
    name: &'static str,
    build: impl FnOnce() -> T,
    bytes: impl Fn(&T) -> usize,
) -> T {
    let start = Instant::now();
    let built = build();
    let seconds = start.elapsed().as_secs_f64();
    report.push(Precompute {
        name,
        seconds,
        bytes: bytes(&built),
    });
    built
}
