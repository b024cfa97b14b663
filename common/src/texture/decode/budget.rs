//! Memory that image decodes may hold at once in this process, shared by every scene being
//! loaded (a coordinator validates submissions side by side; a worker may load while it
//! renders). Each decode reserves what its decoder really allocates at its peak, not only the
//! texels it keeps, before the first pixel is decoded, and waits while others hold the rest.
//!
//! Per-scene budgets ([`TextureLimits`](crate::texture::TextureLimits)) alone let three
//! concurrent submissions of one tiny file claiming 16384² pixels take three times the memory.

use std::sync::{Condvar, Mutex, MutexGuard};
use std::time::{Duration, Instant};

/// What concurrent decodes may hold unless [`set_capacity`] says otherwise.
pub const DEFAULT_CAPACITY: u64 = 2 << 30;
/// How long a decode waits for others to finish before it gives up.
const WAIT: Duration = Duration::from_secs(300);

struct State {
    capacity: u64,
    in_use: u64,
}

/// A capacity shared by reservations.
pub(crate) struct Budget {
    state: Mutex<State>,
    freed: Condvar,
}

/// The process's budget.
pub(crate) static GLOBAL: Budget = Budget::new(DEFAULT_CAPACITY);

/// Sets how many bytes decodes may hold at once in this process.
pub fn set_capacity(bytes: u64) {
    GLOBAL.state().capacity = bytes;
    GLOBAL.freed.notify_all();
}

/// The bytes decodes may hold at once.
pub fn capacity() -> u64 {
    GLOBAL.state().capacity
}

/// Why a reservation was not made.
#[derive(Debug, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// More than the whole capacity.
    TooLarge { capacity: u64 },
    /// Other decodes held the memory for the whole wait.
    Busy,
}

impl Budget {
    const fn new(capacity: u64) -> Self {
        Budget { state: Mutex::new(State { capacity, in_use: 0 }), freed: Condvar::new() }
    }

    fn state(&self) -> MutexGuard<'_, State> {
        // two counters, consistent after any panic
        self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Reserves `bytes`, waiting up to a few minutes while other decodes hold too much.
    pub(crate) fn take(&'static self, bytes: u64) -> Result<Reservation, Refusal> {
        self.take_within(bytes, WAIT)
    }

    fn take_within(&'static self, bytes: u64, wait: Duration) -> Result<Reservation, Refusal> {
        let deadline = Instant::now() + wait;
        let mut s = self.state();
        loop {
            if bytes > s.capacity {
                return Err(Refusal::TooLarge { capacity: s.capacity });
            }
            if s.in_use + bytes <= s.capacity {
                s.in_use += bytes;
                return Ok(Reservation { budget: self, bytes });
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return Err(Refusal::Busy);
            }
            s = self.freed.wait_timeout(s, left).unwrap_or_else(|poisoned| poisoned.into_inner()).0;
        }
    }
}

/// Memory reserved for one decode, given back when dropped.
pub(crate) struct Reservation {
    budget: &'static Budget,
    bytes: u64,
}

impl Drop for Reservation {
    fn drop(&mut self) {
        self.budget.state().in_use -= self.bytes;
        self.budget.freed.notify_all();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reservations add up, wait for each other and are refused when they can never fit.
    #[test]
    fn reservations_share_the_capacity() {
        let budget: &'static Budget = Box::leak(Box::new(Budget::new(100)));
        let a = budget.take_within(50, Duration::ZERO).unwrap();
        let b = budget.take_within(50, Duration::ZERO).unwrap();
        assert_eq!(budget.take_within(1, Duration::ZERO).err(), Some(Refusal::Busy));
        assert_eq!(budget.take_within(101, Duration::ZERO).err(), Some(Refusal::TooLarge { capacity: 100 }));
        let waiter = std::thread::spawn(move || budget.take_within(50, Duration::from_secs(60)).is_ok());
        drop(a);
        assert!(waiter.join().unwrap(), "a waiting decode goes on once memory is given back");
        drop(b);
        assert_eq!(budget.state().in_use, 0);
    }
}
