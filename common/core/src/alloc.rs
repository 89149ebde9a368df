//! [`CacheAligned`], the global allocator of the project's binaries: every block of 512 bytes
//! to 1 MiB starts on a 64-byte boundary (a cache line, and the width of an AVX-512 register).
//!
//! The networks' activations, weights, gradients and Adam's moments are such blocks (nalgebra
//! matrices over `Vec<f32>`), and the products load them a register at a time. glibc's `malloc`
//! aligns to 16 bytes, so where a block starts within its cache line depends on what the
//! process allocated before: with a block off the boundary every 64-byte load straddles two
//! cache lines, and the same train step runs slower in one process than in another (the
//! binaries differ in what they allocate first). Aligned, every process runs it
//! at the same speed. The numbers do not change: only where the blocks are.
//!
//! Smaller blocks are left as they are (most are strings and small vectors), and so are larger
//! ones, so that a large zeroed block keeps `calloc`'s pages untouched until written (an
//! over-aligned zeroed block is written with zeros at once). A binary opts in with
//! `#[global_allocator] static ALLOC: CacheAligned = CacheAligned;`.

use std::alloc::{GlobalAlloc, Layout, System};

/// The boundary blocks start on: one cache line.
pub const LINE: usize = 64;

/// Blocks of this many bytes up to [`UP_TO`] are aligned to [`LINE`].
pub const FROM: usize = 512;

/// The largest block aligned to [`LINE`].
pub const UP_TO: usize = 1 << 20;

/// The system allocator with blocks of [`FROM`] to [`UP_TO`] bytes aligned to [`LINE`].
#[derive(Debug, Default, Clone, Copy)]
pub struct CacheAligned;

/// The layout a block of `layout` is allocated with.
fn aligned(layout: Layout) -> Layout {
    if (FROM..=UP_TO).contains(&layout.size()) && layout.align() < LINE {
        // A size of at most 1 MiB rounded up to 64 never overflows.
        Layout::from_size_align(layout.size(), LINE).unwrap_or(layout)
    } else {
        layout
    }
}

// SAFETY: every block is allocated by `System` with a layout at least as aligned as the one
// asked for and of the same size, and given back to `System` with that same layout (`aligned`
// is a function of the layout, which `GlobalAlloc`'s callers pass back unchanged).
#[allow(unsafe_code)]
unsafe impl GlobalAlloc for CacheAligned {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        // SAFETY: `aligned` keeps the size (non-zero, as the caller guarantees).
        unsafe { System.alloc(aligned(layout)) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        // SAFETY: as `alloc`.
        unsafe { System.alloc_zeroed(aligned(layout)) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: `ptr` was allocated here with `layout`, so by `System` with `aligned(layout)`.
        unsafe { System.dealloc(ptr, aligned(layout)) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        // SAFETY: the caller guarantees that `new_size`, rounded up to the alignment, does not
        // overflow `isize` and is non-zero.
        let new = unsafe { Layout::from_size_align_unchecked(new_size, layout.align()) };
        if aligned(layout) == layout && aligned(new) == new {
            // Neither block is over-aligned: the system's own realloc, which may grow in place.
            // SAFETY: `ptr` is `System`'s with `layout`; the new block's layout is `new`.
            return unsafe { System.realloc(ptr, layout, new_size) };
        }
        // SAFETY: `new` is a valid non-zero layout (above).
        let fresh = unsafe { self.alloc(new) };
        if !fresh.is_null() {
            // SAFETY: both blocks hold at least the smaller size and do not overlap (`fresh` is
            // a new allocation); `ptr` was allocated here with `layout`.
            unsafe {
                std::ptr::copy_nonoverlapping(ptr, fresh, layout.size().min(new_size));
                self.dealloc(ptr, layout);
            }
        }
        fresh
    }
}

#[cfg(test)]
#[allow(unsafe_code)]
mod tests {
    use super::*;

    fn layout(size: usize) -> Layout {
        Layout::from_size_align(size, 4).unwrap()
    }

    fn on_line(p: *mut u8) -> bool {
        (p as usize).is_multiple_of(LINE)
    }

    #[test]
    fn blocks_from_512_bytes_to_1_mib_start_on_a_cache_line() {
        let a = CacheAligned;
        for size in [FROM, 4096, 64 * 64 * 4, 128 * 128 * 4 + 12, UP_TO] {
            // Several at once, so that they cannot all land on a boundary by chance.
            let blocks: Vec<*mut u8> = (0..8)
                // SAFETY: a non-zero layout.
                .map(|_| unsafe { a.alloc(layout(size)) })
                .collect();
            for &p in &blocks {
                assert!(!p.is_null() && on_line(p), "{size} bytes at {p:?}");
                // SAFETY: `p` holds `size` bytes, allocated with this layout.
                unsafe {
                    std::ptr::write_bytes(p, 0xA5, size);
                    assert_eq!(*p.add(size - 1), 0xA5);
                    a.dealloc(p, layout(size));
                }
            }
        }
        // A block asked for with a larger alignment keeps it.
        let big = Layout::from_size_align(4096, 4096).unwrap();
        // SAFETY: a non-zero layout, given back with it.
        unsafe {
            let p = a.alloc(big);
            assert_eq!(p as usize % 4096, 0);
            a.dealloc(p, big);
        }
    }

    #[test]
    fn zeroed_blocks_are_zero_and_aligned() {
        let a = CacheAligned;
        for size in [100, FROM, 10_000, UP_TO + 1] {
            // SAFETY: a non-zero layout, given back with it; `p` holds `size` bytes.
            unsafe {
                let p = a.alloc_zeroed(layout(size));
                assert!(!p.is_null());
                assert!(std::slice::from_raw_parts(p, size).iter().all(|&b| b == 0));
                if (FROM..=UP_TO).contains(&size) {
                    assert!(on_line(p), "{size}");
                }
                a.dealloc(p, layout(size));
            }
        }
    }

    #[test]
    fn a_block_grown_and_shrunk_across_the_bounds_keeps_its_bytes() {
        let a = CacheAligned;
        let sizes = [16, 300, FROM, 5000, UP_TO, UP_TO + 4096, 70_000, 600, 40, 8];
        // SAFETY: the block is always reallocated with the layout it has; `len` bytes of it are
        // written and read within its size.
        unsafe {
            let mut size = sizes[0];
            let mut p = a.alloc(layout(size));
            for (i, b) in std::slice::from_raw_parts_mut(p, size)
                .iter_mut()
                .enumerate()
            {
                *b = (i % 251) as u8;
            }
            for &next in &sizes[1..] {
                let kept = size.min(next);
                p = a.realloc(p, layout(size), next);
                assert!(!p.is_null());
                if (FROM..=UP_TO).contains(&next) {
                    assert!(on_line(p), "{size} -> {next}");
                }
                let bytes = std::slice::from_raw_parts_mut(p, next);
                assert!(
                    bytes[..kept]
                        .iter()
                        .enumerate()
                        .all(|(i, &b)| b == (i % 251) as u8),
                    "{size} -> {next}"
                );
                for (i, b) in bytes.iter_mut().enumerate().skip(kept) {
                    *b = (i % 251) as u8;
                }
                size = next;
            }
            a.dealloc(p, layout(size));
        }
    }
}
