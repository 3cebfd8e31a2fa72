//! Measuring the displacement techniques of [`displace_core::techniques`] against
//! the exact reference, the data behind `displace compare` and
//! BENCHMARKS.md: seeded rays per view elevation ([`elevation_rays`]), every
//! technique and budget traced on them ([`measure_elevation`]), each hit
//! scored in texels against the exact intersection ([`score`]), the
//! cheapest budget within an error bound ([`equal_error`]), the time and
//! memory of each precomputation ([`prepare`]) and the peak memory of a
//! whole comparison ([`peak`]). The same budget means the same work across
//! families: layers of Policarpo and Oliveira's relief search, cone steps
//! (Dummer 2006; Policarpo and Oliveira's relaxed cones, GPU Gems 3 ch. 18), nodes of Tevs et al. 2008's
//! maximum mipmaps, or sphere-tracing steps of Donnelly's distance map (GPU
//! Gems 2 ch. 8), so error can be read against fetches per ray.
//!
//! Everything here is plain data and functions; reading maps, progress and
//! writing files are the caller's ([`csv`] writes to any [`std::io::Write`]).

pub mod csv;
pub mod peak;
mod precompute;
mod run;
mod score;

pub use precompute::{prepare, Precompute};
pub use run::{elevation_rays, exact_hits, measure_elevation, ray_seed};
pub use score::{equal_error, score, texel_error};

use displace_core::techniques::Technique;

/// What a comparison runs: which techniques at which budgets, on how many
/// rays per view elevation.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The techniques compared, in the order of the rows.
    pub techniques: Vec<Technique>,
    /// Budgets (layers, steps or node visits) of every technique that takes
    /// one ([`Technique::uses_budget`]).
    pub budgets: Vec<u32>,
    /// View elevations in degrees above the face.
    pub elevations: Vec<f32>,
    /// Rays per map and elevation.
    pub rays: usize,
}

impl Plan {
    /// The budgets `tech` runs at: the plan's, or one run for a technique
    /// without a budget (parallax offset mapping reads one height).
    pub fn budgets_for(&self, tech: Technique) -> &[u32] {
        if tech.uses_budget() {
            &self.budgets
        } else {
            &[1]
        }
    }
}

/// One technique at one budget on one map and elevation: a row of
/// `compare.csv`.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Short name of the height map.
    pub map: String,
    /// View elevation, degrees above the face.
    pub elevation: f32,
    /// The technique traced.
    pub technique: Technique,
    /// Its budget (1 for a technique without one).
    pub budget: u32,
    /// Rays traced.
    pub rays: usize,
    /// Fraction of rays whose hit or miss disagrees with the exact one.
    pub wrong: f64,
    /// Mean hit error over the rays both hit, texels.
    pub mean_error: f64,
    /// 99th percentile of that error, texels.
    pub p99_error: f64,
    /// Mean texture fetches per ray: the cost a GPU pays.
    pub fetches: f64,
    /// Median CPU time per ray over chunks of rays, nanoseconds.
    pub ns_per_ray: f64,
    /// GPU time per ray, nanoseconds, when the caller timed it there.
    pub gpu_ns_per_ray: Option<f64>,
}

/// Why a comparison stopped.
#[derive(Debug, thiserror::Error)]
pub enum CompareError {
    /// The distance map (needed by the exact reference) did not bake.
    #[error("baking the distance map")]
    Bake(#[source] displace_core::Error),
    /// A technique refused to trace (its precomputation is missing).
    #[error("tracing {technique} at budget {budget}")]
    Trace {
        /// The technique's name.
        technique: &'static str,
        /// The budget it ran at.
        budget: u32,
        /// What it said.
        #[source]
        source: displace_core::Error,
    },
}
