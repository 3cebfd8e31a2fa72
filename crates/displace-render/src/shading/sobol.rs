//! Owen-scrambled Sobol points, padded two dimensions at a time: the
//! low-discrepancy samples of the path integrator.
//!
//! Each pair of dimensions of a pixel's samples is the first two dimensions
//! of the Sobol sequence (Sobol 1967), a (0, 2)-sequence in base 2: any
//! `2^m` consecutive aligned points put exactly one point in every
//! elementary interval of area `2^-m`, so a pixel's `2^m` samples stratify
//! the light's area, the BSDF's lobe and the film all at once, at every
//! scale. Each coordinate is then Owen scrambled (Owen 1995; nested uniform
//! scrambling by a hash, Laine and Karras 2011, "Stratified sampling for
//! stochastic transparency", with the improved hash of Burley 2020,
//! "Practical Hash-based Owen Scrambling", JCGT 9(4), section 4), which
//! keeps the net and makes each point uniformly distributed, so the
//! estimator stays unbiased. The sample index is Owen scrambled too, with
//! a seed per pixel and dimension pair (Burley 2020, section 5,
//! "shuffling"), which decorrelates one pair from the next ("padding",
//! Kollig and Keller 2002; pbrt-v4's `PaddedSobolSampler`, section 8.7.3).
//!
//! Everything here is a pure function of its inputs: a sample is the same
//! whatever thread or tile computes it.

/// The `2^32`-scaled coordinate of point `i` in Sobol's first dimension:
/// the van der Corput sequence, the bits of `i` mirrored.
#[inline]
pub fn sobol0(i: u32) -> u32 {
    i.reverse_bits()
}

/// Point `i` in Sobol's second dimension. Its direction numbers are the
/// rows of Pascal's triangle mod 2 (primitive polynomial `x + 1`, all
/// initial `m_k = 1`), so each is the previous one xor itself shifted.
#[inline]
pub fn sobol1(mut i: u32) -> u32 {
    let mut v = 1u32 << 31;
    let mut r = 0;
    while i != 0 {
        if i & 1 != 0 {
            r ^= v;
        }
        i >>= 1;
        v ^= v >> 1;
    }
    r
}

/// A hash of `x` under which each bit depends only on the bits below it
/// and on the seed: every step (multiplying, adding, xoring a multiple by
/// an even constant) carries upwards only, and each is a bijection. Burley
/// 2020, listing 3, with the constants of its improved form (Vegdahl 2021).
#[inline]
fn laine_karras(mut x: u32, seed: u32) -> u32 {
    x ^= x.wrapping_mul(0x3d20_adea);
    x = x.wrapping_add(seed);
    x = x.wrapping_mul((seed >> 16) | 1);
    x ^= x.wrapping_mul(0x0552_6c56);
    x ^= x.wrapping_mul(0x53a2_2864);
    x
}

/// Nested uniform (Owen) scrambling of the binary fraction `x / 2^32`:
/// each bit is flipped or not by a hash of the bits above it, so points
/// that share their leading bits (an elementary interval) stay together.
#[inline]
pub fn owen_scramble(x: u32, seed: u32) -> u32 {
    laine_karras(x.reverse_bits(), seed).reverse_bits()
}

/// A 32-bit fraction as a float in `[0, 1)` (its top 24 bits, exactly).
#[inline]
pub fn to_unit(x: u32) -> f32 {
    (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// The direction numbers of Sobol's second dimension: `V[b]` is what bit
/// `b` of the index xors into the point.
const fn directions() -> [u32; 32] {
    let mut v = [0u32; 32];
    let mut d = 1u32 << 31;
    let mut b = 0;
    while b < 32 {
        v[b] = d;
        d ^= d >> 1;
        b += 1;
    }
    v
}

/// [`sobol1`] in the mirrored domain, a byte at a time: for `t` the
/// mirrored index, `reverse(sobol1(reverse(t)))` is the xor of
/// `MIRRORED[k][byte k of t]`. Sobol points are linear in the index's
/// bits over GF(2), so four look-ups replace a loop over 32 bits.
const MIRRORED: [[u32; 256]; 4] = {
    let v = directions();
    let mut t = [[0u32; 256]; 4];
    let mut k = 0;
    while k < 4 {
        let mut x = 0;
        while x < 256 {
            let mut acc = 0u32;
            let mut j = 0;
            while j < 8 {
                if x & (1 << j) != 0 {
                    // Bit 8k + j of the mirrored index is bit 31 - 8k - j
                    // of the index.
                    acc ^= v[31 - (8 * k + j)].reverse_bits();
                }
                j += 1;
            }
            t[k][x] = acc;
            x += 1;
        }
        k += 1;
    }
    t
};

#[inline]
fn mirrored_sobol1(t: u32) -> u32 {
    let b = t.to_le_bytes();
    MIRRORED[0][b[0] as usize]
        ^ MIRRORED[1][b[1] as usize]
        ^ MIRRORED[2][b[2] as usize]
        ^ MIRRORED[3][b[3] as usize]
}

/// The three 32-bit seeds of one dimension pair (the index shuffle and
/// the two coordinates' scrambles) from one 64-bit hash.
#[inline]
fn seeds(seed: u64) -> (u32, u32, u32) {
    let third = (seed.wrapping_mul(0x9e37_79b9_7f4a_7c15) >> 32) as u32;
    (seed as u32, (seed >> 32) as u32, third)
}

/// Sample `index` of the scrambled, shuffled 2D Sobol points under `seed`
/// (one seed per pixel and dimension pair): the index is shuffled, then
/// each coordinate scrambled with its own part of the seed. For any `m`,
/// indices `0..2^m` give a (0, m, 2)-net.
///
/// Worked partly in the mirrored domain: with `t = lk(reverse(index))`,
/// the shuffled index `i` is `reverse(t)`, the first coordinate
/// `owen(sobol0(i)) = reverse(lk(i))` and the second
/// `owen(sobol1(i)) = reverse(lk(mirrored_sobol1(t)))`: four bit reversals
/// in all.
#[inline]
pub fn sample_2d(index: u32, seed: u64) -> (u32, u32) {
    let (si, sx, sy) = seeds(seed);
    let t = laine_karras(index.reverse_bits(), si);
    (
        laine_karras(t.reverse_bits(), sx).reverse_bits(),
        laine_karras(mirrored_sobol1(t), sy).reverse_bits(),
    )
}

/// Sample `index` of the scrambled, shuffled 1D points under `seed`: for
/// any `m`, indices `0..2^m` put one point in each interval of `2^-m`.
#[inline]
pub fn sample_1d(index: u32, seed: u64) -> u32 {
    let (si, sx, _) = seeds(seed);
    let i = laine_karras(index.reverse_bits(), si).reverse_bits();
    laine_karras(i, sx).reverse_bits()
}

#[cfg(test)]
mod tests {
    use super::*;
    use displace_core::random::SplitMix64;

    /// Whether `points` (each `2^m` in number) put one point in each
    /// elementary interval `2^-a x 2^-(m - a)` for every `a`.
    fn is_net(points: &[(u32, u32)], m: u32) -> bool {
        (0..=m).all(|a| {
            let mut seen = vec![false; 1 << m];
            points.iter().all(|&(x, y)| {
                let cx = if a == 0 { 0 } else { x >> (32 - a) };
                let cy = if a == m { 0 } else { y >> (32 - (m - a)) };
                let k = ((cx << (m - a)) | cy) as usize;
                !std::mem::replace(&mut seen[k], true)
            })
        })
    }

    #[test]
    fn the_unscrambled_points_are_sobol() {
        // The first points of the second dimension (in index order, not
        // Gray-code order): 0, 1/2, 3/4, 1/4, 5/8, 1/8.
        let want = [0.0, 0.5, 0.75, 0.25, 0.625, 0.125];
        for (i, w) in want.iter().enumerate() {
            assert_eq!(to_unit(sobol1(i as u32)), *w);
        }
        assert_eq!(to_unit(sobol0(3)), 0.75);
        let pts: Vec<_> = (0..256u32).map(|i| (sobol0(i), sobol1(i))).collect();
        assert!(is_net(&pts, 8));
    }

    #[test]
    fn scrambled_shuffled_points_are_nets_for_every_seed() {
        let mut rng = SplitMix64::new(17);
        for _ in 0..200 {
            let seed = rng.next_u64();
            for m in 0..=8 {
                let pts: Vec<_> = (0..1u32 << m).map(|i| sample_2d(i, seed)).collect();
                assert!(is_net(&pts, m), "seed {seed:#x}, m {m}");
                let mut strata = vec![false; 1 << m];
                for i in 0..1u32 << m {
                    let k = if m == 0 {
                        0
                    } else {
                        sample_1d(i, seed) >> (32 - m)
                    };
                    assert!(!std::mem::replace(&mut strata[k as usize], true));
                }
            }
        }
    }

    #[test]
    fn the_mirrored_tables_are_sobol1() {
        let mut rng = SplitMix64::new(5);
        for _ in 0..10_000 {
            let i = rng.next_u64() as u32;
            assert_eq!(mirrored_sobol1(i.reverse_bits()), sobol1(i).reverse_bits());
        }
        // And the shortcut is the definition: shuffle, then scramble.
        for _ in 0..1000 {
            let (index, seed) = (rng.next_u64() as u32 & 0xffff, rng.next_u64());
            let (si, sx, sy) = seeds(seed);
            let i = owen_scramble(index, si);
            let want = (owen_scramble(sobol0(i), sx), owen_scramble(sobol1(i), sy));
            assert_eq!(sample_2d(index, seed), want);
            assert_eq!(sample_1d(index, seed), want.0);
        }
    }

    #[test]
    fn scrambling_is_a_bijection_that_keeps_prefixes_together() {
        let mut rng = SplitMix64::new(3);
        for _ in 0..1000 {
            let (a, b, seed) = (
                rng.next_u64() as u32,
                rng.next_u64() as u32,
                rng.next_u64() as u32,
            );
            let (sa, sb) = (owen_scramble(a, seed), owen_scramble(b, seed));
            assert_eq!(a == b, sa == sb);
            // Equal leading bits stay equal (nested scrambling).
            let common = (a ^ b).leading_zeros();
            assert!((sa ^ sb).leading_zeros() >= common, "{a:#x} {b:#x}");
        }
    }

    #[test]
    fn scrambled_points_are_uniform_over_seeds() {
        // One point of each seed: its mean and variance are the uniform
        // distribution's (each Owen-scrambled point is uniform).
        let mut rng = SplitMix64::new(9);
        let n = 100_000;
        let (mut s, mut s2, mut c) = (0.0f64, 0.0f64, 0.0f64);
        for _ in 0..n {
            let (x, y) = sample_2d(5, rng.next_u64());
            let (x, y) = (to_unit(x) as f64, to_unit(y) as f64);
            s += x;
            s2 += x * x;
            c += (x - 0.5) * (y - 0.5);
        }
        let n = n as f64;
        assert!((s / n - 0.5).abs() < 0.005, "{}", s / n);
        assert!((s2 / n - 1.0 / 3.0).abs() < 0.005, "{}", s2 / n);
        assert!((c / n).abs() < 0.003, "{}", c / n);
    }
}
