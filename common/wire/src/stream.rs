//! Copies into shared memory with stores that bypass the cache.
//!
//! The learner writes its weights into a sample that an actor on another core read a few
//! publications earlier: with ordinary stores every cache line of it is first fetched from that
//! core and invalidated there (a read for ownership), which makes the copy several times slower
//! than the same copy within one core. Non-temporal stores write whole lines without reading
//! them, and leave the reader's next read to fetch the new lines.

use std::mem::MaybeUninit;

/// Copies `parts`, one after another, into `dst`, which must be exactly as long as they are
/// together (panics otherwise). Every element of `dst` is written.
pub(crate) fn copy_parts(dst: &mut [MaybeUninit<f32>], parts: &[&[f32]]) {
    let total: usize = parts.iter().map(|p| p.len()).sum();
    assert_eq!(dst.len(), total, "the parts do not fill the destination");
    let mut offset = 0;
    for part in parts {
        copy_streaming(&mut dst[offset..offset + part.len()], part);
        offset += part.len();
    }
    fence();
}

/// Plain stores up to the first 16-byte boundary of `dst` and after the last one, streaming
/// stores of four lanes between them.
#[cfg(target_arch = "x86_64")]
fn copy_streaming(dst: &mut [MaybeUninit<f32>], src: &[f32]) {
    use std::arch::x86_64::{_mm_loadu_ps, _mm_stream_ps};
    let misaligned = dst.as_ptr().align_offset(16).min(dst.len());
    let (head, rest) = dst.split_at_mut(misaligned);
    let (src_head, src_rest) = src.split_at(misaligned);
    copy_plain(head, src_head);
    let body = rest.len() / 4 * 4;
    let (body_dst, tail) = rest.split_at_mut(body);
    let (body_src, src_tail) = src_rest.split_at(body);
    for (d, s) in body_dst.chunks_exact_mut(4).zip(body_src.chunks_exact(4)) {
        // SAFETY: SSE is part of x86_64. `s` holds four readable floats (unaligned load); `d`
        // is four writable floats starting on a 16-byte boundary (`align_offset` above, and
        // every chunk after it is 16 bytes further), as the streaming store requires.
        #[allow(unsafe_code)]
        unsafe {
            _mm_stream_ps(d.as_mut_ptr().cast::<f32>(), _mm_loadu_ps(s.as_ptr()));
        }
    }
    copy_plain(tail, src_tail);
}

#[cfg(not(target_arch = "x86_64"))]
fn copy_streaming(dst: &mut [MaybeUninit<f32>], src: &[f32]) {
    copy_plain(dst, src);
}

fn copy_plain(dst: &mut [MaybeUninit<f32>], src: &[f32]) {
    for (d, s) in dst.iter_mut().zip(src) {
        d.write(*s);
    }
}

/// Orders the streaming stores before whatever follows (the send that publishes the sample):
/// they are weakly ordered, unlike ordinary stores.
#[cfg(target_arch = "x86_64")]
fn fence() {
    // SAFETY: SSE is part of x86_64; the fence has no operands.
    #[allow(unsafe_code)]
    unsafe {
        std::arch::x86_64::_mm_sfence();
    }
}

#[cfg(not(target_arch = "x86_64"))]
fn fence() {}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every split of a buffer into parts, at every alignment of the destination, gives the
    /// concatenation of the parts.
    #[test]
    fn the_parts_land_one_after_another_at_any_alignment() {
        let src: Vec<f32> = (0..203).map(|i| i as f32 * 0.5 - 7.0).collect();
        for skip in 0..4 {
            for cuts in [vec![], vec![1], vec![3, 4], vec![5, 100, 101], vec![0, 202]] {
                let mut parts = Vec::new();
                let mut from = 0;
                for c in cuts.iter().copied().chain([src.len()]) {
                    parts.push(&src[from..c]);
                    from = c;
                }
                let mut buf = vec![MaybeUninit::new(f32::NAN); src.len() + skip];
                copy_parts(&mut buf[skip..], &parts);
                // SAFETY (test): every element was initialised by `vec!`.
                #[allow(unsafe_code)]
                let got: Vec<f32> = buf[skip..]
                    .iter()
                    .map(|x| unsafe { x.assume_init() })
                    .collect();
                assert_eq!(got, src, "skip {skip}, cuts {cuts:?}");
            }
        }
    }

    #[test]
    #[should_panic(expected = "do not fill")]
    fn parts_shorter_than_the_destination_are_refused() {
        let mut buf = vec![MaybeUninit::new(0.0f32); 5];
        copy_parts(&mut buf, &[&[1.0, 2.0]]);
    }

    #[test]
    fn nothing_to_copy_is_fine() {
        copy_parts(&mut [], &[]);
        copy_parts(&mut [], &[&[]]);
    }
}
