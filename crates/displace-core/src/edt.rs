//! Exact Euclidean distance transforms in linear time: the lower envelope of
//! parabolas of Felzenszwalb and Huttenlocher ("Distance Transforms of
//! Sampled Functions", Theory of Computing 8, 2012), applied one axis at a
//! time. Seed 000 cites Danielsson's vector propagation (section 8.4); this
//! transform is exact where Danielsson's can err by a fraction of a voxel, and
//! it is linear in the number of voxels as well.
//!
//! All functions work on *squared* distances, with per-axis voxel spacing so
//! that anisotropic grids (a distance map is much wider than it is deep) are
//! measured in physical units.
//!
//! # Precision
//! The envelope works in `f32` and in sample units: parabola `p` is
//! `(x - p)^2 + F(p)` with `F = f / spacing^2`. Two parabolas `p < q` meet at
//! `s = ((F(q) - F(p)) + (q - p)(q + p)) / (2 (q - p))`: the difference of the
//! `F` values loses nothing to the large `q^2` terms (the integer product is
//! exact below 2^24), so `s` carries the rounding of `F` only. Where rounding
//! moves an intersection by `e` samples, the two parabolas it separates differ
//! there by `2 (q - p) e`, the rounding of the numerator: about one `f32` ulp
//! of the largest squared distance along the line. Picking the other parabola
//! near a tie therefore changes a result by its own rounding error.

use std::mem::take;

/// Scratch space for the 1D transforms, reused across lines so that no line
/// allocates.
#[derive(Default)]
pub struct LineScratch {
    /// The lower envelope, a stack.
    stack: Vec<Parabola>,
    /// One periodic line with its wrapped neighbours.
    ext: Vec<f32>,
    /// Columns gathered for the second pass of [`transform_2d_with`].
    block: Vec<f32>,
}

/// One parabola of the lower envelope: site `p` (in samples; an `f32` holds
/// every index below 2^24 exactly, and saves a conversion per step), `f` and
/// `g = f / spacing^2` there, and `z`, the left end of its interval of the
/// envelope in samples. One struct, so that a step of the envelope touches
/// one cache line.
#[derive(Clone, Copy, Default)]
struct Parabola {
    p: f32,
    f: f32,
    g: f32,
    z: f32,
}

/// `line[q] <- min_p (spacing * (q - p))^2 + line[p]`, in place, for a sampled
/// function (infinite values allowed, meaning "no site here"). With
/// `periodic`, the line repeats with its length as period and the minimum
/// runs over every image, as a tiling map needs.
pub fn transform_line(line: &mut [f32], spacing: f32, periodic: bool, s: &mut LineScratch) {
    if !periodic {
        envelope(line, spacing, s);
        return;
    }
    // Every site has an image within half a period of every sample, so half
    // a period wrapped onto each side is enough (2n samples, not 3n).
    let n = line.len();
    let m = n / 2;
    let mut ext = take(&mut s.ext);
    ext.clear();
    ext.extend_from_slice(&line[n - m..]);
    ext.extend_from_slice(line);
    ext.extend_from_slice(&line[..m]);
    envelope(&mut ext, spacing, s);
    line.copy_from_slice(&ext[m..m + n]);
    s.ext = ext;
}

/// The lower envelope of the parabolas rooted at the finite samples, then
/// sampled back into `line`. The envelope keeps each parabola's site and
/// value on its own stack, so writing the results over the input is safe.
fn envelope(line: &mut [f32], spacing: f32, s: &mut LineScratch) {
    let n = line.len();
    let Some(q0) = line.iter().position(|x| x.is_finite()) else {
        return; // no site: every value stays infinite
    };
    let inv = 1.0 / (spacing * spacing);
    s.stack.resize(n + 1, Parabola::default());
    let st = &mut s.stack[..];
    let mut k = 0;
    st[0] = Parabola {
        p: q0 as f32,
        f: line[q0],
        g: line[q0] * inv,
        z: f32::NEG_INFINITY,
    };
    let mut qf = q0 as f32;
    for &fq in &line[q0 + 1..] {
        qf += 1.0;
        if !fq.is_finite() {
            continue;
        }
        let gq = fq * inv;
        // Pop while the new parabola is below the top one at the top one's
        // left end; compared by cross-multiplication, so only the pushed
        // intersection needs a division.
        loop {
            let top = st[k];
            let d2 = 2.0 * (qf - top.p);
            let num = (gq - top.g) + 0.5 * d2 * (qf + top.p);
            if k > 0 && num <= top.z * d2 {
                k -= 1;
            } else {
                k += 1;
                st[k] = Parabola {
                    p: qf,
                    f: fq,
                    g: gq,
                    z: num / d2,
                };
                break;
            }
        }
    }
    st[k + 1].z = f32::INFINITY;
    let mut k = 0;
    let mut qf = 0.0f32;
    for o in line.iter_mut() {
        while st[k + 1].z < qf {
            k += 1;
        }
        let d = spacing * (qf - st[k].p);
        *o = d * d + st[k].f;
        qf += 1.0;
    }
}

/// 2D transform of a sampled function `g` (`w x h`, row-major), in place:
/// `g'(i, j) = min (hx (i - i'))^2 + (hy (j - j'))^2 + g(i', j')`.
pub fn transform_2d(
    g: &mut [f32],
    w: usize,
    h: usize,
    spacing: [f32; 2],
    periodic: [bool; 2],
    s: &mut LineScratch,
) {
    transform_2d_with(g, w, h, spacing, periodic, s, |_, _| {}, |_, _| {});
}

/// [`transform_2d`] with the producer and consumer of the slice fused in:
/// `fill(j, row)` writes row `j`'s input just before that row is transformed,
/// while it is in cache, and `finish(start, run)` maps, in place, each run of
/// results as the second pass stores it (`start` is the flat index of the
/// run's first value), so neither needs a pass of its own over the slice.
///
/// Rows are transformed in place; columns go in blocks of [`BLOCK`], gathered
/// into contiguous lines (each row of a block is two cache lines) and
/// scattered back through `finish`.
#[allow(clippy::too_many_arguments)]
pub fn transform_2d_with(
    g: &mut [f32],
    w: usize,
    h: usize,
    spacing: [f32; 2],
    periodic: [bool; 2],
    s: &mut LineScratch,
    mut fill: impl FnMut(usize, &mut [f32]),
    mut finish: impl FnMut(usize, &mut [f32]),
) {
    debug_assert_eq!(g.len(), w * h);
    for (j, row) in g.chunks_exact_mut(w).enumerate() {
        fill(j, row);
        transform_line(row, spacing[0], periodic[0], s);
    }
    // Lines of the block one cache line longer than a column: with a stride
    // of a power of two (h = 1024 floats is 4 KiB) the lines would all
    // map to the same cache sets and evict each other while being gathered.
    let stride = h + BLOCK;
    let mut block = take(&mut s.block);
    block.resize(BLOCK * stride, 0.0);
    for i0 in (0..w).step_by(BLOCK) {
        let nb = BLOCK.min(w - i0);
        for (j, row) in g.chunks_exact(w).enumerate() {
            for (b, &x) in row[i0..i0 + nb].iter().enumerate() {
                block[b * stride + j] = x;
            }
        }
        for line in block.chunks_exact_mut(stride).take(nb) {
            transform_line(&mut line[..h], spacing[1], periodic[1], s);
        }
        for (j, row) in g.chunks_exact_mut(w).enumerate() {
            let run = &mut row[i0..i0 + nb];
            for (b, x) in run.iter_mut().enumerate() {
                *x = block[b * stride + j];
            }
            finish(j * w + i0, run);
        }
    }
    s.block = block;
}

/// Columns transformed together: 32 `f32` are two 64-byte cache lines of a
/// row, and a block of 1024-sample lines (128 KiB) stays in L2.
const BLOCK: usize = 32;

/// Classic binary EDT of a 3D volume (`[k][j][i]`, `size = [w, h, d]`):
/// for every voxel, the Euclidean distance (physical units, `spacing` per
/// axis) to the nearest voxel where `site` is true; `inf` when there is none.
/// This is what `scipy.ndimage.distance_transform_edt` and the `edt` package
/// compute (on the complement), used to check the transform against brute
/// force.
pub fn binary_edt_3d(site: &[bool], size: [usize; 3], spacing: [f32; 3]) -> Vec<f32> {
    use rayon::prelude::*;
    let [w, h, d] = size;
    let plane = w * h;
    let mut vol: Vec<f32> = site
        .iter()
        .map(|&b| if b { 0.0 } else { f32::INFINITY })
        .collect();
    vol.par_chunks_mut(plane.max(1))
        .for_each_init(LineScratch::default, |s, slice| {
            transform_2d(slice, w, h, [spacing[0], spacing[1]], [false, false], s)
        });
    // Along z, in strips of columns so each thread owns disjoint memory.
    let columns: Vec<usize> = (0..plane).collect();
    let results: Vec<(usize, Vec<f32>)> = columns
        .par_chunks(256)
        .flat_map_iter(|chunk| {
            let mut s = LineScratch::default();
            chunk
                .iter()
                .map(|&c| {
                    let mut col: Vec<f32> = (0..d).map(|k| vol[k * plane + c]).collect();
                    transform_line(&mut col, spacing[2], false, &mut s);
                    (c, col)
                })
                .collect::<Vec<_>>()
        })
        .collect();
    for (c, col) in results {
        for (k, x) in col.into_iter().enumerate() {
            vol[k * plane + c] = x.sqrt();
        }
    }
    vol
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_line(f: &[f32], spacing: f32, periodic: bool) -> Vec<f32> {
        let n = f.len() as i64;
        (0..n)
            .map(|q| {
                let mut best = f32::INFINITY;
                for p in 0..n {
                    let shifts: &[i64] = if periodic { &[-1, 0, 1] } else { &[0] };
                    for &sh in shifts {
                        let dq = (q - (p + sh * n)) as f32 * spacing;
                        best = best.min(dq * dq + f[p as usize]);
                    }
                }
                best
            })
            .collect()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(256))]

        #[test]
        fn line_matches_brute_force(
            f in prop::collection::vec(prop_oneof![3 => 0.0f32..10.0, 1 => Just(f32::INFINITY)], 1..40),
            spacing in 0.05f32..3.0,
            periodic: bool,
        ) {
            let mut out = f.clone();
            transform_line(&mut out, spacing, periodic, &mut LineScratch::default());
            let want = brute_line(&f, spacing, periodic);
            for (a, b) in out.iter().zip(&want) {
                if b.is_infinite() {
                    prop_assert!(a.is_infinite());
                } else {
                    prop_assert!((a - b).abs() <= 1e-4 * (1.0 + b), "{a} vs {b}");
                }
            }
        }

        #[test]
        fn binary_3d_matches_brute_force(
            w in 1usize..9, h in 1usize..9, d in 1usize..6,
            sx in 0.1f32..4.0, sy in 0.1f32..4.0, sz in 0.1f32..4.0,
            seed in any::<u64>(), density in 0.02f64..0.5,
        ) {
            let mut state = seed | 1;
            let mut next = || { state ^= state << 13; state ^= state >> 7; state ^= state << 17; (state >> 11) as f64 / (1u64 << 53) as f64 };
            let site: Vec<bool> = (0..w * h * d).map(|_| next() < density).collect();
            let got = binary_edt_3d(&site, [w, h, d], [sx, sy, sz]);
            for k in 0..d { for j in 0..h { for i in 0..w {
                let mut best = f32::INFINITY;
                for kk in 0..d { for jj in 0..h { for ii in 0..w {
                    if site[(kk * h + jj) * w + ii] {
                        let dx = (i as f32 - ii as f32) * sx;
                        let dy = (j as f32 - jj as f32) * sy;
                        let dz = (k as f32 - kk as f32) * sz;
                        best = best.min((dx * dx + dy * dy + dz * dz).sqrt());
                    }
                }}}
                let g = got[(k * h + j) * w + i];
                if best.is_infinite() { prop_assert!(g.is_infinite()); }
                else { prop_assert!((g - best).abs() <= 1e-4 * (1.0 + best), "({i},{j},{k}): {g} vs {best}"); }
            }}}
        }
    }
}
