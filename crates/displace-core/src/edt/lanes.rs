//! Lines of the lower envelope eight or sixteen at once, one per lane of an
//! AVX2 or AVX-512 register.
//!
//! The scalar envelope ([`super::transform_line`]) spends most of its time in
//! mispredicted branches: how many parabolas a new one pops, and where the
//! read-back moves to the next parabola, depend on the data. Independent
//! lines step together here, so a branch is taken once for all of them and
//! the loop runs as long as the lane that pops the most.
//!
//! A lane's stack is a linked list in arrays indexed by site (element
//! `(site + 1) * lanes + lane`, after a sentinel group): pushing parabola
//! `q` stores its value, its left end and the index of the parabola below it
//! at `q`, one contiguous store for all lanes, and popping follows that link.
//! AVX2 has gathers but no scatters, which a stack indexed by depth would
//! need. The read-back walks the list from the right end, so it runs from the
//! last sample to the first.
//!
//! Following a link with a gather makes each step wait for the last one's
//! gather: the read-back was latency-bound on that chain. But on the rows a
//! bake feeds it most sites are on the envelope, so the parabola below the
//! one covering `x` is the site `x - 1`, in the same group for every lane:
//! a step checks each lane's link against that group and takes the lanes
//! that match from one plain load, whose address is known before the link
//! is loaded, leaving gathers to the others (a 2048x2048x64 `studded` bake:
//! 27.9 M read-back steps with 435 M lane moves, nearly all of them to the
//! site before; the kernel's time fell by half). Pops guess the same way.
//!
//! The arithmetic is [`super::envelope`]'s, operation for operation (the same
//! intersection numerator, the same cross-multiplied pop test, the same
//! division for a pushed left end, the same `d * d + f` result), so the
//! envelope and the results are the scalar ones; the only way the two can
//! differ is where rounding makes two adjacent left ends out of order (the
//! scalar read-back and this one then pick different parabolas at a tie that
//! rounding broke), which changes a value by its rounding error. Eight and
//! sixteen lanes give the same bits lane for lane.

/// Lines per group: one `f32` per lane of a 256-bit register.
pub const LANES: usize = 8;

/// Per-thread scratch of the lane kernel, reused across groups.
#[derive(Default)]
pub struct LaneScratch {
    /// The input value at each site (element `(site + 1) * 8 + lane`).
    f: Vec<f32>,
    /// Left end of the site's interval of the envelope, when it was pushed.
    z: Vec<f32>,
    /// Element index of the parabola below the site on its lane's stack.
    prev: Vec<i32>,
    /// One lane as a line, for the scalar path.
    line: Vec<f32>,
    scalar: super::LineScratch,
}

/// Whether [`transform_lanes`] runs the vector kernel on this CPU (otherwise
/// it runs the scalar envelope lane by lane).
pub fn vector_kernel() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// [`super::transform_line`] on eight interleaved lines: sample `t` of lane
/// `b` is `data[t * stride + b]`, for `t < n`. Every value must be finite
/// (a line without sites, which the scalar transform allows, has no use in
/// a bake); groups with an infinite or NaN value go through the scalar
/// envelope instead.
pub fn transform_lanes(
    data: &mut [f32],
    stride: usize,
    n: usize,
    spacing: f32,
    periodic: bool,
    s: &mut LaneScratch,
) {
    assert!(stride >= LANES && n > 0 && data.len() >= (n - 1) * stride + LANES);
    #[cfg(target_arch = "x86_64")]
    if vector_kernel() && n <= MAX_LEN && all_finite(data, stride, n) {
        // SAFETY: AVX2 is present, the values are finite and the bounds the
        // kernel relies on were asserted above.
        unsafe { avx2::envelope(data, stride, n, spacing, periodic, s) };
        return;
    }
    let line = &mut s.line;
    for b in 0..LANES {
        line.clear();
        line.extend((0..n).map(|t| data[t * stride + b]));
        super::transform_line(line, spacing, periodic, &mut s.scalar);
        for (t, &v) in line.iter().enumerate() {
            data[t * stride + b] = v;
        }
    }
}

/// Lines per group of the 2D transform: sixteen, one per lane of an
/// AVX-512 register where the CPU has one, else two groups of eight.
pub const WIDE: usize = 16;

/// Whether [`transform_wide`] runs sixteen lanes in one register (AVX-512F)
/// on this CPU; otherwise it runs [`transform_lanes`] on each half.
pub fn wide_kernel() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx512f")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// [`transform_lanes`] on sixteen interleaved lines (sample `t` of lane `b`
/// at `data[t * stride + b]`): the same values lane for lane. Sixteen lanes
/// in one register halve the instructions per line, and the latency of the
/// gathers that walk each lane's stack is paid once for twice the lines.
pub fn transform_wide(
    data: &mut [f32],
    stride: usize,
    n: usize,
    spacing: f32,
    periodic: bool,
    s: &mut LaneScratch,
) {
    wide(data, stride, n, spacing, periodic, s, true);
}

/// [`transform_wide`], checking that every value is finite only when
/// `check` (the vector kernel's loops end only on finite values; a caller
/// that knows its values are, a bake's squared distances, skips the pass).
pub(super) fn wide(
    data: &mut [f32],
    stride: usize,
    n: usize,
    spacing: f32,
    periodic: bool,
    s: &mut LaneScratch,
    check: bool,
) {
    assert!(stride >= WIDE && n > 0 && data.len() >= (n - 1) * stride + WIDE);
    #[cfg(target_arch = "x86_64")]
    // SAFETY: AVX-512F is present and the rows reach sixteen lanes (above).
    if wide_kernel() && n <= MAX_LEN && (!check || unsafe { avx512::all_finite(data, stride, n) }) {
        // SAFETY: as above.
        debug_assert!(unsafe { avx512::all_finite(data, stride, n) });
        // SAFETY: as above, and every value is finite.
        unsafe { avx512::envelope(data, stride, n, spacing, periodic, s) };
        return;
    }
    transform_lanes(data, stride, n, spacing, periodic, s);
    transform_lanes(&mut data[LANES..], stride, n, spacing, periodic, s);
}

/// Whether the eight lanes hold finite values only (the kernel's domain).
#[cfg(target_arch = "x86_64")]
fn all_finite(data: &[f32], stride: usize, n: usize) -> bool {
    // No early exit, so that the test vectorises.
    (0..n).fold(true, |ok, t| {
        data[t * stride..][..LANES]
            .iter()
            .fold(ok, |ok, x| ok & (x.abs() < f32::INFINITY))
    })
}

/// Interleaves `rows` rows of `w` samples (`group[b * w + x]`,
/// `rows <= width`, `width` 8 or 16) into `block[x * width + b]`, as
/// [`transform_lanes`] (width 8) and [`transform_wide`] (16) take them;
/// lanes past `rows` repeat the first row.
pub fn interleave(group: &[f32], rows: usize, w: usize, width: usize, block: &mut [f32]) {
    assert!(width.is_multiple_of(LANES) && (1..=width).contains(&rows));
    assert!(group.len() >= rows * w && block.len() >= w * width);
    let done = if rows == width {
        // Eight rows at a time; tile t of half h: rows at
        // group[(8 h + b) * w + 8 t], written to block[8 h + width (8 t + k)].
        let mut done = w;
        for h in 0..width / LANES {
            done = done.min(transposed(
                &group[h * LANES * w..],
                [w, LANES],
                &mut block[h * LANES..],
                [width, LANES * width],
                w,
            ));
        }
        done
    } else {
        0
    };
    for b in 0..width {
        let row = &group[if b < rows { b } else { 0 } * w..][..w];
        for x in done..w {
            block[x * width + b] = row[x];
        }
    }
}

/// The inverse of [`interleave`]: `group[b * w + x] = block[x * width + b]`
/// for the first `rows` lanes.
pub fn deinterleave(block: &[f32], rows: usize, w: usize, width: usize, group: &mut [f32]) {
    assert!(width.is_multiple_of(LANES) && (1..=width).contains(&rows));
    assert!(group.len() >= rows * w && block.len() >= w * width);
    let done = if rows == width {
        let mut done = w;
        for h in 0..width / LANES {
            done = done.min(transposed(
                &block[h * LANES..],
                [width, LANES * width],
                &mut group[h * LANES * w..],
                [w, LANES],
                w,
            ));
        }
        done
    } else {
        0
    };
    for (b, row) in group.chunks_exact_mut(w).take(rows).enumerate() {
        for x in done..w {
            row[x] = block[x * width + b];
        }
    }
}

/// Transposes the `n / 8` whole 8x8 tiles of a strided layout, where the
/// vector unit is there, and returns how many columns it did (`0` or
/// `n / 8 * 8`). `from` and `to` are `[row stride, tile step]` of `src`
/// and `dst`: tile `t` reads row `b` at `src[b * from[0] + t * from[1]..]`
/// and writes its column `k` to `dst[k * to[0] + t * to[1]..]`, eight
/// values each.
fn transposed(src: &[f32], from: [usize; 2], dst: &mut [f32], to: [usize; 2], n: usize) -> usize {
    let tiles = n / LANES;
    let reach = |[stride, step]: [usize; 2]| 7 * stride + tiles.saturating_sub(1) * step + LANES;
    #[cfg(target_arch = "x86_64")]
    if vector_kernel() && tiles > 0 && src.len() >= reach(from) && dst.len() >= reach(to) {
        // SAFETY: AVX2 is present and every tile read and written lies
        // within the slices (checked above).
        unsafe { avx2::transpose_tiles(src, from, dst, to, tiles) };
        return tiles * LANES;
    }
    let _ = (src, from, dst, to, reach);
    0
}

/// Longest line the kernel takes: element indices of the extended periodic
/// line (`2n * 8`) must fit an `i32`, and sites must be exact in `f32`.
#[cfg(target_arch = "x86_64")]
const MAX_LEN: usize = 1 << 22;

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{LaneScratch, LANES};
    use std::arch::x86_64::*;

    /// 8x8 transposes of `tiles` tiles; see [`super::transposed`].
    ///
    /// # Safety
    /// The CPU has AVX2; both slices reach every tile's rows.
    #[target_feature(enable = "avx2")]
    pub unsafe fn transpose_tiles(
        src: &[f32],
        [src_stride, src_step]: [usize; 2],
        dst: &mut [f32],
        [dst_stride, dst_step]: [usize; 2],
        tiles: usize,
    ) {
        let (s, d) = (src.as_ptr(), dst.as_mut_ptr());
        for t in 0..tiles {
            let r = |b: usize| _mm256_loadu_ps(s.add(b * src_stride + t * src_step));
            let (r0, r1, r2, r3) = (r(0), r(1), r(2), r(3));
            let (r4, r5, r6, r7) = (r(4), r(5), r(6), r(7));
            let (t0, t1) = (_mm256_unpacklo_ps(r0, r1), _mm256_unpackhi_ps(r0, r1));
            let (t2, t3) = (_mm256_unpacklo_ps(r2, r3), _mm256_unpackhi_ps(r2, r3));
            let (t4, t5) = (_mm256_unpacklo_ps(r4, r5), _mm256_unpackhi_ps(r4, r5));
            let (t6, t7) = (_mm256_unpacklo_ps(r6, r7), _mm256_unpackhi_ps(r6, r7));
            // u_k holds column k of rows 0-3 (low half) and column k + 4.
            let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
            let u1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
            let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
            let u3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
            let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
            let u5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
            let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
            let u7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
            let w = |k: usize, v: __m256| _mm256_storeu_ps(d.add(k * dst_stride + t * dst_step), v);
            w(0, _mm256_permute2f128_ps::<0x20>(u0, u4));
            w(1, _mm256_permute2f128_ps::<0x20>(u1, u5));
            w(2, _mm256_permute2f128_ps::<0x20>(u2, u6));
            w(3, _mm256_permute2f128_ps::<0x20>(u3, u7));
            w(4, _mm256_permute2f128_ps::<0x31>(u0, u4));
            w(5, _mm256_permute2f128_ps::<0x31>(u1, u5));
            w(6, _mm256_permute2f128_ps::<0x31>(u2, u6));
            w(7, _mm256_permute2f128_ps::<0x31>(u3, u7));
        }
    }

    /// The envelope of eight interleaved lines; see the module docs.
    ///
    /// # Safety
    /// The CPU has AVX2; every value is finite; `n <= MAX_LEN`;
    /// `data.len() >= (n - 1) * stride + 8`.
    #[target_feature(enable = "avx2")]
    pub unsafe fn envelope(
        data: &mut [f32],
        stride: usize,
        n: usize,
        spacing: f32,
        periodic: bool,
        s: &mut LaneScratch,
    ) {
        // A periodic line is extended by half a period on each side, as the
        // scalar transform does, without copying: `src` follows the wrap.
        let m = if periodic { n / 2 } else { 0 };
        let len = n + 2 * m;
        s.f.resize((len + 1) * LANES, 0.0);
        s.z.resize((len + 1) * LANES, 0.0);
        s.prev.resize((len + 1) * LANES, 0);
        let (fs, zs, ps) = (s.f.as_mut_ptr(), s.z.as_mut_ptr(), s.prev.as_mut_ptr());
        let base = data.as_mut_ptr();
        let inv = _mm256_set1_ps(1.0 / (spacing * spacing));
        let two = _mm256_set1_ps(2.0);
        let half = _mm256_set1_ps(0.5);
        let lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);

        let mut src = if m > 0 { n - m } else { 0 };
        let load = |src: usize| _mm256_loadu_ps(base.add(src * stride));

        // Element `(site + 1) * 8 + lane` holds a site; group 0 is a
        // sentinel below every stack (left end -inf, linked to itself), so
        // that every gather reads inside the arrays.
        let ninf = _mm256_set1_ps(f32::NEG_INFINITY);
        _mm256_storeu_ps(fs, _mm256_setzero_ps());
        _mm256_storeu_ps(zs, ninf);
        _mm256_storeu_si256(ps as *mut __m256i, lane);
        let site = |e: __m256i| {
            _mm256_cvtepi32_ps(_mm256_sub_epi32(
                _mm256_srli_epi32::<3>(e),
                _mm256_set1_epi32(1),
            ))
        };
        let element =
            |q: usize| _mm256_add_epi32(_mm256_set1_epi32(((q + 1) * LANES) as i32), lane);

        // The top parabola of each lane's stack (`t_*`) and the one below it
        // (`b_*`, with `b_prev` the element below that) stay in registers:
        // a pop or a read-back step decides on registers, and the gathers
        // that fetch the new parabola below run in the shadow of the next
        // decision instead of in front of it. A push needs no gather at all.
        let f0 = load(src);
        _mm256_storeu_ps(fs.add(LANES), f0);
        _mm256_storeu_ps(zs.add(LANES), ninf);
        _mm256_storeu_si256(ps.add(LANES) as *mut __m256i, lane);
        let (mut t_e, mut t_p, mut t_f, mut t_z) = (element(0), _mm256_setzero_ps(), f0, ninf);
        let (mut b_e, mut b_p, mut b_f, mut b_z) = (lane, site(lane), _mm256_setzero_ps(), ninf);
        let mut b_prev = lane;

        // Moves the lanes of `mask` down their stack by one parabola. The
        // new parabola below is fetched with gathers, except in the lanes
        // where it is the one at group `at / 8` (`at` a multiple of 8):
        // those take it from a plain load of that group, at an address that
        // does not wait on the gather before it.
        macro_rules! follow {
            ($mask:expr, $at:expr) => {{
                let mask = $mask;
                let maski = _mm256_castps_si256(mask);
                t_e = _mm256_blendv_epi8(t_e, b_e, maski);
                t_p = _mm256_blendv_ps(t_p, b_p, mask);
                t_f = _mm256_blendv_ps(t_f, b_f, mask);
                t_z = _mm256_blendv_ps(t_z, b_z, mask);
                b_e = _mm256_blendv_epi8(b_e, b_prev, maski);
                b_p = site(b_e);
                let at: usize = $at;
                let near = _mm256_add_epi32(_mm256_set1_epi32(at as i32), lane);
                let hit = _mm256_and_si256(_mm256_cmpeq_epi32(b_e, near), maski);
                let hitf = _mm256_castsi256_ps(hit);
                b_f = _mm256_blendv_ps(b_f, _mm256_loadu_ps(fs.add(at)), hitf);
                b_z = _mm256_blendv_ps(b_z, _mm256_loadu_ps(zs.add(at)), hitf);
                b_prev = _mm256_blendv_epi8(
                    b_prev,
                    _mm256_loadu_si256(ps.add(at) as *const __m256i),
                    hit,
                );
                let miss = _mm256_andnot_si256(hit, maski);
                if _mm256_testz_si256(miss, miss) == 0 {
                    let missf = _mm256_castsi256_ps(miss);
                    b_f = _mm256_mask_i32gather_ps::<4>(b_f, fs, b_e, missf);
                    b_z = _mm256_mask_i32gather_ps::<4>(b_z, zs, b_e, missf);
                    b_prev = _mm256_mask_i32gather_epi32::<4>(b_prev, ps, b_e, miss);
                }
            }};
        }

        for q in 1..len {
            src += 1;
            if src == n {
                src = 0;
            }
            let qf = _mm256_set1_ps(q as f32);
            let fq = load(src);
            let gq = _mm256_mul_ps(fq, inv);
            let at = (q + 1) * LANES;
            _mm256_storeu_ps(fs.add(at), fq);
            // Where the parabolas below the top are the sites just before
            // `q` (a smooth line), the one the next pop exposes is at the
            // group below the last: `guess` follows it down.
            let mut guess = q.saturating_sub(2) * LANES;
            let (num, d2) = loop {
                // super::envelope: d2 = 2 (q - p), num = (g_q - g_p) + d2/2 (q + p).
                let d2 = _mm256_mul_ps(two, _mm256_sub_ps(qf, t_p));
                let t_g = _mm256_mul_ps(t_f, inv);
                let num = _mm256_add_ps(
                    _mm256_sub_ps(gq, t_g),
                    _mm256_mul_ps(_mm256_mul_ps(half, d2), _mm256_add_ps(qf, t_p)),
                );
                let pop = _mm256_cmp_ps::<_CMP_LE_OQ>(num, _mm256_mul_ps(t_z, d2));
                if _mm256_movemask_ps(pop) == 0 {
                    break (num, d2);
                }
                follow!(pop, guess);
                guess = guess.saturating_sub(LANES);
            };
            let z = _mm256_div_ps(num, d2);
            _mm256_storeu_ps(zs.add(at), z);
            _mm256_storeu_si256(ps.add(at) as *mut __m256i, t_e);
            b_prev = b_e;
            (b_e, b_p, b_f, b_z) = (t_e, t_p, t_f, t_z);
            (t_e, t_p, t_f, t_z) = (element(q), qf, fq, z);
        }

        // Read-back from the right: a sample at x takes the parabola whose
        // interval [z, next z) holds it; move left while z >= x (the scalar
        // read-back moves right while the next z < x: the same choice).
        let sp = _mm256_set1_ps(spacing);
        for x in (m..m + n).rev() {
            let xf = _mm256_set1_ps(x as f32);
            // Where every site is on the envelope (smooth lines), the
            // parabola below the one that covers `x` is at `x - 1`.
            let mut guess = x * LANES;
            loop {
                let back = _mm256_cmp_ps::<_CMP_GE_OQ>(t_z, xf);
                if _mm256_movemask_ps(back) == 0 {
                    break;
                }
                follow!(back, guess);
                guess = guess.saturating_sub(LANES);
            }
            let d = _mm256_mul_ps(sp, _mm256_sub_ps(xf, t_p));
            let out = _mm256_add_ps(_mm256_mul_ps(d, d), t_f);
            _mm256_storeu_ps(base.add((x - m) * stride), out);
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod avx512 {
    use super::{LaneScratch, WIDE};
    use std::arch::x86_64::*;

    /// Whether the sixteen lanes of `n` rows hold finite values only.
    ///
    /// # Safety
    /// The CPU has AVX-512F; `data.len() >= (n - 1) * stride + 16`.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn all_finite(data: &[f32], stride: usize, n: usize) -> bool {
        let inf = _mm512_set1_ps(f32::INFINITY);
        let p = data.as_ptr();
        let mut finite: __mmask16 = 0xffff;
        for t in 0..n {
            let v = _mm512_abs_ps(_mm512_loadu_ps(p.add(t * stride)));
            finite &= _mm512_cmp_ps_mask::<_CMP_LT_OQ>(v, inf);
        }
        finite == 0xffff
    }

    /// [`super::avx2::envelope`] on sixteen lanes: the same operations
    /// lane for lane, with the lane masks in mask registers.
    ///
    /// # Safety
    /// The CPU has AVX-512F; every value is finite; `n <= MAX_LEN`;
    /// `data.len() >= (n - 1) * stride + 16`.
    #[target_feature(enable = "avx512f")]
    pub unsafe fn envelope(
        data: &mut [f32],
        stride: usize,
        n: usize,
        spacing: f32,
        periodic: bool,
        s: &mut LaneScratch,
    ) {
        let m = if periodic { n / 2 } else { 0 };
        let len = n + 2 * m;
        s.f.resize((len + 1) * WIDE, 0.0);
        s.z.resize((len + 1) * WIDE, 0.0);
        s.prev.resize((len + 1) * WIDE, 0);
        let (fs, zs, ps) = (s.f.as_mut_ptr(), s.z.as_mut_ptr(), s.prev.as_mut_ptr());
        let base = data.as_mut_ptr();
        let inv = _mm512_set1_ps(1.0 / (spacing * spacing));
        let two = _mm512_set1_ps(2.0);
        let half = _mm512_set1_ps(0.5);
        let lane = _mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15);

        let mut src = if m > 0 { n - m } else { 0 };
        let load = |src: usize| _mm512_loadu_ps(base.add(src * stride));

        // Element `(site + 1) * 16 + lane`; group 0 is the sentinel.
        let ninf = _mm512_set1_ps(f32::NEG_INFINITY);
        _mm512_storeu_ps(fs, _mm512_setzero_ps());
        _mm512_storeu_ps(zs, ninf);
        _mm512_storeu_si512(ps as *mut __m512i, lane);
        let site = |e: __m512i| {
            _mm512_cvtepi32_ps(_mm512_sub_epi32(
                _mm512_srli_epi32::<4>(e),
                _mm512_set1_epi32(1),
            ))
        };
        let element = |q: usize| _mm512_add_epi32(_mm512_set1_epi32(((q + 1) * WIDE) as i32), lane);

        let f0 = load(src);
        _mm512_storeu_ps(fs.add(WIDE), f0);
        _mm512_storeu_ps(zs.add(WIDE), ninf);
        _mm512_storeu_si512(ps.add(WIDE) as *mut __m512i, lane);
        let (mut t_e, mut t_p, mut t_f, mut t_z) = (element(0), _mm512_setzero_ps(), f0, ninf);
        let (mut b_e, mut b_p, mut b_f, mut b_z) = (lane, site(lane), _mm512_setzero_ps(), ninf);
        let mut b_prev = lane;

        // Moves the lanes of `mask` down their stack by one parabola. The
        // new parabola below is fetched with gathers, except in the lanes
        // where it is the one at group `at / 16` (`at` a multiple of 16):
        // those load it from that group directly, at an address that does
        // not wait on the gather before it.
        macro_rules! follow {
            ($mask:expr, $at:expr) => {{
                let mask: __mmask16 = $mask;
                t_e = _mm512_mask_blend_epi32(mask, t_e, b_e);
                t_p = _mm512_mask_blend_ps(mask, t_p, b_p);
                t_f = _mm512_mask_blend_ps(mask, t_f, b_f);
                t_z = _mm512_mask_blend_ps(mask, t_z, b_z);
                b_e = _mm512_mask_blend_epi32(mask, b_e, b_prev);
                b_p = site(b_e);
                let at: usize = $at;
                let near = _mm512_add_epi32(_mm512_set1_epi32(at as i32), lane);
                let hit = _mm512_mask_cmpeq_epi32_mask(mask, b_e, near);
                b_f = _mm512_mask_loadu_ps(b_f, hit, fs.add(at));
                b_z = _mm512_mask_loadu_ps(b_z, hit, zs.add(at));
                b_prev = _mm512_mask_loadu_epi32(b_prev, hit, ps.add(at));
                let miss = mask & !hit;
                if miss != 0 {
                    b_f = _mm512_mask_i32gather_ps::<4>(b_f, miss, b_e, fs);
                    b_z = _mm512_mask_i32gather_ps::<4>(b_z, miss, b_e, zs);
                    b_prev = _mm512_mask_i32gather_epi32::<4>(b_prev, miss, b_e, ps);
                }
            }};
        }

        for q in 1..len {
            src += 1;
            if src == n {
                src = 0;
            }
            let qf = _mm512_set1_ps(q as f32);
            let fq = load(src);
            let gq = _mm512_mul_ps(fq, inv);
            let at = (q + 1) * WIDE;
            _mm512_storeu_ps(fs.add(at), fq);
            // Where the parabolas below the top are the sites just before
            // `q` (a smooth line), the one the next pop exposes is at the
            // group below the last: `guess` follows it down.
            let mut guess = q.saturating_sub(2) * WIDE;
            let (num, d2) = loop {
                let d2 = _mm512_mul_ps(two, _mm512_sub_ps(qf, t_p));
                let t_g = _mm512_mul_ps(t_f, inv);
                let num = _mm512_add_ps(
                    _mm512_sub_ps(gq, t_g),
                    _mm512_mul_ps(_mm512_mul_ps(half, d2), _mm512_add_ps(qf, t_p)),
                );
                let pop = _mm512_cmp_ps_mask::<_CMP_LE_OQ>(num, _mm512_mul_ps(t_z, d2));
                if pop == 0 {
                    break (num, d2);
                }
                follow!(pop, guess);
                guess = guess.saturating_sub(WIDE);
            };
            let z = _mm512_div_ps(num, d2);
            _mm512_storeu_ps(zs.add(at), z);
            _mm512_storeu_si512(ps.add(at) as *mut __m512i, t_e);
            b_prev = b_e;
            (b_e, b_p, b_f, b_z) = (t_e, t_p, t_f, t_z);
            (t_e, t_p, t_f, t_z) = (element(q), qf, fq, z);
        }
        let sp = _mm512_set1_ps(spacing);
        for x in (m..m + n).rev() {
            let xf = _mm512_set1_ps(x as f32);
            // Where every site is on the envelope (smooth lines), the
            // parabola below the one that covers `x` is at `x - 1`.
            let mut guess = x * WIDE;
            loop {
                let back = _mm512_cmp_ps_mask::<_CMP_GE_OQ>(t_z, xf);
                if back == 0 {
                    break;
                }
                follow!(back, guess);
                guess = guess.saturating_sub(WIDE);
            }
            let d = _mm512_mul_ps(sp, _mm512_sub_ps(xf, t_p));
            let out = _mm512_add_ps(_mm512_mul_ps(d, d), t_f);
            _mm512_storeu_ps(base.add((x - m) * stride), out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::edt::{transform_line, LineScratch};
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(crate::random::property_cases(256)))]

        /// Bit-identical to the scalar envelope, up to the rounding of a tie
        /// (see the module docs), on random lines with repeated values
        /// (ties) and the shapes a bake feeds it.
        #[test]
        fn lanes_match_the_scalar_transform(
            n in 1usize..70,
            spacing in 0.05f32..3.0,
            periodic: bool,
            pad in 0usize..3,
            seed in any::<u64>(),
            levels in 1u32..12,
        ) {
            let mut state = seed | 1;
            let mut next = || { state ^= state << 13; state ^= state >> 7; state ^= state << 17; state };
            let stride = LANES + pad;
            let data: Vec<f32> = (0..n * stride)
                .map(|_| (next() % u64::from(levels)) as f32 * 0.37)
                .collect();
            let mut got = data.clone();
            transform_lanes(&mut got, stride, n, spacing, periodic, &mut LaneScratch::default());
            for b in 0..LANES {
                let mut want: Vec<f32> = (0..n).map(|t| data[t * stride + b]).collect();
                transform_line(&mut want, spacing, periodic, &mut LineScratch::default());
                for t in 0..n {
                    let (g, w) = (got[t * stride + b], want[t]);
                    prop_assert!((g - w).abs() <= 1e-5 * (1.0 + w), "lane {b} sample {t}: {g} vs {w}");
                }
            }
            // Padding between groups is not touched.
            for t in 0..n {
                for p in LANES..stride {
                    prop_assert_eq!(got[t * stride + p], data[t * stride + p]);
                }
            }
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(crate::random::property_cases(256)))]

        /// Sixteen lanes give the eight-lane kernel's values to the bit,
        /// lane for lane, on smooth lines (every site on the envelope: the
        /// read-back loads the parabola below directly) and on lines with
        /// repeated levels (pops deep into the stack: gathers), in any
        /// mix across the lanes.
        #[test]
        fn wide_lanes_match_eight_lanes_bit_for_bit(
            n in 1usize..90,
            spacing in 0.05f32..3.0,
            periodic: bool,
            pad in 0usize..3,
            seed in any::<u64>(),
            levels in 1u32..12,
            smooth_lanes in any::<u16>(),
        ) {
            let mut state = seed | 1;
            let mut next = || { state ^= state << 13; state ^= state >> 7; state ^= state << 17; state };
            let stride = WIDE + pad;
            let mut data = vec![0.0f32; n * stride];
            for b in 0..WIDE {
                let smooth = smooth_lanes >> b & 1 == 1;
                let (a, f) = ((next() % 1000) as f32 / 1000.0, (next() % 100) as f32 / 400.0);
                for t in 0..n {
                    data[t * stride + b] = if smooth {
                        let x = a + (t as f32 * f).sin();
                        x * x
                    } else {
                        (next() % u64::from(levels)) as f32 * 0.37
                    };
                }
            }
            let mut wide = data.clone();
            transform_wide(&mut wide, stride, n, spacing, periodic, &mut LaneScratch::default());
            let mut eight = data.clone();
            let mut s = LaneScratch::default();
            transform_lanes(&mut eight, stride, n, spacing, periodic, &mut s);
            transform_lanes(&mut eight[LANES..], stride, n, spacing, periodic, &mut s);
            for (i, (a, b)) in wide.iter().zip(&eight).enumerate() {
                prop_assert_eq!(a.to_bits(), b.to_bits(), "element {} of {}x{}", i, n, stride);
            }
            // And the scalar envelope's, up to the rounding of a tie (on a
            // CPU without AVX-512 both sides above run the same kernel).
            for b in 0..WIDE {
                let mut want: Vec<f32> = (0..n).map(|t| data[t * stride + b]).collect();
                transform_line(&mut want, spacing, periodic, &mut LineScratch::default());
                for t in 0..n {
                    let (g, w) = (wide[t * stride + b], want[t]);
                    prop_assert!((g - w).abs() <= 1e-5 * (1.0 + w), "lane {b} sample {t}: {g} vs {w}");
                }
            }
        }
    }

    #[test]
    fn interleaving_round_trips() {
        for width in [LANES, WIDE] {
            for w in [1, 7, 8, 9, 16, 37] {
                for rows in 1..=width {
                    let group: Vec<f32> = (0..rows * w).map(|i| i as f32).collect();
                    let mut block = vec![-1.0; w * width];
                    interleave(&group, rows, w, width, &mut block);
                    for x in 0..w {
                        for b in 0..width {
                            let from = if b < rows { b } else { 0 };
                            assert_eq!(
                                block[x * width + b],
                                group[from * w + x],
                                "{width} {w} {rows} {x} {b}"
                            );
                        }
                    }
                    let mut back = vec![-1.0; rows * w];
                    deinterleave(&block, rows, w, width, &mut back);
                    assert_eq!(back, group, "{width} {w} {rows}");
                }
            }
        }
    }

    #[test]
    fn infinite_values_take_the_scalar_path() {
        let n = 9;
        let mut data = vec![f32::INFINITY; n * LANES];
        data[4 * LANES + 3] = 0.0;
        transform_lanes(&mut data, LANES, n, 1.0, false, &mut LaneScratch::default());
        for t in 0..n {
            assert_eq!(data[t * LANES + 3], ((t as f32) - 4.0).powi(2));
            assert!(data[t * LANES].is_infinite());
        }
    }
}
