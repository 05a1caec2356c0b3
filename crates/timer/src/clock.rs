//! [`Clock`]: where "now" comes from. [`MonotonicClock`] in real runs, [`MockClock`] in tests
//! and deterministic runs.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// A source of monotonic time in nanoseconds. `now_ns` never allocates, locks or fails.
pub trait Clock: Send + Sync {
    /// Current time in ns since an arbitrary fixed origin.
    fn now_ns(&self) -> u64;
}

/// `CLOCK_MONOTONIC`, the clock every ticker sleeps on.
#[derive(Debug, Clone, Copy, Default)]
pub struct MonotonicClock;

/// Reads `CLOCK_MONOTONIC` in ns.
#[inline]
pub fn monotonic_now_ns() -> u64 {
    // CLOCK_MONOTONIC always exists on Linux: the call cannot fail (0 if it ever did).
    let ts = nix::time::clock_gettime(nix::time::ClockId::CLOCK_MONOTONIC)
        .unwrap_or(nix::sys::time::TimeSpec::new(0, 0));
    ts.tv_sec() as u64 * crate::NS_PER_S + ts.tv_nsec() as u64
}

impl Clock for MonotonicClock {
    #[inline]
    fn now_ns(&self) -> u64 {
        monotonic_now_ns()
    }
}

/// A clock that only moves when told to. Clones share the same time.
#[derive(Debug, Clone, Default)]
pub struct MockClock {
    now: Arc<AtomicU64>,
}

impl MockClock {
    /// A mock clock at `start_ns`.
    pub fn new(start_ns: u64) -> MockClock {
        MockClock { now: Arc::new(AtomicU64::new(start_ns)) }
    }

    /// Moves the clock forward by `ns`.
    #[inline]
    pub fn advance(&self, ns: u64) {
        self.now.fetch_add(ns, Ordering::Relaxed);
    }

    /// Sets the clock to `ns`.
    #[inline]
    pub fn set(&self, ns: u64) {
        self.now.store(ns, Ordering::Relaxed);
    }
}

impl Clock for MockClock {
    #[inline]
    fn now_ns(&self) -> u64 {
        self.now.load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn monotonic_clock_does_not_go_back() {
        let c = MonotonicClock;
        let a = c.now_ns();
        let b = c.now_ns();
        assert!(b >= a);
        assert!(a > 0);
    }

    #[test]
    fn mock_clock_clones_share_time() {
        let c = MockClock::new(5);
        let d = c.clone();
        c.advance(10);
        assert_eq!(d.now_ns(), 15);
        d.set(3);
        assert_eq!(c.now_ns(), 3);
    }
}
