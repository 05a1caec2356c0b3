//! Real-time pacing for the QMARC servo loop (thesis 3.7, 4.1).
//!
//! The thesis' Timer was an interrupt handler that woke the controller every servo period.
//! Here the servo thread itself is the timer thread: [`rt`] makes it SCHED_FIFO and locks
//! memory, and a [`Ticker`] blocks it until the next absolute expiry. Two tickers measure the
//! machine's limit differently (`../shared/notes/realtime-linux.md`): [`TimerFdTicker`], the
//! design's periodic absolute timerfd, and [`NanosleepTicker`], `clock_nanosleep` with
//! `TIMER_ABSTIME`. Both report every wake against its *intended* expiry and count missed
//! periods. [`ManualTicker`] and [`MockClock`] give tests simulated time. [`Histogram`] keeps
//! latency figures in fixed memory.
//!
//! ```
//! use qmarc_timer::{Histogram, ManualTicker, Ticker};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut ticker = ManualTicker::new(400_000);
//! let mut latency = Histogram::new(800);
//! ticker.start()?;
//! for _ in 0..3 {
//!     let tick = ticker.wait()?;
//!     latency.record_ns(tick.woke_ns - tick.intended_ns);
//! }
//! assert_eq!(latency.count(), 3);
//! assert_eq!(latency.percentiles().max_us, 0.0);
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod clock;
pub mod cpus;
pub mod histogram;
pub mod rt;
pub mod stop;
pub mod ticker;

pub use clock::{Clock, MockClock, MonotonicClock};
pub use histogram::{Histogram, Percentiles};
pub use ticker::{
    ManualTicker, NanosleepTicker, Tick, Ticker, TickerError, TickerKind, TimerFdTicker,
    UnpacedTicker,
};

/// Nanoseconds per microsecond.
pub const NS_PER_US: u64 = 1_000;
/// Nanoseconds per second.
pub const NS_PER_S: u64 = 1_000_000_000;
