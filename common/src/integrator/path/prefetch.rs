//! A hint to the CPU to start loading memory that is about to be read: the light-vertex cache
//! and its index are far larger than the caches, and a connection's pick is two dependent
//! random loads that would otherwise each stall the camera path
//! (docs/decisions/0044-connection-picks-prefetched.md).

/// Asks the CPU to bring every cache line of `value` into the cache; a no-op on targets
/// without a prefetch instruction.
#[inline(always)]
pub fn prefetch<T>(value: &T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let start = (value as *const T).cast::<i8>();
        let size = size_of::<T>().max(1);
        // every 64 bytes, and the last byte: an unaligned value may end on one more line
        for offset in (0..size).step_by(64).chain(std::iter::once(size - 1)) {
            // SAFETY: a prefetch only hints the cache and never faults; the address lies inside
            // `value`, which the reference keeps alive.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(offset)) };
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = value;
}
