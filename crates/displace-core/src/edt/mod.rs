//! Exact Euclidean distance transforms in linear time: the lower envelope of
//! parabolas of Felzenszwalb and Huttenlocher ("Distance Transforms of
//! Sampled Functions", Theory of Computing 8, 2012), applied one axis at a
//! time. Donnelly cites Danielsson's vector propagation (section 8.4); this
//! transform is exact where Danielsson's can err by a fraction of a voxel, and
//! it is linear in the number of voxels as well.
//!
//! All functions work on *squared* distances, with per-axis voxel spacing so
//! that anisotropic grids (a distance map is much wider than it is deep) are
//! measured in physical units.
//!
//! [`transform_line`] is the envelope for one line; the 2D transform a bake
//! runs takes its lines sixteen at a time through [`transform_wide`], the
//! same arithmetic in the lanes of an AVX-512 register, or of two AVX2
//! registers through [`transform_lanes`] (eight lanes were 1.7x the scalar
//! throughput on the rows of `studded`, 3x on `noise`, `cargo bench --bench
//! bake -- envelope`: the scalar envelope's time goes to branches it
//! mispredicts), with the scalar envelope as the fallback on other CPUs.
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

mod lanes;

pub use lanes::{
    deinterleave, interleave, transform_lanes, transform_wide, vector_kernel, wide_kernel,
    LaneScratch, LANES, WIDE,
};
use std::mem::take;

/// Scratch space for the 1D transforms, reused across lines so that no line
/// allocates.
#[derive(Default)]
pub struct LineScratch {
    /// The lower envelope, a stack.
    stack: Vec<Parabola>,
    /// One periodic line with its wrapped neighbours.
    ext: Vec<f32>,
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

/// Scratch space of the 2D transform, one per thread.
#[derive(Default)]
pub struct SliceScratch {
    lanes: LaneScratch,
    /// Sixteen interleaved rows, or `BLOCK` interleaved columns.
    block: Vec<f32>,
}

/// The sampling of a 2D slice: its size in samples, the spacing between
/// samples along each axis (the `hx`, `hy` of the transform) and whether each
/// axis wraps around (a tiling height map's distance wraps too).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Grid2 {
    /// Samples per row.
    pub w: usize,
    /// Rows.
    pub h: usize,
    /// Distance between neighbouring samples along x and y.
    pub spacing: [f32; 2],
    /// Whether x and y wrap around.
    pub periodic: [bool; 2],
}

/// 2D transform of a sampled function `g` (`w x h`, row-major), in place:
/// `g'(i, j) = min (hx (i - i'))^2 + (hy (j - j'))^2 + g(i', j')`.
pub fn transform_2d(g: &mut [f32], grid: Grid2, s: &mut SliceScratch) {
    let copy = |_: usize, _: usize, results: &[f32], out: &mut [f32]| out.copy_from_slice(results);
    transform_2d_with(g, grid, s, false, |_, _| {}, copy);
}

/// [`transform_2d`] with the producer and consumer of the slice fused in:
/// `fill(j, row)` writes row `j`'s input just before that row is transformed,
/// while it is in cache, and `finish(j, i0, results, out)` maps each run of
/// the second pass's results into the slice as it stores them (`out` is row
/// `j` from column `i0`, a multiple of [`BLOCK`]; the identity is a copy),
/// so neither needs a pass of its own over the slice. With `finite` the
/// caller promises that every value `fill` writes is finite (as squared
/// distances are), and the kernel skips checking it; an infinite value
/// there would not end.
///
/// Both passes run sixteen lines at a time through [`transform_wide`]: rows
/// are interleaved into a block sixteen at a time, columns are copied a
/// block of 32 at a time (a row of the block is two cache lines) and
/// transformed as two groups of sixteen. A group short of sixteen lines (the
/// last rows or columns of a slice whose size is not a multiple of sixteen)
/// is padded with copies of its first line, whose results are dropped.
///
/// Always inlined, so that a caller compiled for a wider instruction set
/// (the bake's slices, for AVX2) compiles `fill`, `finish` and the copies
/// for it too.
#[inline(always)]
pub fn transform_2d_with(
    g: &mut [f32],
    grid: Grid2,
    s: &mut SliceScratch,
    finite: bool,
    mut fill: impl FnMut(usize, &mut [f32]),
    mut finish: impl FnMut(usize, usize, &[f32], &mut [f32]),
) {
    let Grid2 {
        w,
        h,
        spacing,
        periodic,
    } = grid;
    debug_assert_eq!(g.len(), w * h);
    if w == 0 || h == 0 {
        return;
    }
    let mut block = take(&mut s.block);
    block.resize((w * WIDE).max(h * BLOCK), 0.0);
    for j0 in (0..h).step_by(WIDE) {
        let rows = WIDE.min(h - j0);
        let group = &mut g[j0 * w..(j0 + rows) * w];
        for (b, row) in group.chunks_exact_mut(w).enumerate() {
            fill(j0 + b, row);
        }
        interleave(group, rows, w, WIDE, &mut block);
        lanes::wide(
            &mut block[..w * WIDE],
            WIDE,
            w,
            spacing[0],
            periodic[0],
            &mut s.lanes,
            !finite,
        );
        deinterleave(&block, rows, w, WIDE, group);
    }
    for i0 in (0..w).step_by(BLOCK) {
        let nb = BLOCK.min(w - i0);
        let groups = nb.div_ceil(WIDE);
        if nb == BLOCK {
            // A whole block: copies of a known length, inlined.
            for (row, dst) in g.chunks_exact(w).zip(block.chunks_exact_mut(BLOCK)) {
                let run: &[f32; BLOCK] = row[i0..i0 + BLOCK].try_into().unwrap();
                dst.copy_from_slice(run);
            }
        } else {
            for (j, row) in g.chunks_exact(w).enumerate() {
                let run = &row[i0..i0 + nb];
                let dst = &mut block[j * BLOCK..][..groups * WIDE];
                dst[..nb].copy_from_slice(run);
                dst[nb..].fill(run[0]);
            }
        }
        for c in 0..groups {
            lanes::wide(
                &mut block[c * WIDE..h * BLOCK],
                BLOCK,
                h,
                spacing[1],
                periodic[1],
                &mut s.lanes,
                !finite,
            );
        }
        for (j, row) in g.chunks_exact_mut(w).enumerate() {
            finish(j, i0, &block[j * BLOCK..][..nb], &mut row[i0..i0 + nb]);
        }
    }
    s.block = block;
}

/// Columns the second pass transforms together: 32 `f32` are two 64-byte
/// cache lines of a row, and a block of 2048-sample lines (256 KiB) stays in
/// L2.
pub const BLOCK: usize = 32;

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
        .for_each_init(SliceScratch::default, |s, slice| {
            let spacing = [spacing[0], spacing[1]];
            transform_2d(
                slice,
                Grid2 {
                    w,
                    h,
                    spacing,
                    periodic: [false; 2],
                },
                s,
            )
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
        #![proptest_config(ProptestConfig::with_cases(crate::random::property_cases(256)))]

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

        /// The 2D driver on finite functions, as a bake feeds it: groups of
        /// eight rows and blocks of columns through the lane kernel, with
        /// the padding of short groups and blocks (sizes not multiples of 8
        /// or 32), against the brute-force minimum over all samples.
        #[test]
        fn finite_2d_matches_brute_force(
            w in 1usize..45, h in 1usize..21,
            sx in 0.05f32..3.0, sy in 0.05f32..3.0,
            px: bool, py: bool, seed in any::<u64>(),
        ) {
            let mut state = seed | 1;
            let mut next = || { state ^= state << 13; state ^= state >> 7; state ^= state << 17; (state >> 11) as f32 / (1u64 << 53) as f32 };
            let g: Vec<f32> = (0..w * h).map(|_| next() * 20.0).collect();
            let mut got = g.clone();
            let grid = Grid2 { w, h, spacing: [sx, sy], periodic: [px, py] };
            transform_2d(&mut got, grid, &mut SliceScratch::default());
            let d = |a: usize, b: usize, n: usize, periodic: bool| {
                let t = a.abs_diff(b);
                if periodic { t.min(n - t) } else { t }
            };
            for j in 0..h { for i in 0..w {
                let mut best = f32::INFINITY;
                for jj in 0..h { for ii in 0..w {
                    let dx = d(i, ii, w, px) as f32 * sx;
                    let dy = d(j, jj, h, py) as f32 * sy;
                    best = best.min(dx * dx + dy * dy + g[jj * w + ii]);
                }}
                let v = got[j * w + i];
                prop_assert!((v - best).abs() <= 1e-4 * (1.0 + best), "({i},{j}) of {w}x{h}: {v} vs {best}");
            }}
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
