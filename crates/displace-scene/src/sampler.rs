//! Deterministic randomness: every pixel sample owns a generator seeded from
//! a hash of `(seed, x, y, sample)`, so a render is identical whatever the
//! thread count or tiling, and crops stitch bit-exactly (the randomness
//! convention of `docs/architecture.md`). The same hash keys the bake
//! cache; the renderers' per-sample streams build on these.

// SplitMix64's finaliser (Steele et al. 2014) hashes the words together.
use displace_core::random::mix64 as mix;
use glam::Vec2;

/// Hashes `words` into one seed: the per-sample seed of
/// [`Rng::for_sample`], and the bake cache's keys.
pub fn hash(words: &[u64]) -> u64 {
    hash_iter(words.iter().copied())
}

/// [`hash`] of words as they come, without collecting them first (the
/// bake cache's checksum over a whole distance map).
pub fn hash_iter(words: impl IntoIterator<Item = u64>) -> u64 {
    words.into_iter().fold(0x9e37_79b9_7f4a_7c15u64, |h, w| {
        mix(h ^ mix(w.wrapping_add(0x9e37_79b9_7f4a_7c15)))
    })
}

/// PCG32 (O'Neill 2014): small state, good statistics, fast.
#[derive(Clone, Debug)]
pub struct Rng {
    state: u64,
    inc: u64,
}

impl Rng {
    /// A generator on `stream` from `seed` (PCG's seeding procedure).
    pub fn new(seed: u64, stream: u64) -> Self {
        let mut r = Self {
            state: 0,
            inc: (stream << 1) | 1,
        };
        r.next_u32();
        r.state = r.state.wrapping_add(seed);
        r.next_u32();
        r
    }

    /// The generator of one pixel sample.
    pub fn for_sample(seed: u64, x: u32, y: u32, sample: u32) -> Self {
        let h = hash(&[seed, x as u64, y as u64, sample as u64]);
        Self::new(h, mix(h))
    }

    /// The next 32 random bits.
    #[inline]
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(self.inc);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }

    /// Uniform in `[0, 1)`.
    #[inline]
    pub fn next_f32(&mut self) -> f32 {
        (self.next_u32() >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
    }

    /// Two uniform numbers in `[0, 1)`.
    #[inline]
    pub fn next_2d(&mut self) -> Vec2 {
        Vec2::new(self.next_f32(), self.next_f32())
    }
}

/// Where the path integrator's uniform numbers come from (`image.sampler`,
/// `--sampler`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SamplerKind {
    /// A PCG stream per pixel sample, the camera's film position jittered
    /// in its stratum: the Whitted integrator's numbers.
    #[default]
    Independent,
    /// Owen-scrambled Sobol points padded a dimension pair at a time
    /// ([`crate::sobol`]): a pixel's samples stratify every 2D decision of
    /// a path (film, light, BSDF) at every scale (pbrt-v4 section 8.7).
    Sobol,
}

impl SamplerKind {
    /// Every kind, in the order the scene format lists them.
    pub const ALL: [Self; 2] = [Self::Independent, Self::Sobol];

    /// The name a scene file and the command line use.
    pub fn name(self) -> &'static str {
        match self {
            Self::Independent => "independent",
            Self::Sobol => "sobol",
        }
    }
}

impl std::str::FromStr for SamplerKind {
    type Err = crate::Error;
    fn from_str(s: &str) -> Result<Self, crate::Error> {
        let choices = Self::ALL.map(|k| (k.name(), k));
        displace_core::names::parse_known("sampler", s, &choices).map_err(crate::Error::Option)
    }
}

/// Columns and rows of the stratification grid for `n` samples: as square as
/// possible, `nx * ny >= n`.
pub fn strata(n: u32) -> (u32, u32) {
    let nx = (n as f32).sqrt().ceil().max(1.0) as u32;
    let ny = n.div_ceil(nx).max(1);
    (nx, ny)
}

/// Sample `i` of `n` jittered within its stratum of the unit square
/// (Cook, Porter, Carpenter 1984, "jittered" sampling).
#[inline]
pub fn jittered(i: u32, n: u32, rng: &mut Rng) -> Vec2 {
    let (nx, ny) = strata(n);
    let (sx, sy) = (i % nx, (i / nx) % ny);
    let j = rng.next_2d();
    Vec2::new((sx as f32 + j.x) / nx as f32, (sy as f32 + j.y) / ny as f32)
}

/// Shirley-Chiu concentric map of the unit square onto the unit disk.
pub fn concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o == Vec2::ZERO {
        return Vec2::ZERO;
    }
    let (r, theta) = if o.x.abs() > o.y.abs() {
        (o.x, std::f32::consts::FRAC_PI_4 * (o.y / o.x))
    } else {
        (
            o.y,
            std::f32::consts::FRAC_PI_2 - std::f32::consts::FRAC_PI_4 * (o.x / o.y),
        )
    };
    r * Vec2::new(theta.cos(), theta.sin())
}
