//! The large buffers of a command, allocated so that a refusal is an
//! error and not an abort.
//!
//! The estimates ([`super::check`]) refuse a job before it starts when its
//! peak is over the least limit in force; they count the buffers the code
//! knows of. What they cannot see (another process taking the memory in
//! the meantime, an allocator's own overhead, a limit set after the
//! check) would otherwise end in Rust's `memory allocation of N bytes
//! failed` and an abort (exit 134, nothing said about what or why). The
//! buffers that make up most of a peak (a bake's distance volume and
//! slabs, its column ranges, the decoded heights, a render's film) are
//! allocated here instead, with `try_reserve` or a checked zeroed
//! allocation, and a refusal becomes [`Error::OutOfMemory`] naming the
//! buffer and its size.

use super::human;
use crate::{Error, Result};
use std::alloc::Layout;

/// Element types whose all-zero bit pattern is a valid value (zero), so
/// that a zeroed buffer of them can come from the allocator's zeroed pages
/// (`calloc`: untouched until written, as `vec![0; n]` has them) without a
/// write of its own.
///
/// # Safety
/// Only for types every value of whose all-zero bytes is valid.
pub unsafe trait Zeroable: Copy {}

// SAFETY: zero bytes are the value 0 (0.0 for the floats) for each.
unsafe impl Zeroable for f32 {}
// SAFETY: as above.
unsafe impl Zeroable for f64 {}
// SAFETY: as above.
unsafe impl Zeroable for u8 {}
// SAFETY: as above.
unsafe impl Zeroable for u16 {}
// SAFETY: as above.
unsafe impl Zeroable for u32 {}
// SAFETY: as above.
unsafe impl Zeroable for u64 {}
// SAFETY: as above.
unsafe impl Zeroable for i32 {}
// SAFETY: as above.
unsafe impl Zeroable for i64 {}

/// `n` zeros, or [`Error::OutOfMemory`] naming `what` where the allocator
/// refuses (or `n` elements overflow the address space). Zeroed pages as
/// `vec![0; n]` has them: nothing is written until the buffer is.
pub fn zeroed<T: Zeroable>(what: &str, n: usize) -> Result<Vec<T>> {
    let Ok(layout) = Layout::array::<T>(n) else {
        return Err(refused::<T>(what, n));
    };
    if layout.size() == 0 {
        return Ok(Vec::new());
    }
    // SAFETY: `layout` has a non-zero size. A non-null pointer is a block
    // of `n` zeroed `T` (valid values, `Zeroable`) allocated by the global
    // allocator with `T`'s alignment and `n * size_of::<T>()` bytes: what
    // `Vec::from_raw_parts` asks for a vector of length and capacity `n`.
    unsafe {
        let p = std::alloc::alloc_zeroed(layout).cast::<T>();
        if p.is_null() {
            return Err(refused::<T>(what, n));
        }
        Ok(Vec::from_raw_parts(p, n, n))
    }
}

/// `n` copies of `value`, or [`Error::OutOfMemory`] naming `what` where the
/// allocator refuses.
pub fn filled<T: Clone>(what: &str, n: usize, value: T) -> Result<Vec<T>> {
    let mut v = Vec::new();
    v.try_reserve_exact(n).map_err(|_| refused::<T>(what, n))?;
    v.resize(n, value);
    Ok(v)
}

/// What a refused allocation of `n` elements of `T` says.
fn refused<T>(what: &str, n: usize) -> Error {
    let bytes = n as u128 * std::mem::size_of::<T>() as u128;
    Error::OutOfMemory {
        message: format!(
            "{what}: the system refused {} ({bytes} bytes) although the estimate allowed it \
             (another process may hold the memory, or a limit is lower than it reads); \
             free memory or ask for less",
            human(bytes)
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn buffers_are_zeroed_or_filled() {
        let z: Vec<f32> = zeroed("z", 1000).unwrap();
        assert_eq!((z.len(), z.capacity()), (1000, 1000));
        assert!(z.iter().all(|&v| v == 0.0));
        let f = filled("f", 7, -1.5f32).unwrap();
        assert_eq!(f, vec![-1.5; 7]);
        assert!(zeroed::<u8>("empty", 0).unwrap().is_empty());
    }

    /// Sizes no allocator can give (past the address space, or past what
    /// `isize` counts) are refused as errors naming the buffer, not as an
    /// abort.
    #[test]
    fn impossible_sizes_are_errors_naming_the_buffer() {
        for n in [usize::MAX / 4, 1usize << 60, (1usize << 47) / 4] {
            let e = zeroed::<f32>("the distance volume", n).unwrap_err();
            assert!(matches!(e, Error::OutOfMemory { .. }));
            let m = e.to_string();
            assert!(
                m.starts_with("the distance volume: the system refused"),
                "{m}"
            );
            assert!(filled("the slab", n, 1.0f32).is_err());
        }
    }
}
