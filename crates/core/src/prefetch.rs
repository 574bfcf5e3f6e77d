//! Software prefetch: asking for memory a little before it is used.
//!
//! With thousands of tags, a tag's state is out of cache when its next
//! read comes, and each of its cache lines costs a trip to memory (about
//! 100 ns, more under a hypervisor's nested page tables) that the filter's
//! arithmetic waits for. The engine knows which tag comes next in a batch
//! ([`crate::engine::Engine::run_batch`]), so it asks for that tag's lines
//! while the current tag is stepped ([`crate::track::Tracker::prefetch`]);
//! they are then in cache when needed. A prefetch is a hint: it changes
//! only timing, never results.

/// Cache line size assumed (bytes): 64 on every x86-64 and most ARM cores.
pub const LINE_BYTES: usize = 64;

/// Starts loading the cache lines that hold `bytes` bytes from `start`.
/// A no-op where no stable prefetch instruction is exposed (non-x86-64).
#[inline]
pub fn bytes(start: *const u8, bytes: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        let mut offset = 0;
        while offset < bytes {
            // SAFETY: PREFETCHT0 only hints the cache: it never faults,
            // whatever the address (null, freed or unmapped included), and
            // its one effect is timing. `wrapping_add` forms the address
            // without claiming it lies in an allocation.
            unsafe { std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(start.wrapping_add(offset).cast()) };
            offset += LINE_BYTES;
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (start, bytes);
}

/// Starts loading the cache lines of `value` (a slice: all of its items).
#[inline]
pub fn value<T: ?Sized>(value: &T) {
    bytes((value as *const T).cast(), std::mem::size_of_val(value));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn prefetching_changes_nothing_and_never_faults() {
        let data = vec![1.0f64; 1000];
        value(data.as_slice());
        bytes(std::ptr::null(), 4096);
        bytes(usize::MAX as *const u8, 128); // wraps around: still a hint
        assert!(data.iter().all(|&x| x == 1.0));
    }
}
