//! Piecewise-constant distributions for importance sampling: in one
//! dimension (picking a light in proportion to its power) and in two (an
//! environment map by its luminance), after pbrt-v3 section 13.6.7 and
//! pbrt-v4 section A.4.1 (`PiecewiseConstant1D`, `PiecewiseConstant2D`).

/// A piecewise-constant density on `[0, 1)` proportional to non-negative
/// weights, with its cumulative distribution for inversion.
#[derive(Clone, Debug)]
pub struct Distribution1D {
    /// The weights as given.
    func: Vec<f32>,
    /// `cdf[i]` = the probability of the first `i` pieces; `cdf[n] = 1`.
    cdf: Vec<f32>,
    /// Sum of the weights over the pieces (each piece `1 / n` wide).
    integral: f32,
}

impl Distribution1D {
    /// The distribution of `weights` (each finite and >= 0). When every
    /// weight is 0 the distribution is uniform, as pbrt's is, and
    /// [`Distribution1D::total`] says 0.
    pub fn new(weights: &[f32]) -> Self {
        let n = weights.len().max(1);
        let mut cdf = Vec::with_capacity(n + 1);
        cdf.push(0.0f64);
        let mut sum = 0.0f64;
        for &w in weights {
            sum += w.max(0.0) as f64;
            cdf.push(sum);
        }
        if weights.is_empty() {
            cdf.push(0.0);
        }
        let cdf: Vec<f32> = if sum > 0.0 {
            cdf.iter().map(|c| (c / sum) as f32).collect()
        } else {
            (0..=n).map(|i| i as f32 / n as f32).collect()
        };
        Self {
            func: if weights.is_empty() {
                vec![0.0]
            } else {
                weights.iter().map(|w| w.max(0.0)).collect()
            },
            cdf,
            integral: (sum / n as f64) as f32,
        }
    }

    /// Number of pieces.
    pub fn len(&self) -> usize {
        self.func.len()
    }

    /// Whether there are no pieces (never: an empty weight list is one
    /// piece of weight 0).
    pub fn is_empty(&self) -> bool {
        self.func.is_empty()
    }

    /// The sum of the weights (0 when every weight is 0).
    pub fn total(&self) -> f32 {
        self.integral * self.func.len() as f32
    }

    /// The mean weight: the integral of the step function over `[0, 1)`.
    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// The piece `u` in `[0, 1)` falls in: largest `i` with `cdf[i] <= u`,
    /// skipping pieces of zero probability.
    fn find(&self, u: f32) -> usize {
        let n = self.func.len();
        // First index whose cdf exceeds u, minus one.
        let i = self.cdf.partition_point(|&c| c <= u);
        i.saturating_sub(1).min(n - 1)
    }

    /// Picks a piece with probability proportional to its weight: the
    /// index, its probability, and `u` rescaled to `[0, 1)` within the
    /// piece (so it can be reused).
    pub fn sample_discrete(&self, u: f32) -> (usize, f32, f32) {
        let i = self.find(u);
        let (lo, hi) = (self.cdf[i], self.cdf[i + 1]);
        let p = hi - lo;
        let rest = if p > 0.0 {
            ((u - lo) / p).clamp(0.0, 1.0 - f32::EPSILON / 2.0)
        } else {
            0.0
        };
        (i, p, rest)
    }

    /// [`Distribution1D::sample_discrete`] without the rescaled `u`: the
    /// piece and its probability, for callers that draw afresh (a light
    /// chosen per vertex, many vertices at once).
    pub fn choose(&self, u: f32) -> (usize, f32) {
        let i = self.find(u);
        (i, self.cdf[i + 1] - self.cdf[i])
    }

    /// Probability of piece `i` in [`Distribution1D::sample_discrete`].
    pub fn pmf(&self, i: usize) -> f32 {
        self.cdf[i + 1] - self.cdf[i]
    }

    /// A point of `[0, 1)` distributed by the density, its density, and
    /// the piece it lies in.
    pub fn sample_continuous(&self, u: f32) -> (f32, f32, usize) {
        let (i, p, rest) = self.sample_discrete(u);
        let n = self.func.len() as f32;
        let x = ((i as f32 + rest) / n).min(1.0 - f32::EPSILON / 2.0);
        (x, p * n, i)
    }

    /// The density at `x` in `[0, 1)`.
    pub fn pdf(&self, x: f32) -> f32 {
        let n = self.func.len();
        let i = ((x * n as f32) as usize).min(n - 1);
        self.pmf(i) * n as f32
    }
}

/// A piecewise-constant density on `[0, 1)^2` over a `width x height` grid
/// of non-negative weights (row-major, row `j` covering `v` in `[j / h,
/// (j + 1) / h)`): the marginal density of rows, and each row's conditional
/// density of columns (pbrt-v3 section 13.6.7).
#[derive(Clone, Debug)]
pub struct Distribution2D {
    rows: Vec<Distribution1D>,
    marginal: Distribution1D,
}

impl Distribution2D {
    /// `weights.len()` must be `width * height`.
    pub fn new(weights: &[f32], width: usize, height: usize) -> Self {
        assert_eq!(weights.len(), width * height);
        let rows: Vec<Distribution1D> = weights.chunks(width).map(Distribution1D::new).collect();
        let marginal = Distribution1D::new(
            &rows
                .iter()
                .map(Distribution1D::integral)
                .collect::<Vec<_>>(),
        );
        Self { rows, marginal }
    }

    /// A point `(u, v)` distributed by the density, and its density.
    pub fn sample(&self, u: glam::Vec2) -> (glam::Vec2, f32) {
        let (v, pv, j) = self.marginal.sample_continuous(u.y);
        let (x, pu, _) = self.rows[j].sample_continuous(u.x);
        (glam::Vec2::new(x, v), pu * pv)
    }

    /// The density at `(u, v)`.
    pub fn pdf(&self, uv: glam::Vec2) -> f32 {
        let h = self.rows.len();
        let j = ((uv.y * h as f32) as usize).min(h - 1);
        self.marginal.pdf(uv.y) * self.rows[j].pdf(uv.x)
    }

    /// The mean weight over the grid.
    pub fn integral(&self) -> f32 {
        self.marginal.integral()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec2;

    #[test]
    fn discrete_sampling_follows_the_weights() {
        let d = Distribution1D::new(&[1.0, 0.0, 3.0]);
        assert_eq!(d.pmf(0), 0.25);
        assert_eq!(d.pmf(1), 0.0);
        assert_eq!(d.pmf(2), 0.75);
        assert_eq!(d.sample_discrete(0.1).0, 0);
        assert_eq!(d.sample_discrete(0.25).0, 2);
        assert_eq!(d.sample_discrete(0.999).0, 2);
        let (_, _, rest) = d.sample_discrete(0.625);
        assert!((rest - 0.5).abs() < 1e-6);
        assert_eq!(d.total(), 4.0);
    }

    #[test]
    fn zero_weights_are_uniform_and_say_so() {
        let d = Distribution1D::new(&[0.0, 0.0]);
        assert_eq!(d.total(), 0.0);
        assert_eq!(d.pmf(0), 0.5);
        let e = Distribution1D::new(&[]);
        assert_eq!(e.len(), 1);
        assert_eq!(e.total(), 0.0);
    }

    #[test]
    fn continuous_density_integrates_to_one_and_matches_samples() {
        let d = Distribution2D::new(&[1.0, 2.0, 0.0, 5.0, 1.0, 1.0], 3, 2);
        // Density integrates to 1 over the grid.
        let mut sum = 0.0;
        for j in 0..2 {
            for i in 0..3 {
                sum += d.pdf(Vec2::new((i as f32 + 0.5) / 3.0, (j as f32 + 0.5) / 2.0)) / 6.0;
            }
        }
        assert!((sum - 1.0).abs() < 1e-5, "{sum}");
        // A sample's reported density is the density at it.
        for k in 0..50 {
            let u = Vec2::new((k as f32 * 0.618).fract(), (k as f32 * 0.379).fract());
            let (p, pdf) = d.sample(u);
            assert!((d.pdf(p) - pdf).abs() < 1e-4 * pdf.max(1.0), "{p} {pdf}");
            // Never the empty cell (column 2 of row 0).
            assert!(!(p.y < 0.5 && p.x >= 2.0 / 3.0), "{p}");
        }
    }
}
