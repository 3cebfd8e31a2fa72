//! Stores that bypass the caches (x86-64's non-temporal stores), for the
//! output columns of a first-hit query.
//!
//! Why: a million first hits are 48 MB of columns, written once and read by
//! the caller only after the query. Written through the caches, each line
//! of them is first read from memory (a read for ownership) and then
//! evicts a line of the height and distance maps the trace is reading; on
//! a coarse map that traffic was a few percent of the query. Streamed, the
//! stores of a line are combined and written out whole. Measured on the
//! Python benchmark's rays (`face.intersect` against `displace trace`, one
//! thread, best of four or five pairs, alternating builds, on a 2-core
//! Xeon VM): the binding's share over the trace fell from 12-15% to 6-7%
//! on the elevation model's coarse map and from 8-10% to 4-6% on the
//! studded face's.
//!
//! Every stream of stores is closed by [`fence`] before the columns are
//! handed over, so that the caller's reads see them (Intel SDM vol. 1,
//! 10.4.6.2: non-temporal stores are weakly ordered).

#[cfg(target_arch = "x86_64")]
use std::arch::x86_64::{_mm_sfence, _mm_stream_si32, _mm_stream_si64};

/// `*dst = v`, streamed.
#[inline(always)]
pub fn f32(dst: &mut f32, v: f32) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `dst` is a valid, aligned place of four bytes; SSE2 is part
    // of x86-64.
    unsafe {
        _mm_stream_si32((dst as *mut f32).cast(), v.to_bits() as i32)
    };
    #[cfg(not(target_arch = "x86_64"))]
    {
        *dst = v;
    }
}

/// `dst[k] = src[k]` for each `k`, streamed.
#[inline(always)]
pub fn f32s(dst: &mut [f32], src: &[f32]) {
    for (d, &s) in dst.iter_mut().zip(src) {
        f32(d, s);
    }
}

/// `*dst = v`, streamed.
#[inline(always)]
pub fn u32(dst: &mut u32, v: u32) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: as in [`f32`].
    unsafe {
        _mm_stream_si32((dst as *mut u32).cast(), v as i32)
    };
    #[cfg(not(target_arch = "x86_64"))]
    {
        *dst = v;
    }
}

/// `*dst = v`, streamed.
#[inline(always)]
pub fn i64(dst: &mut i64, v: i64) {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: `dst` is a valid, aligned place of eight bytes.
    unsafe {
        _mm_stream_si64(dst, v)
    };
    #[cfg(not(target_arch = "x86_64"))]
    {
        *dst = v;
    }
}

/// Orders the streamed stores before every store that follows, so that
/// the columns are complete when another thread reads them.
#[inline(always)]
pub fn fence() {
    #[cfg(target_arch = "x86_64")]
    // SAFETY: SSE is part of x86-64.
    unsafe {
        _mm_sfence()
    };
}
