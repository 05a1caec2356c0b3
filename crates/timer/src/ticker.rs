//! [`Ticker`]: blocks the servo thread until the next absolute expiry and says how late it woke.
//!
//! Tick `i` is due at `t0 + i·P`. A wake services the first tick not yet serviced; its
//! lateness is measured against *that* tick's expiry, never the latest one, so a stall shows
//! as the stall (`../shared/notes/realtime-linux.md`, "Measuring lateness correctly"). Ticks
//! that expired during the stall are counted in [`Tick::missed`] and skipped: [`Tick::index`]
//! is the newest expired tick, so time-based paths stay on time.

use crate::clock::{MockClock, monotonic_now_ns};
use crate::{Clock, NS_PER_S};
use nix::errno::Errno;
use nix::sys::time::TimeSpec;
use nix::sys::timerfd::{ClockId, Expiration, TimerFd, TimerFlags, TimerSetTimeFlags};
use nix::time::{ClockNanosleepFlags, clock_nanosleep};

/// One wake of a [`Ticker`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Tick {
    /// Index of the newest expired tick (0 for the first).
    pub index: u64,
    /// Expiry of the first tick this wake services (ns, `CLOCK_MONOTONIC` or mock time).
    pub intended_ns: u64,
    /// When the thread woke (ns, same clock).
    pub woke_ns: u64,
    /// Ticks that expired before this wake and were not serviced (overruns).
    pub missed: u64,
}

impl Tick {
    /// Wake latency in ns: how late the thread woke for the tick it services.
    #[inline]
    pub fn latency_ns(&self) -> u64 {
        self.woke_ns.saturating_sub(self.intended_ns)
    }
}

/// A ticker failed: the kernel refused the timer or the wait.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum TickerError {
    /// `timerfd_create` or `timerfd_settime` failed with this errno.
    #[error("cannot arm the timerfd: errno {0}")]
    Arm(i32),
    /// The wait failed with this errno.
    #[error("waiting for the next tick failed: errno {0}")]
    Wait(i32),
    /// `wait` was called before `start`.
    #[error("the ticker was not started")]
    NotStarted,
}

/// Paces a periodic loop. `start` may allocate and fail; `wait` is called once per cycle
/// and never allocates or locks.
pub trait Ticker: Send {
    /// The period in ns.
    fn period_ns(&self) -> u64;
    /// Arms the ticker: tick 0 is due one period from now. Returns its expiry.
    fn start(&mut self) -> Result<u64, TickerError>;
    /// Blocks until the next tick is due and reports the wake.
    fn wait(&mut self) -> Result<Tick, TickerError>;
}

/// How the real-time ticker waits (config `[timer] method`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum TickerKind {
    /// A one-shot absolute timerfd re-armed for each period after the work: the design's
    /// choice.
    #[default]
    TimerFd,
    /// `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`.
    Nanosleep,
    /// A periodic absolute timerfd (the kernel re-arms it inside `read()`, on the wake's path).
    TimerFdPeriodic,
}

impl TickerKind {
    /// The config spelling: `timerfd` or `nanosleep`.
    pub fn name(self) -> &'static str {
        match self {
            TickerKind::TimerFd => "timerfd",
            TickerKind::Nanosleep => "nanosleep",
            TickerKind::TimerFdPeriodic => "timerfd-periodic",
        }
    }

    /// Every kind, for benchmarks that measure them all.
    pub const ALL: [TickerKind; 3] =
        [TickerKind::TimerFd, TickerKind::Nanosleep, TickerKind::TimerFdPeriodic];

    /// Parses the config spelling.
    pub fn from_name(name: &str) -> Option<TickerKind> {
        match name {
            "timerfd" => Some(TickerKind::TimerFd),
            "nanosleep" => Some(TickerKind::Nanosleep),
            "timerfd-periodic" => Some(TickerKind::TimerFdPeriodic),
            _ => None,
        }
    }

    /// A ticker of this kind with period `period_ns`.
    pub fn build(self, period_ns: u64) -> Box<dyn Ticker> {
        match self {
            TickerKind::TimerFd => Box::new(TimerFdTicker::new(period_ns)),
            TickerKind::Nanosleep => Box::new(NanosleepTicker::new(period_ns)),
            TickerKind::TimerFdPeriodic => Box::new(TimerFdTicker::periodic(period_ns)),
        }
    }
}

fn timespec(ns: u64) -> TimeSpec {
    TimeSpec::new((ns / NS_PER_S) as libc::time_t, (ns % NS_PER_S) as libc::c_long)
}

/// Bookkeeping shared by the tickers: which tick is next and when it is due.
#[derive(Debug, Clone, Copy)]
struct Schedule {
    period_ns: u64,
    t0_ns: u64,
    next_index: u64,
}

impl Schedule {
    /// Tick 0 due one period after `now_ns`.
    fn starting(period_ns: u64, now_ns: u64) -> Schedule {
        Schedule { period_ns, t0_ns: now_ns + period_ns, next_index: 0 }
    }

    fn due_ns(&self, index: u64) -> u64 {
        self.t0_ns + index * self.period_ns
    }

    /// Services a wake at `woke_ns` during which `expired ≥ 1` ticks had expired.
    fn service(&mut self, woke_ns: u64, expired: u64) -> Tick {
        let expired = expired.max(1);
        let tick = Tick {
            index: self.next_index + expired - 1,
            intended_ns: self.due_ns(self.next_index),
            woke_ns,
            missed: expired - 1,
        };
        self.next_index += expired;
        tick
    }
}

/// An absolute timerfd on `CLOCK_MONOTONIC` (the design's choice).
///
/// One-shot (the default): each `wait` arms it for the tick due next and reads it — the
/// timer is programmed after the work, as `clock_nanosleep` does, not inside the wake's
/// `read()` as a periodic timerfd is (`hrtimer_forward_now` + `hrtimer_restart` in
/// `timerfd_read_iter`: in a VM guest a VM exit on every wake). Overruns are counted against
/// the schedule. Periodic ([`TimerFdTicker::periodic`]): armed once; `read` returns the
/// expirations since the last read, more than one meaning missed periods.
#[derive(Debug)]
pub struct TimerFdTicker {
    period_ns: u64,
    periodic: bool,
    fd: Option<TimerFd>,
    schedule: Option<Schedule>,
}

impl TimerFdTicker {
    /// A one-shot ticker with period `period_ns`; nothing is armed until [`Ticker::start`].
    pub fn new(period_ns: u64) -> TimerFdTicker {
        TimerFdTicker { period_ns, periodic: false, fd: None, schedule: None }
    }

    /// A periodic ticker with period `period_ns`.
    pub fn periodic(period_ns: u64) -> TimerFdTicker {
        TimerFdTicker { periodic: true, ..TimerFdTicker::new(period_ns) }
    }
}

impl Ticker for TimerFdTicker {
    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn start(&mut self) -> Result<u64, TickerError> {
        let arm = |e: Errno| TickerError::Arm(e as i32);
        let fd = TimerFd::new(ClockId::CLOCK_MONOTONIC, TimerFlags::TFD_CLOEXEC).map_err(arm)?;
        let schedule = Schedule::starting(self.period_ns, monotonic_now_ns());
        let t0_ns = schedule.t0_ns;
        if self.periodic {
            let periodic = Expiration::IntervalDelayed(timespec(t0_ns), timespec(self.period_ns));
            fd.set(periodic, TimerSetTimeFlags::TFD_TIMER_ABSTIME).map_err(arm)?;
        }
        self.fd = Some(fd);
        self.schedule = Some(schedule);
        Ok(t0_ns)
    }

    fn wait(&mut self) -> Result<Tick, TickerError> {
        let (Some(fd), Some(schedule)) = (&self.fd, &mut self.schedule) else {
            return Err(TickerError::NotStarted);
        };
        let due_ns = schedule.due_ns(schedule.next_index);
        if !self.periodic {
            // A due time already past expires at once: the read then returns without sleeping.
            let once = Expiration::OneShot(timespec(due_ns));
            fd.set(once, TimerSetTimeFlags::TFD_TIMER_ABSTIME)
                .map_err(|e| TickerError::Arm(e as i32))?;
        }
        // The expirations since the last read, a native-endian u64 (timerfd_create(2)).
        let mut expirations = [0u8; 8];
        loop {
            match nix::unistd::read(fd, &mut expirations) {
                Ok(8) => break,
                Err(Errno::EINTR) => continue,
                Ok(_) => return Err(TickerError::Wait(Errno::EIO as i32)),
                Err(e) => return Err(TickerError::Wait(e as i32)),
            }
        }
        let woke_ns = monotonic_now_ns();
        let expired = if self.periodic {
            u64::from_ne_bytes(expirations)
        } else {
            1 + woke_ns.saturating_sub(due_ns) / schedule.period_ns
        };
        Ok(schedule.service(woke_ns, expired))
    }
}

/// `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)` to each expiry; overruns counted by
/// comparing the wake time with the schedule.
#[derive(Debug)]
pub struct NanosleepTicker {
    period_ns: u64,
    schedule: Option<Schedule>,
}

impl NanosleepTicker {
    /// A ticker with period `period_ns`.
    pub fn new(period_ns: u64) -> NanosleepTicker {
        NanosleepTicker { period_ns, schedule: None }
    }
}

impl Ticker for NanosleepTicker {
    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn start(&mut self) -> Result<u64, TickerError> {
        let schedule = Schedule::starting(self.period_ns, monotonic_now_ns());
        self.schedule = Some(schedule);
        Ok(schedule.t0_ns)
    }

    fn wait(&mut self) -> Result<Tick, TickerError> {
        let Some(schedule) = &mut self.schedule else {
            return Err(TickerError::NotStarted);
        };
        let due = timespec(schedule.due_ns(schedule.next_index));
        loop {
            match clock_nanosleep(
                nix::time::ClockId::CLOCK_MONOTONIC,
                ClockNanosleepFlags::TIMER_ABSTIME,
                &due,
            ) {
                Ok(_) => break,
                Err(Errno::EINTR) => continue,
                Err(e) => return Err(TickerError::Wait(e as i32)),
            }
        }
        let woke_ns = monotonic_now_ns();
        let late = woke_ns.saturating_sub(schedule.due_ns(schedule.next_index));
        Ok(schedule.service(woke_ns, 1 + late / schedule.period_ns))
    }
}

/// Simulated time: every `wait` returns at once, exactly on time, and moves a [`MockClock`]
/// forward by one period. For tests and benchmarks of the loop without sleeping.
#[derive(Debug)]
pub struct ManualTicker {
    period_ns: u64,
    clock: MockClock,
    schedule: Option<Schedule>,
    late_ns: u64,
    skip: u64,
}

impl ManualTicker {
    /// A manual ticker with its own clock starting at 0.
    pub fn new(period_ns: u64) -> ManualTicker {
        ManualTicker::with_clock(period_ns, MockClock::new(0))
    }

    /// A manual ticker driving `clock`.
    pub fn with_clock(period_ns: u64, clock: MockClock) -> ManualTicker {
        ManualTicker { period_ns, clock, schedule: None, late_ns: 0, skip: 0 }
    }

    /// The next wake happens `late_ns` after its tick and after `skip` further ticks expired.
    pub fn inject_delay(&mut self, late_ns: u64, skip: u64) {
        self.late_ns = late_ns;
        self.skip = skip;
    }

    /// The clock this ticker moves.
    pub fn clock(&self) -> &MockClock {
        &self.clock
    }
}

impl Ticker for ManualTicker {
    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn start(&mut self) -> Result<u64, TickerError> {
        let schedule = Schedule::starting(self.period_ns, self.clock.now_ns());
        self.schedule = Some(schedule);
        Ok(schedule.t0_ns)
    }

    fn wait(&mut self) -> Result<Tick, TickerError> {
        let Some(schedule) = &mut self.schedule else {
            return Err(TickerError::NotStarted);
        };
        let due = schedule.due_ns(schedule.next_index);
        let woke = due + self.skip * self.period_ns + self.late_ns;
        self.clock.set(woke.max(self.clock.now_ns()));
        let tick = schedule.service(self.clock.now_ns(), 1 + self.skip);
        self.late_ns = 0;
        self.skip = 0;
        Ok(tick)
    }
}

/// A ticker that never waits: each tick is due the moment it is asked for (late by nothing,
/// missing nothing). Only for lock-step runs on the simulated robot (`--unpaced`), whose
/// time is the simulator's: a move then takes as long as its computing does.
#[derive(Debug)]
pub struct UnpacedTicker {
    period_ns: u64,
    /// The index of the next tick, once started.
    next_index: Option<u64>,
}

impl UnpacedTicker {
    /// An unpaced ticker; `period_ns` is what it reports as its period.
    pub fn new(period_ns: u64) -> UnpacedTicker {
        UnpacedTicker { period_ns, next_index: None }
    }
}

impl Ticker for UnpacedTicker {
    fn period_ns(&self) -> u64 {
        self.period_ns
    }

    fn start(&mut self) -> Result<u64, TickerError> {
        self.next_index = Some(0);
        Ok(monotonic_now_ns())
    }

    fn wait(&mut self) -> Result<Tick, TickerError> {
        let Some(index) = &mut self.next_index else {
            return Err(TickerError::NotStarted);
        };
        let now = monotonic_now_ns();
        let tick = Tick { index: *index, intended_ns: now, woke_ns: now, missed: 0 };
        *index += 1;
        Ok(tick)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_unpaced_ticker_ticks_at_once_and_misses_nothing() {
        let mut t = UnpacedTicker::new(400_000);
        assert_eq!(t.wait(), Err(TickerError::NotStarted));
        t.start().unwrap();
        for i in 0..10_000 {
            let tick = t.wait().unwrap();
            assert_eq!((tick.index, tick.missed, tick.latency_ns()), (i, 0, 0));
        }
    }

    #[test]
    fn schedule_counts_skipped_ticks_and_measures_against_the_first() {
        let mut s = Schedule { period_ns: 100, t0_ns: 1_000, next_index: 0 };
        let a = s.service(1_010, 1);
        assert_eq!(a, Tick { index: 0, intended_ns: 1_000, woke_ns: 1_010, missed: 0 });
        // Woke 350 ns after tick 1 was due: ticks 1, 2, 3 expired; 3 is current.
        let b = s.service(1_450, 3);
        assert_eq!(b, Tick { index: 3, intended_ns: 1_100, woke_ns: 1_450, missed: 2 });
        assert_eq!(b.latency_ns(), 350);
        let c = s.service(1_400 + 5, 1);
        assert_eq!(c.index, 4);
        assert_eq!(c.intended_ns, 1_400);
    }

    #[test]
    fn manual_ticker_runs_on_time_and_injects_stalls() {
        let mut t = ManualTicker::new(400);
        assert_eq!(t.wait(), Err(TickerError::NotStarted));
        let t0 = t.start().unwrap();
        assert_eq!(t0, 400);
        let a = t.wait().unwrap();
        assert_eq!((a.index, a.latency_ns(), a.missed), (0, 0, 0));
        t.inject_delay(30, 2);
        let b = t.wait().unwrap();
        assert_eq!((b.index, b.latency_ns(), b.missed), (3, 830, 2));
        let c = t.wait().unwrap();
        assert_eq!((c.index, c.latency_ns(), c.missed), (4, 0, 0));
        assert_eq!(t.clock().now_ns(), 400 + 4 * 400);
    }

    #[test]
    fn kinds_parse_their_names() {
        for k in TickerKind::ALL {
            assert_eq!(TickerKind::from_name(k.name()), Some(k));
        }
        assert_eq!(TickerKind::from_name("posix"), None);
    }
}
