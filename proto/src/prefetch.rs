//! Cache-line prefetch for a message that arrived from another core.
//!
//! A round's observation is written on the world's core and read on each agent's; an
//! action goes the other way. Every line the reader touches first is a cross-core miss,
//! and the reader's code touches them one by one as it goes, so the misses queue up behind
//! each other. Asking for all lines in use the moment the message arrives lets them load
//! at once (`docs/PERFORMANCE.md`, "Prefetching a round's messages", has the figures).

/// Bytes per cache line on the machines this runs on.
const LINE: usize = 64;

/// Asks the CPU to start loading every cache line of `items` into the closest cache. A
/// hint only: it never faults and changes no value, so it cannot change a result.
#[inline]
pub fn prefetch<T>(items: &[T]) {
    for line in lines(items) {
        prefetch_line(line as *const u8);
    }
}

/// The addresses of the cache lines `items` spans, each rounded down to its line start.
#[inline]
fn lines<T>(items: &[T]) -> impl Iterator<Item = usize> {
    let start = items.as_ptr() as usize;
    let len = std::mem::size_of_val(items);
    let first = start / LINE;
    let count = if len == 0 { 0 } else { (start + len - 1) / LINE - first + 1 };
    (first..first + count).map(|line| line * LINE)
}

#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn prefetch_line(address: *const u8) {
    use std::arch::x86_64::{_mm_prefetch, _MM_HINT_T0};
    // SAFETY: SSE, the intrinsic's target feature, is part of every x86_64 CPU, and a
    // prefetch never dereferences its address: any address is fine.
    unsafe { _mm_prefetch::<_MM_HINT_T0>(address.cast()) };
}

#[cfg(not(target_arch = "x86_64"))]
#[inline(always)]
fn prefetch_line(_address: *const u8) {}

#[cfg(test)]
mod tests {
    use super::*;

    #[repr(C, align(64))]
    struct Lines([u8; 4 * LINE]);

    #[test]
    fn every_line_a_slice_touches_is_asked_for_once() {
        let block = Lines([0; 4 * LINE]);
        let base = block.0.as_ptr() as usize;
        let spans = |from: usize, len: usize| -> Vec<usize> {
            lines(&block.0[from..from + len]).map(|line| (line - base) / LINE).collect()
        };
        assert_eq!(spans(0, LINE), [0], "one aligned line");
        assert_eq!(spans(40, 64), [0, 1], "a line's worth straddling two lines");
        assert_eq!(spans(63, 2), [0, 1]);
        assert_eq!(spans(64, 129), [1, 2, 3]);
        assert_eq!(spans(10, 0), Vec::<usize>::new(), "nothing to load");
        prefetch(&block.0[40..200]);
    }
}
