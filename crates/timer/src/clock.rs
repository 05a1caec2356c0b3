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

/// Reads the system clock (`CLOCK_REALTIME`) in ns since the Unix epoch: the time hosts
/// share (PTP, NTP), which log files and other programs stamp with.
#[inline]
pub fn realtime_now_ns() -> u64 {
    let ts = nix::time::clock_gettime(nix::time::ClockId::CLOCK_REALTIME)
        .unwrap_or(nix::sys::time::TimeSpec::new(0, 0));
    (ts.tv_sec().max(0) as u64) * crate::NS_PER_S + ts.tv_nsec() as u64
}

/// The system clock minus `CLOCK_MONOTONIC`, ns: a monotonic time plus this is the system
/// clock's (and a system-clock time minus it, this host's monotonic one). Read between two
/// monotonic reads, taken at their midpoint.
pub fn realtime_offset_ns() -> i64 {
    let before = monotonic_now_ns();
    let real = realtime_now_ns();
    let after = monotonic_now_ns();
    real as i64 - (before / 2 + after / 2) as i64
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

    /// The system clock is the Unix epoch's (std's), and the offset turns a monotonic time
    /// into it: both within the few ms a loaded host takes between two reads.
    #[test]
    fn a_monotonic_time_plus_the_offset_is_the_system_clocks() {
        let std_now =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap().as_nanos()
                as i64;
        let ours = realtime_now_ns() as i64;
        assert!((ours - std_now).abs() < 50_000_000, "{ours} vs {std_now}");
        let offset = realtime_offset_ns();
        let mono = monotonic_now_ns() as i64;
        let real = realtime_now_ns() as i64;
        assert!((mono + offset - real).abs() < 50_000_000, "{mono} + {offset} vs {real}");
        assert!(offset > 1_000_000_000_000_000_000, "after 2001: {offset}");
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
