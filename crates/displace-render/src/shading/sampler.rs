//! The numbers of one pixel sample ([`SampleStream`]): independent
//! ([`Rng`]) or Owen-scrambled Sobol points ([`crate::shading::sobol`]), on the
//! deterministic per-sample seeds of [`displace_scene::sampler`], which
//! this module re-exports.

pub use displace_scene::sampler::*;

// SplitMix64's finaliser (Steele et al. 2014) hashes the words together.
use crate::shading::sobol::{sample_1d, sample_2d, to_unit};
use displace_core::random::mix64 as mix;
use glam::Vec2;

/// The uniform numbers of one pixel sample, dimension by dimension, from
/// either kind of [`SamplerKind`]. With Sobol points, a dimension is a
/// decision of the path (the film position, a bounce's light sample),
/// which [`SampleStream::set_dimension`] pins so that the same decision of
/// every sample of a pixel draws from the same stratified set.
#[derive(Clone, Debug)]
pub struct SampleStream {
    source: Source,
    /// The dimension the next number comes from (Sobol points only).
    dim: u32,
}

#[derive(Clone, Debug)]
enum Source {
    Independent(Rng),
    Sobol {
        /// Hash of the seed and the pixel.
        pixel: u64,
        index: u32,
    },
}

impl SampleStream {
    /// The Sobol points of sample `index` of pixel `(x, y)` under `seed`.
    pub fn sobol(seed: u64, x: u32, y: u32, index: u32) -> Self {
        Self {
            source: Source::Sobol {
                pixel: hash(&[seed, x as u64, y as u64, 0x50b0_1dad]),
                index,
            },
            dim: 0,
        }
    }

    /// The stream of an independent sample already under way (the
    /// Whitted camera's generator, which the path integrator continues).
    pub fn independent(rng: Rng) -> Self {
        Self {
            source: Source::Independent(rng),
            dim: 0,
        }
    }

    /// Draws the following numbers from dimension `dim` on (no effect on
    /// independent numbers).
    #[inline]
    pub fn set_dimension(&mut self, dim: u32) {
        self.dim = dim;
    }

    /// The seed of the current dimension of pixel hash `pixel`, and on to
    /// the next dimension.
    #[inline]
    fn seed(&mut self, pixel: u64) -> u64 {
        let s = dimension_seed(pixel, self.dim);
        self.dim += 1;
        s
    }

    /// One uniform number in `[0, 1)`.
    #[inline]
    pub fn next_1d(&mut self) -> f32 {
        match self.source {
            Source::Independent(ref mut rng) => rng.next_f32(),
            Source::Sobol { pixel, index } => to_unit(sample_1d(index, self.seed(pixel))),
        }
    }

    /// The number of a choice (a light, a lobe) that may have one
    /// alternative only (`choosing` false): then a stratified stream spends
    /// nothing and returns 0, which picks the one alternative, while the
    /// independent stream draws it anyway so that its sequence, and so its
    /// images, stay as they were.
    #[inline]
    pub fn next_choice(&mut self, choosing: bool) -> f32 {
        match self.source {
            Source::Sobol { .. } if !choosing => {
                self.dim += 1;
                0.0
            }
            _ => self.next_1d(),
        }
    }

    /// Two uniform numbers in `[0, 1)`, stratified together.
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        match self.source {
            Source::Independent(ref mut rng) => rng.next_2d(),
            Source::Sobol { pixel, index } => {
                let (x, y) = sample_2d(index, self.seed(pixel));
                Vec2::new(to_unit(x), to_unit(y))
            }
        }
    }
}

/// A Sobol stream's next 2D draw, put off so that many streams' draws can
/// be made together ([`draw_2d8`]): the pixel's hash, the sample's index and
/// the dimension, all that [`SampleStream::next_2d`] reads.
#[derive(Clone, Copy, Debug, Default)]
pub struct Deferred2d {
    pixel: u64,
    index: u32,
    dim: u32,
}

impl SampleStream {
    /// [`SampleStream::next_2d`] put off: the stream moves on to its next
    /// dimension as if it had drawn, and the draw's inputs are returned for
    /// [`draw_2d8`]. `None` for independent numbers, which depend on the
    /// draws before them and are drawn with `next_2d` in their turn.
    #[inline]
    pub fn defer_2d(&mut self) -> Option<Deferred2d> {
        match self.source {
            Source::Independent(_) => None,
            Source::Sobol { pixel, index } => {
                let d = Deferred2d {
                    pixel,
                    index,
                    dim: self.dim,
                };
                self.dim += 1;
                Some(d)
            }
        }
    }
}

/// Eight put-off draws at once, as columns (`[x, y]`, lane by lane): lane
/// `l` is what `next_2d` would have returned to the stream that put off
/// `draws[l]`, bit for bit. The hashes, the Owen scrambles, the bit
/// reversals and the Sobol table's look-ups are integer work that runs in
/// vector lanes (with AVX2 where the CPU has it: the same integers either
/// way), where one stream at a time it is a chain of dependent
/// multiplications.
pub fn draw_2d8(draws: &[Deferred2d; 8]) -> [[f32; 8]; 2] {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2, checked just above.
        return unsafe { draw_2d8_avx2(draws) };
    }
    draw_2d8_lanes(draws)
}

/// [`draw_2d8_lanes`] compiled for AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn draw_2d8_avx2(draws: &[Deferred2d; 8]) -> [[f32; 8]; 2] {
    draw_2d8_lanes(draws)
}

/// The lanes of [`draw_2d8`]: [`SampleStream::next_2d`]'s arithmetic,
/// one loop over eight streams.
#[inline(always)]
fn draw_2d8_lanes(draws: &[Deferred2d; 8]) -> [[f32; 8]; 2] {
    let mut out = [[0.0; 8]; 2];
    for (l, d) in draws.iter().enumerate() {
        let seed = dimension_seed(d.pixel, d.dim);
        let (x, y) = sample_2d(d.index, seed);
        out[0][l] = to_unit(x);
        out[1][l] = to_unit(y);
    }
    out
}

/// The seed of dimension `dim` of the stream of pixel hash `pixel`.
#[inline(always)]
fn dimension_seed(pixel: u64, dim: u32) -> u64 {
    mix(pixel.wrapping_add((dim as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn eight_put_off_draws_are_the_streams_own() {
        let mut draws = [Deferred2d::default(); 8];
        let mut want = [Vec2::ZERO; 8];
        for round in 0..50u32 {
            for l in 0..8u32 {
                let mut a = SampleStream::sobol(3, l * 7 + round, round, round * 13 + l);
                let mut b = a.clone();
                a.set_dimension(l + round % 5);
                b.set_dimension(l + round % 5);
                want[l as usize] = a.next_2d();
                draws[l as usize] = b.defer_2d().expect("a Sobol stream");
                // Both streams moved on alike.
                assert_eq!(a.next_2d(), b.next_2d());
            }
            let got = draw_2d8(&draws);
            for l in 0..8 {
                assert_eq!(
                    Vec2::new(got[0][l], got[1][l]),
                    want[l],
                    "round {round} lane {l}"
                );
                assert_eq!(draw_2d8_lanes(&draws)[0][l], got[0][l]);
            }
        }
        let rng = Rng::for_sample(1, 2, 3, 4);
        assert!(SampleStream::independent(rng).defer_2d().is_none());
    }

    #[test]
    fn same_inputs_same_stream() {
        let mut a = Rng::for_sample(7, 3, 4, 5);
        let mut b = Rng::for_sample(7, 3, 4, 5);
        let mut c = Rng::for_sample(7, 4, 3, 5);
        let va: Vec<u32> = (0..8).map(|_| a.next_u32()).collect();
        let vb: Vec<u32> = (0..8).map(|_| b.next_u32()).collect();
        let vc: Vec<u32> = (0..8).map(|_| c.next_u32()).collect();
        assert_eq!(va, vb);
        assert_ne!(va, vc);
    }

    #[test]
    fn a_pixels_sobol_samples_stratify_each_dimension_pair() {
        // 16 samples of a pixel: each 2D decision puts one sample in each
        // cell of a 4x4 grid (a (0, 4, 2)-net has one in each square).
        for kind_dim in 0..6 {
            let mut seen = [false; 16];
            for s in 0..16 {
                let mut st = SampleStream::sobol(3, 10, 20, s);
                st.set_dimension(kind_dim);
                let p = st.next_2d();
                let k = (p.y * 4.0) as usize * 4 + (p.x * 4.0) as usize;
                assert!(!seen[k], "dimension {kind_dim}");
                seen[k] = true;
            }
        }
        // Another pixel, another set; the same pixel, the same numbers.
        let a = SampleStream::sobol(3, 10, 20, 0).next_2d();
        let b = SampleStream::sobol(3, 11, 20, 0).next_2d();
        let c = SampleStream::sobol(3, 10, 20, 0).next_2d();
        assert_ne!(a, b);
        assert_eq!(a, c);
        assert_eq!("sobol".parse::<SamplerKind>().unwrap(), SamplerKind::Sobol);
        let e = "halton".parse::<SamplerKind>().unwrap_err().to_string();
        assert!(e.contains("independent, sobol"), "{e}");
    }

    #[test]
    fn jittered_samples_cover_each_stratum_once() {
        let mut rng = Rng::new(1, 2);
        let n = 16;
        let mut seen = [false; 16];
        for i in 0..n {
            let p = jittered(i, n, &mut rng);
            let k = (p.y * 4.0) as usize * 4 + (p.x * 4.0) as usize;
            assert!(!seen[k]);
            seen[k] = true;
        }
        let m = (0..100_000).map(|_| rng.next_f32()).sum::<f32>() / 100_000.0;
        assert!((m - 0.5).abs() < 0.01);
    }
}
