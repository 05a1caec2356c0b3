//! The figures the loop keeps as it runs, in fixed memory: following errors per motor, how
//! far each motor was commanded and moved, and the timing of every cycle. The report
//! (`qmarc-report`) turns them into `summary.json` after the move.

use qmarc_proto::MAX_MOTORS;
use qmarc_timer::{Histogram, Tick};

/// Following-error figures of one motor, accumulated every servo cycle (error = command −
/// actual, counts).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AxisErrors {
    /// Smallest error.
    pub min: f64,
    /// Largest error.
    pub max: f64,
    /// Σ |error|.
    pub sum_abs: f64,
    /// Σ error².
    pub sum_sq: f64,
    /// Cycles counted.
    pub count: u64,
}

impl AxisErrors {
    /// Adds one cycle's error.
    #[inline]
    pub fn add(&mut self, e: f64) {
        if self.count == 0 {
            self.min = e;
            self.max = e;
        } else {
            self.min = self.min.min(e);
            self.max = self.max.max(e);
        }
        self.sum_abs += e.abs();
        self.sum_sq += e * e;
        self.count += 1;
    }
}

/// Error figures of every motor, and how far each was commanded and moved.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct ErrorStats {
    /// Per motor.
    pub axes: [AxisErrors; MAX_MOTORS],
    /// Per motor: the range of the command and of the actual position.
    pub travel: [Travel; MAX_MOTORS],
}

impl ErrorStats {
    /// Adds one cycle: error = cmd − act for the first `n_motors`.
    #[inline]
    pub fn add(&mut self, n_motors: usize, cmd: &[f64; MAX_MOTORS], act: &[f64; MAX_MOTORS]) {
        for m in 0..n_motors {
            self.axes[m].add(cmd[m] - act[m]);
            self.travel[m].add(cmd[m], act[m]);
        }
    }
}

/// How far one motor was commanded and how far it moved, counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Travel {
    /// Smallest and largest command.
    pub cmd: (f64, f64),
    /// Smallest and largest actual position.
    pub act: (f64, f64),
}

impl Default for Travel {
    fn default() -> Travel {
        Travel { cmd: (f64::INFINITY, f64::NEG_INFINITY), act: (f64::INFINITY, f64::NEG_INFINITY) }
    }
}

impl Travel {
    /// Commanded travel at least this long (counts) is checked for being followed.
    pub const CHECKED_COUNTS: f64 = 10.0;

    /// Adds one cycle.
    #[inline]
    pub fn add(&mut self, cmd: f64, act: f64) {
        self.cmd = (self.cmd.0.min(cmd), self.cmd.1.max(cmd));
        self.act = (self.act.0.min(act), self.act.1.max(act));
    }

    /// The commanded and the actual travel (largest − smallest), counts.
    pub fn lengths(&self) -> (f64, f64) {
        ((self.cmd.1 - self.cmd.0).max(0.0), (self.act.1 - self.act.0).max(0.0))
    }

    /// True when the motor did not follow its command: it was commanded over at least
    /// [`Travel::CHECKED_COUNTS`] and moved less than half of that, or ended (its
    /// `final_error`) more than half of it away from its last command.
    pub fn not_followed(&self, final_error: f64) -> bool {
        let (commanded, moved) = self.lengths();
        commanded >= Travel::CHECKED_COUNTS
            && (moved < 0.5 * commanded || final_error.abs() > 0.5 * commanded)
    }
}

/// Timing figures of every cycle, in fixed memory.
#[derive(Debug, Clone, PartialEq)]
pub struct TimingStats {
    period_ns: u64,
    /// Wake latency against the intended expiry.
    pub wake_latency: Histogram,
    /// |interval between wakes − period|.
    pub period_error: Histogram,
    /// Read-all-encoders round trip.
    pub read: Histogram,
    /// Trajectory + law.
    pub compute: Histogram,
    /// From the intended tick to the DAC write being acknowledged.
    pub output_latency: Histogram,
    /// Periods that expired without a cycle.
    pub missed: u64,
    /// Of those, the ones lost in host stalls: a wake at least [`HOST_STALL_NS`] late.
    pub missed_in_stalls: u64,
    /// Wakes more than 40 µs off the period (the thesis' criterion, 5.3.2).
    pub outside_40us: u64,
    prev_woke_ns: Option<u64>,
}

/// Nanoseconds the thesis tolerated off the period.
const OFF_PERIOD_NS: u64 = 40_000;

/// A wake this late is a host stall, not the loop's doing: no cycle of ours takes a
/// millisecond, and a bare timer loop on the same machine sees such stalls too
/// (`../shared/notes/realtime-linux.md`: hypervisor stalls of 1–60 ms on a VM).
pub const HOST_STALL_NS: u64 = 1_000_000;

impl TimingStats {
    /// Histograms with 1 µs bins up to two periods.
    pub fn new(period_ns: u64) -> TimingStats {
        let bound = (2 * period_ns / 1_000) as usize;
        TimingStats {
            period_ns,
            wake_latency: Histogram::new(bound),
            period_error: Histogram::new(bound),
            read: Histogram::new(bound),
            compute: Histogram::new(bound),
            output_latency: Histogram::new(bound),
            missed: 0,
            missed_in_stalls: 0,
            outside_40us: 0,
            prev_woke_ns: None,
        }
    }

    /// Records a wake: latency, period error, missed periods. Called for every tick, also
    /// the one on which a move ends or faults, so a stall is never lost.
    #[inline]
    pub fn record_tick(&mut self, tick: &Tick) {
        self.wake_latency.record_ns(tick.latency_ns());
        if let Some(prev) = self.prev_woke_ns {
            let err = tick.woke_ns.saturating_sub(prev).abs_diff(self.period_ns);
            self.period_error.record_ns(err);
            if err > OFF_PERIOD_NS {
                self.outside_40us += 1;
            }
        }
        self.prev_woke_ns = Some(tick.woke_ns);
        self.missed += tick.missed;
        if tick.latency_ns() >= HOST_STALL_NS {
            self.missed_in_stalls += tick.missed;
        }
    }

    /// Records a completed cycle: when the read, the computation and the write ended.
    #[inline]
    pub fn record_cycle(
        &mut self,
        tick: &Tick,
        read_start_ns: u64,
        read_done_ns: u64,
        computed_ns: u64,
        written_ns: u64,
    ) {
        self.read.record_ns(read_done_ns.saturating_sub(read_start_ns));
        self.compute.record_ns(computed_ns.saturating_sub(read_done_ns));
        self.output_latency.record_ns(written_ns.saturating_sub(tick.intended_ns));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_errors_track_extremes_and_sums() {
        let mut e = AxisErrors::default();
        for v in [2.0, -3.0, 1.0] {
            e.add(v);
        }
        assert_eq!(e, AxisErrors { min: -3.0, max: 2.0, sum_abs: 6.0, sum_sq: 14.0, count: 3 });
    }

    #[test]
    fn timing_measures_against_the_intended_tick() {
        let mut t = TimingStats::new(400_000);
        let tick = |i: u64, late: u64, missed: u64| Tick {
            index: i,
            intended_ns: 1_000_000 + i * 400_000,
            woke_ns: 1_000_000 + i * 400_000 + late,
            missed,
        };
        let cycle = |t: &mut TimingStats, k: Tick, a, b, c, d| {
            t.record_tick(&k);
            t.record_cycle(&k, a, b, c, d);
        };
        cycle(&mut t, tick(0, 10_000, 0), 1_010_000, 1_030_000, 1_035_000, 1_060_000);
        cycle(&mut t, tick(1, 60_000, 0), 1_460_000, 1_480_000, 1_481_000, 1_500_000);
        cycle(&mut t, tick(3, 5_000, 1), 2_205_000, 2_215_000, 2_216_000, 2_230_000);
        assert_eq!((t.missed, t.missed_in_stalls), (1, 0));
        assert_eq!(t.wake_latency.max_ns(), 60_000);
        assert_eq!(t.outside_40us, 2, "+50 µs, then a skipped period");
        assert_eq!(t.read.percentiles().max_us, 20.0);
        assert_eq!(t.output_latency.max_ns(), 100_000);
        // A 2.1 ms host stall: five periods go by, all of them in the stall.
        t.record_tick(&tick(9, 2_100_000, 5));
        assert_eq!((t.missed, t.missed_in_stalls), (6, 5));
    }
}
