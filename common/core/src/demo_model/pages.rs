//! Zeroed buffers for kernel matrices, in transparent huge pages where Linux offers them.
//!
//! A fresh buffer costs a page fault on the first write to each of its 4 KiB pages: the kernel
//! matrix of 1,000 demonstrations (8 MB) takes about 2,000 of them. Where the kernel serves
//! advised memory from transparent huge pages ("madvise" or "always" in
//! `/sys/kernel/mm/transparent_hugepage/enabled`), the buffer's whole 2 MiB pages are advised
//! so that each costs one fault. The values are zeros either way: the hint changes no result.
//! A buffer that will grow again can give its spare capacity's pages back and keep the
//! capacity ([`release_spare`]), so that growing never copies it.

/// The size of an x86-64 or AArch64 transparent huge page.
const HUGE_PAGE: usize = 2 << 20;

/// `len` zeros, the buffer's whole huge pages advised as such.
pub(crate) fn zeroed(len: usize) -> Vec<f64> {
    let v = vec![0.0; len];
    advise_huge(&v);
    v
}

/// Gives the whole pages of `v`'s spare capacity back to the kernel, the capacity kept: values
/// pushed into it later cost a page fault per page, not a copy of the buffer (moving a factor
/// of 10,000 demonstrations, 400 MB, takes a quarter of a second).
pub(crate) fn release_spare(v: &mut Vec<f64>) {
    let spare = v.spare_capacity_mut();
    let start = spare.as_ptr() as usize;
    release(start, start + std::mem::size_of_val(spare));
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

#[cfg(target_os = "linux")]
#[allow(unsafe_code)]
fn release(start: usize, end: usize) {
    // SAFETY: sysconf has no preconditions.
    let page = usize::try_from(unsafe { libc::sysconf(libc::_SC_PAGESIZE) }).unwrap_or(0);
    if page == 0 {
        return;
    }
    let (first, last) = (start.next_multiple_of(page), end / page * page);
    if last > first {
        // SAFETY: [first, last) lies inside a buffer's spare capacity, which holds no values
        // and stays allocated; MADV_DONTNEED frees its pages, which read as zeros when next
        // touched. A failure leaves them as they are.
        unsafe {
            libc::madvise(
                first as *mut libc::c_void,
                last - first,
                libc::MADV_DONTNEED,
            );
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn release(_: usize, _: usize) {}

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
    fn releasing_the_spare_capacity_keeps_the_values_and_the_capacity() {
        let mut v = zeroed(3 * HUGE_PAGE / 8);
        for (i, x) in v.iter_mut().enumerate() {
            *x = i as f64;
        }
        v.truncate(HUGE_PAGE / 8 + 3);
        let (ptr, capacity) = (v.as_ptr(), v.capacity());
        release_spare(&mut v);
        assert_eq!((v.as_ptr(), v.capacity()), (ptr, capacity));
        assert!(v.iter().enumerate().all(|(i, &x)| x == i as f64));
        v.extend((0..1000).map(|i| -(i as f64)));
        assert_eq!(v.as_ptr(), ptr, "the pushed values fill the kept capacity");
        assert_eq!(v[HUGE_PAGE / 8 + 3 + 999], -999.0);
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
