//! Zeroed buffers for kernel matrices, in transparent huge pages where Linux offers them.
//!
//! A fresh buffer costs a page fault on the first write to each of its 4 KiB pages: the kernel
//! matrix of 1,000 demonstrations (8 MB) takes about 2,000 of them. Where the kernel serves
//! advised memory from transparent huge pages ("madvise" or "always" in
//! `/sys/kernel/mm/transparent_hugepage/enabled`), the buffer's whole 2 MiB pages are advised
//! so that each costs one fault. The values are zeros either way: the hint changes no result.

/// The size of an x86-64 or AArch64 transparent huge page.
const HUGE_PAGE: usize = 2 << 20;

/// `len` zeros, the buffer's whole huge pages advised as such.
pub(crate) fn zeroed(len: usize) -> Vec<f64> {
    let v = vec![0.0; len];
    advise_huge(&v);
    v
}

/// The 2 MiB-aligned byte range inside `v`, if it holds one huge page at least.
fn huge_range(v: &[f64]) -> Option<(usize, usize)> {
    let start = v.as_ptr() as usize;
    let first = start.next_multiple_of(HUGE_PAGE);
    let end = (start + std::mem::size_of_val(v)) / HUGE_PAGE * HUGE_PAGE;
    (end > first).then_some((first, end - first))
}

#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn advise_huge(v: &[f64]) {
    if let Some((first, len)) = huge_range(v) {
        // SAFETY: [first, first + len) lies inside `v`'s allocation, starts on a page boundary
        // and is not freed while madvise runs; MADV_HUGEPAGE changes no contents, only how
        // later faults are served. A failure (no transparent huge pages) leaves 4 KiB pages.
        unsafe {
            libc::madvise(first as *mut libc::c_void, len, libc::MADV_HUGEPAGE);
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn advise_huge(_: &[f64]) {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zeroed_buffers_hold_zeros_of_the_length_asked() {
        for len in [0, 1, 1000, 3 * HUGE_PAGE / 8 + 5] {
            let v = zeroed(len);
            assert_eq!(v.len(), len);
            assert!(v.iter().all(|&x| x == 0.0));
        }
    }

    #[test]
    fn the_advised_range_is_aligned_and_inside_the_buffer() {
        let v = zeroed(5 * HUGE_PAGE / 8);
        let (first, len) = huge_range(&v).expect("five huge pages hold an aligned one");
        let start = v.as_ptr() as usize;
        assert_eq!(first % HUGE_PAGE, 0);
        assert_eq!(len % HUGE_PAGE, 0);
        assert!(first >= start && first + len <= start + v.len() * 8);
        assert!(len >= 4 * HUGE_PAGE);
        assert_eq!(huge_range(&v[..HUGE_PAGE / 16]), None);
    }
}
