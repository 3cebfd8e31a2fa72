//! A global allocator that backs large buffers with transparent huge pages,
//! for the programs that trace (`displace`, the Python extension).
//!
//! Why: a trace reads the height map and the distance map at scattered
//! places, and a large map spans far more 4 KiB pages than the TLB holds
//! (a 4096 x 4096 elevation model's heights are 16 384 pages; the
//! second-level TLB of the cores we measure on holds about 2 000), so most
//! reads of a ray through such a map also walk the page tables. In 2 MiB
//! pages the same heights are 32. Linux gives those pages to anonymous
//! memory that asks for them (`madvise(MADV_HUGEPAGE)`; the kernel's
//! default policy, `enabled = madvise`, gives them to nothing else).
//! Measured on the Python benchmark's elevation model (4096 x 4096
//! heights, a 1024 x 1024 x 16 map, a million first-hit rays, one thread,
//! a 2-core Xeon VM): `displace trace` 0.90-0.92 Mrays/s in 4 KiB pages,
//! 1.05 in huge pages; the Python binding, whose process holds more memory
//! beside the maps and so missed the TLB more, 0.88 and 1.04.
//!
//! Allocations of at least [`LARGE`] bytes are mapped on their own,
//! aligned to 2 MiB and advised as huge; smaller ones go to the system
//! allocator. A mapping is zeroed and untouched until written, as a large
//! `calloc` is, so zeroed buffers still cost nothing until they are used
//! (their first touch may then happen on the threads that fill them). A
//! library does not choose the allocator of the program it is linked into,
//! so the programs declare it:
//!
//! ```ignore
//! #[global_allocator]
//! static ALLOC: displace_core::memory::HugePages = displace_core::memory::HugePages;
//! ```
//!
//! Elsewhere than on Linux every allocation goes to the system allocator.

use std::alloc::{GlobalAlloc, Layout, System};

/// The smallest allocation mapped on its own in huge pages: 4 MiB, two
/// huge pages, below which the TLB reach is not the problem and a mapping
/// a buffer would cost more than it saves.
pub const LARGE: usize = 4 << 20;

/// A huge page of x86-64 and AArch64 Linux (with 4 KiB base pages).
#[cfg(target_os = "linux")]
const HUGE_PAGE: usize = 2 << 20;

/// The alignment every mapping has, moved or not: a base page.
#[cfg(target_os = "linux")]
const BASE_PAGE: usize = 4096;

/// The global allocator described in the module's notes.
#[derive(Clone, Copy, Debug, Default)]
pub struct HugePages;

/// Whether `layout` is served by its own mapping.
#[cfg(target_os = "linux")]
fn mapped(layout: Layout) -> bool {
    layout.size() >= LARGE && layout.align() <= HUGE_PAGE
}

/// The length of the mapping of `size` bytes: whole huge pages.
#[cfg(target_os = "linux")]
fn mapping_len(size: usize) -> usize {
    size.div_ceil(HUGE_PAGE) * HUGE_PAGE
}

/// A new mapping of `size` bytes (`size >= LARGE`), zeroed, aligned to a
/// huge page and advised as huge; null where the system refuses.
///
/// # Safety
/// `size` is at least [`LARGE`].
#[cfg(target_os = "linux")]
unsafe fn map(size: usize) -> *mut u8 {
    let Some(len) = mapping_len(size).checked_add(HUGE_PAGE) else {
        return std::ptr::null_mut();
    };
    // Mapped a huge page longer than needed, then trimmed to an aligned
    // start: mmap aligns only to base pages.
    // SAFETY: an anonymous private mapping at an address of the kernel's
    // choosing touches no existing memory.
    let p = unsafe {
        libc::mmap(
            std::ptr::null_mut(),
            len,
            libc::PROT_READ | libc::PROT_WRITE,
            libc::MAP_PRIVATE | libc::MAP_ANONYMOUS,
            -1,
            0,
        )
    };
    if p == libc::MAP_FAILED {
        return std::ptr::null_mut();
    }
    let start = p as usize;
    let aligned = start.next_multiple_of(HUGE_PAGE);
    let want = mapping_len(size);
    let (head, tail) = (aligned - start, len - (aligned - start) - want);
    // SAFETY: both ranges lie inside the mapping just made, at base-page
    // boundaries (the start and the lengths are multiples of 4 KiB), and
    // nothing refers to them. A failure leaves them mapped, which wastes
    // address space and nothing else.
    unsafe {
        if head > 0 {
            libc::munmap(p, head);
        }
        if tail > 0 {
            libc::munmap((aligned + want) as *mut libc::c_void, tail);
        }
        // Advice only: where the kernel cannot (THP turned off, no huge
        // page free), the mapping stays in base pages and works the same.
        libc::madvise(aligned as *mut libc::c_void, want, libc::MADV_HUGEPAGE);
    }
    aligned as *mut u8
}

// SAFETY: every block handed out is either the system allocator's (and
// returned to it) or a private mapping of `mapping_len(layout.size())`
// bytes at an address aligned to `layout.align()` (2 MiB when new, a base
// page when moved by `mremap`, which is done only for layouts aligned to
// at most that), which is unmapped exactly when the block is freed; which
// of the two a block is follows from its layout alone, which the caller
// passes back unchanged.
unsafe impl GlobalAlloc for HugePages {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        #[cfg(target_os = "linux")]
        if mapped(layout) {
            // SAFETY: `mapped` checked the size.
            return unsafe { map(layout.size()) };
        }
        // SAFETY: the caller's layout, passed on.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        #[cfg(target_os = "linux")]
        if mapped(layout) {
            // SAFETY: as above; a new anonymous mapping reads as zeros.
            return unsafe { map(layout.size()) };
        }
        // SAFETY: the caller's layout, passed on.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        #[cfg(target_os = "linux")]
        if mapped(layout) {
            // SAFETY: `ptr` is the start of a mapping of this length made
            // by `map` for this layout (the caller's contract).
            unsafe { libc::munmap(ptr.cast(), mapping_len(layout.size())) };
            return;
        }
        // SAFETY: a block of the system allocator, with its layout.
        unsafe { System.dealloc(ptr, layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller's contract for `realloc`: `new_size` rounded
        // up to the alignment does not overflow, so this layout is valid.
        let new_layout = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        #[cfg(target_os = "linux")]
        if mapped(layout) && mapped(new_layout) && layout.align() <= BASE_PAGE {
            // Moved or resized in the page tables, not copied (as glibc
            // grows its own large blocks), so that a growing buffer never
            // holds its old and new copies at once. The kernel keeps the
            // advice with the mapping; a moved one starts at a base page,
            // enough for this alignment.
            // SAFETY: `ptr` is the start of a mapping of the old length
            // made for this layout (the caller's contract).
            let p = unsafe {
                libc::mremap(
                    ptr.cast(),
                    mapping_len(layout.size()),
                    mapping_len(new_size),
                    libc::MREMAP_MAYMOVE,
                )
            };
            return if p == libc::MAP_FAILED {
                std::ptr::null_mut()
            } else {
                p.cast()
            };
        }
        #[cfg(target_os = "linux")]
        if mapped(layout) || mapped(new_layout) {
            // SAFETY: both blocks are valid for the smaller of the two
            // sizes, and distinct; the old block is freed with its layout.
            unsafe {
                let new = self.alloc(new_layout);
                if !new.is_null() {
                    std::ptr::copy_nonoverlapping(ptr, new, layout.size().min(new_size));
                    self.dealloc(ptr, layout);
                }
                return new;
            }
        }
        // SAFETY: a block of the system allocator, with its layout.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Large blocks come back aligned to a huge page, zeroed and writable
    /// to their last byte, and keep their contents when grown or shrunk
    /// across the threshold; small ones are the system's.
    #[test]
    fn blocks_of_every_size_work() {
        let a = HugePages;
        let at = |n: usize| Layout::from_size_align(n, 8).expect("layout");
        for size in [2, 4096, LARGE - 1, LARGE, LARGE + 1, 3 * LARGE + 12345] {
            // SAFETY: non-zero sizes; each block is used within its size,
            // and freed (or reallocated) once with its layout.
            unsafe {
                let p = a.alloc_zeroed(at(size));
                assert!(!p.is_null(), "{size} bytes refused");
                #[cfg(target_os = "linux")]
                if size >= LARGE {
                    assert_eq!(p as usize % HUGE_PAGE, 0, "{size} bytes not aligned");
                }
                let s = std::slice::from_raw_parts_mut(p, size);
                assert!(s.iter().all(|&b| b == 0), "{size} bytes not zeroed");
                s[0] = 7;
                s[size - 1] = 9;
                // Grown past the threshold and back.
                let big = 2 * size + LARGE;
                let q = a.realloc(p, at(size), big);
                assert!(!q.is_null());
                assert_eq!((*q, *q.add(size - 1)), (7, 9));
                *q.add(big - 1) = 5;
                let r = a.realloc(q, at(big), size);
                assert!(!r.is_null());
                assert_eq!((*r, *r.add(size - 1)), (7, 9));
                // Shrunk to half.
                let half = size.div_ceil(2);
                let h = a.realloc(r, at(size), half);
                assert!(!h.is_null());
                assert_eq!(*h, 7);
                a.dealloc(h, at(half));
                // Uninitialised, written at both ends.
                let u = a.alloc(at(size));
                assert!(!u.is_null());
                *u = 1;
                *u.add(size - 1) = 2;
                a.dealloc(u, at(size));
            }
        }
    }
}
