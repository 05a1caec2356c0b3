//! What a move leaves behind besides its data: the error figures per motor, the timing
//! figures, the fault if any, and `summary.json` that carries them to the starter, the
//! console and the tests.

use crate::link::LinkError;
use qmarc_proto::{MAX_MOTORS, Status};
use qmarc_timer::{Histogram, Percentiles, Tick};
use serde::{Deserialize, Serialize};

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
    /// Wakes more than 40 µs off the period (the thesis' criterion, 5.3.2).
    pub outside_40us: u64,
    prev_woke_ns: Option<u64>,
}

/// Nanoseconds the thesis tolerated off the period.
const OFF_PERIOD_NS: u64 = 40_000;

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

/// What ended a move early.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultKind {
    /// A limit switch tripped.
    LimitSwitch,
    /// The hwserver stopped answering or died.
    HwserverLost,
    /// The hwserver was stopped by a signal and refuses to drive.
    HwserverShutdown,
    /// The hwserver's watchdog fired.
    Watchdog,
    /// The hardware reported an error.
    HardwareFault,
    /// An encoder count jumped further than the motor can move (a counter or cable fault).
    EncoderFault,
    /// The hwserver did not understand a request (a bug on one side).
    ProtocolError,
    /// A stop signal (Ctrl-C, SIGTERM) aborted the move.
    Aborted,
    /// The trajectory generator had no command for a sample.
    TrajectoryStarved,
    /// The trajectory generator could not go on (a bad knot in a stream).
    TrajectoryError,
    /// |command − actual| or |Σ (command − actual)| went past its limit.
    FollowingError,
    /// A command went outside the software position limits.
    SoftwareLimit,
    /// Too many servo periods in a row went by without a cycle.
    Overrun,
    /// Homing could not find, clear or leave a switch as it should.
    HomingFailed,
    /// The controller process died (reported by the starter).
    ControllerLost,
}

impl FaultKind {
    /// The `kind` string of `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::LimitSwitch => "limit_switch",
            FaultKind::HwserverLost => "hwserver_lost",
            FaultKind::HwserverShutdown => "hwserver_shutdown",
            FaultKind::Watchdog => "watchdog",
            FaultKind::HardwareFault => "hardware_fault",
            FaultKind::EncoderFault => "encoder_fault",
            FaultKind::ProtocolError => "protocol_error",
            FaultKind::Aborted => "aborted",
            FaultKind::TrajectoryStarved => "trajectory_starved",
            FaultKind::TrajectoryError => "trajectory_error",
            FaultKind::FollowingError => "following_error",
            FaultKind::SoftwareLimit => "software_limit",
            FaultKind::Overrun => "overrun",
            FaultKind::HomingFailed => "homing_failed",
            FaultKind::ControllerLost => "controller_lost",
        }
    }
}

/// A fault, as the loop records it: numbers only, `Copy`, formatted after the move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    /// What happened.
    pub kind: FaultKind,
    /// 0-based motor, if it concerns one.
    pub motor: Option<usize>,
    /// Servo sample index at which it was seen.
    pub cycle: u64,
    /// The hwserver status word of the response that reported it.
    pub status: Status,
    /// The link failure, for [`FaultKind::HwserverLost`] and IPC errors.
    pub link: Option<LinkError>,
    /// The signal, for [`FaultKind::Aborted`].
    pub signal: i32,
    /// Whether the hwserver acknowledged disabling every motor afterwards.
    pub disabled: bool,
    /// The offending value (following error, command, missed periods), counts.
    pub value: f64,
    /// The limit it broke.
    pub limit: f64,
    /// A following error that is the integrated one (Σ), not the instantaneous one.
    pub integrated: bool,
    /// The hwserver's timestamp of the read that showed the fault (its own clock: simulated
    /// time in lock-step), 0 if none.
    pub hw_time_ns: u64,
}

impl Fault {
    /// A fault of `kind` at sample `cycle` with nothing else known.
    #[inline]
    pub fn new(kind: FaultKind, cycle: u64) -> Fault {
        Fault {
            kind,
            motor: None,
            cycle,
            status: Status::OK,
            link: None,
            signal: 0,
            disabled: false,
            value: 0.0,
            limit: 0.0,
            integrated: false,
            hw_time_ns: 0,
        }
    }

    /// The fault a non-zero status word means, most severe first; `None` for a clean status.
    #[inline]
    pub fn from_status(status: Status, cycle: u64) -> Option<Fault> {
        if status.is_ok() {
            return None;
        }
        let (kind, motor) = if status.contains(Status::WATCHDOG) {
            (FaultKind::Watchdog, None)
        } else if status.contains(Status::SHUTDOWN) {
            (FaultKind::HwserverShutdown, None)
        } else if status.contains(Status::HARDWARE_FAULT) {
            (FaultKind::HardwareFault, None)
        } else if let Some((m, _)) = status.first_limit() {
            (FaultKind::LimitSwitch, Some(m))
        } else if let Some(m) = status.first_encoder_overflow() {
            (FaultKind::EncoderFault, Some(m))
        } else {
            (FaultKind::ProtocolError, None)
        };
        Some(Fault { motor, status, ..Fault::new(kind, cycle) })
    }

    /// A lost or failed link at sample `cycle`; a wait a stop signal ended is an abort.
    #[inline]
    pub fn from_link(e: LinkError, cycle: u64) -> Fault {
        let kind = match e {
            LinkError::Stopped { .. } => FaultKind::Aborted,
            _ => FaultKind::HwserverLost,
        };
        Fault { link: Some(e), ..Fault::new(kind, cycle) }
    }

    /// The message for the terminal and `summary.json`, motors 1-based.
    pub fn message(&self) -> String {
        let what = match self.kind {
            FaultKind::LimitSwitch => {
                let m = self.motor.unwrap_or(0);
                let side =
                    if self.status.contains(Status::limit_top(m)) { "top" } else { "bottom" };
                format!("motor {} hit its {side} limit switch", m + 1)
            }
            FaultKind::HwserverLost => match self.link {
                Some(e) => format!("lost the hwserver: {e}"),
                None => "lost the hwserver".to_string(),
            },
            FaultKind::HwserverShutdown => {
                "the hwserver was stopped and disabled the motors".to_string()
            }
            FaultKind::Watchdog => "the hwserver's watchdog fired: the controller was silent for \
                longer than hwserver.watchdog_periods with motors enabled (without PREEMPT_RT, \
                host stalls of a few ms can do that: raise the limit)"
                .to_string(),
            FaultKind::HardwareFault => "the hardware reported an error".to_string(),
            FaultKind::EncoderFault => format!(
                "motor {} encoder fault: its count jumped further than the motor can move",
                self.motor.map_or(0, |m| m + 1)
            ),
            FaultKind::ProtocolError => format!("the hwserver refused a request: {}", self.status),
            FaultKind::Aborted => format!(
                "aborted by {}",
                if self.signal == 0 {
                    "a stop signal"
                } else {
                    qmarc_timer::stop::signal_name(self.signal)
                }
            ),
            FaultKind::TrajectoryStarved => {
                "the knot stream ran dry before it ended (motors held, then disabled)".to_string()
            }
            FaultKind::TrajectoryError => "the trajectory failed".to_string(),
            FaultKind::FollowingError => format!(
                "motor {} {} following error {:.1} counts passed its limit {}",
                self.motor.map_or(0, |m| m + 1),
                if self.integrated { "integrated" } else { "instantaneous" },
                self.value,
                self.limit
            ),
            FaultKind::SoftwareLimit => format!(
                "motor {} was commanded to {:.1} counts, past its software limit {}",
                self.motor.map_or(0, |m| m + 1),
                self.value,
                self.limit
            ),
            FaultKind::Overrun => format!(
                "{} servo periods in a row went by without a cycle (limit {}: without \
                 PREEMPT_RT, host stalls of a few ms can do that; raise safety.max_missed_in_row)",
                self.value, self.limit
            ),
            FaultKind::HomingFailed => "homing failed".to_string(),
            FaultKind::ControllerLost => "the controller died".to_string(),
        };
        let after = if self.disabled {
            "all motors disabled"
        } else {
            "the hwserver did not acknowledge disabling the motors (on hardware the charge-pump \
             relay drops them when the hwserver stops)"
        };
        format!("{what} at cycle {}; {after}", self.cycle)
    }

    /// The JSON form.
    pub fn report(&self) -> FaultReport {
        FaultReport {
            kind: self.kind.name().to_string(),
            motor: self.motor.map(|m| m + 1),
            cycle: self.cycle,
            message: self.message(),
            hw_time_ns: (self.hw_time_ns > 0).then_some(self.hw_time_ns),
        }
    }
}

/// A fault in `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaultReport {
    /// [`FaultKind::name`].
    pub kind: String,
    /// 1-based motor, or null.
    pub motor: Option<usize>,
    /// Servo sample index.
    pub cycle: u64,
    /// What happened, in words.
    pub message: String,
    /// The hwserver's clock when the fault was read (simulated time in lock-step), ns.
    #[serde(default)]
    pub hw_time_ns: Option<u64>,
}

/// Error figures of one motor in `summary.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MotorSummary {
    /// Smallest error, counts.
    pub min_error_counts: f64,
    /// Largest error, counts.
    pub max_error_counts: f64,
    /// Σ |error|, counts.
    pub accumulated_abs_error_counts: f64,
    /// Σ error², counts².
    pub sum_squares_error_counts2: f64,
    /// Smallest error, rad at the arm.
    pub min_error_rad: f64,
    /// Largest error, rad.
    pub max_error_rad: f64,
    /// Σ |error|, rad.
    pub accumulated_abs_error_rad: f64,
    /// Σ error², rad².
    pub sum_squares_error_rad2: f64,
    /// False when the motor did not follow its command ([`Travel::not_followed`]): a seized
    /// joint, a dead amplifier. Such a motor is never reported ok.
    #[serde(default = "yes")]
    pub followed: bool,
}

fn yes() -> bool {
    true
}

impl MotorSummary {
    /// The figures of `e`, with `counts_per_rad` to convert (rad = counts / counts_per_rad).
    pub fn new(e: &AxisErrors, counts_per_rad: f64) -> MotorSummary {
        MotorSummary {
            min_error_counts: e.min,
            max_error_counts: e.max,
            accumulated_abs_error_counts: e.sum_abs,
            sum_squares_error_counts2: e.sum_sq,
            min_error_rad: e.min / counts_per_rad,
            max_error_rad: e.max / counts_per_rad,
            accumulated_abs_error_rad: e.sum_abs / counts_per_rad,
            sum_squares_error_rad2: e.sum_sq / (counts_per_rad * counts_per_rad),
            followed: true,
        }
    }
}

/// The gains a motor's law ran with (rescaled to the servo period, see
/// [`crate::config::Settings::effective_gains`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct GainsReport {
    /// Kp.
    pub kp: f64,
    /// Ki.
    pub ki: f64,
    /// Kd.
    pub kd: f64,
    /// Kvff.
    pub kvff: f64,
    /// Kaff.
    pub kaff: f64,
}

impl From<crate::config::MotorGains> for GainsReport {
    fn from(g: crate::config::MotorGains) -> GainsReport {
        GainsReport { kp: g.kp, ki: g.ki, kd: g.kd, kvff: g.kvff, kaff: g.kaff }
    }
}

/// The hold at the end of a path (`trajectory.settle_s`) in `summary.json`: the error figures
/// of the move leave it out; these are its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SettleSummary {
    /// Cycles of the settle (fewer than planned if a fault ended it).
    pub cycles: u64,
    /// Their duration, s.
    pub seconds: f64,
    /// Per motor: command − actual at the end of the settle, counts.
    pub final_error_counts: Vec<f64>,
    /// Per motor: the largest |command − actual| during the settle, counts.
    pub max_abs_error_counts: Vec<f64>,
}

/// Percentiles in `summary.json`, µs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Pct {
    /// Median.
    pub p50: f64,
    /// 99th percentile.
    pub p99: f64,
    /// 99.9th percentile.
    pub p999: f64,
    /// Maximum.
    pub max: f64,
}

impl From<Percentiles> for Pct {
    fn from(p: Percentiles) -> Pct {
        Pct { p50: p.p50_us, p99: p.p99_us, p999: p.p999_us, max: p.max_us }
    }
}

/// Timing figures in `summary.json`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct TimingSummary {
    /// `timerfd` or `nanosleep`.
    pub method: String,
    /// Scheduling policy of the servo thread, e.g. `SCHED_FIFO 80`.
    pub policy: String,
    /// Wake latency against the intended expiry, µs.
    pub wake_latency_us: Pct,
    /// |interval between wakes − period|, µs.
    pub period_error_us: Pct,
    /// Wakes more than 40 µs off the period.
    pub outside_40us: u64,
    /// Periods that expired without a cycle.
    pub missed_periods: u64,
    /// Read round trip, µs.
    pub read_us: Pct,
    /// Trajectory + law, µs.
    pub compute_us: Pct,
    /// Intended tick → DAC write acknowledged, µs.
    pub output_latency_us: Pct,
}

impl TimingSummary {
    /// The figures of `t`.
    pub fn new(t: &TimingStats, method: &str, policy: &str) -> TimingSummary {
        TimingSummary {
            method: method.to_string(),
            policy: policy.to_string(),
            wake_latency_us: t.wake_latency.percentiles().into(),
            period_error_us: t.period_error.percentiles().into(),
            outside_40us: t.outside_40us,
            missed_periods: t.missed,
            read_us: t.read.percentiles().into(),
            compute_us: t.compute.percentiles().into(),
            output_latency_us: t.output_latency.percentiles().into(),
        }
    }
}

/// `summary.json`: everything about one move.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// `step`, `run` or `home`.
    pub mode: String,
    /// The trajectory generator (`step`, `spline`, `pvt`).
    pub trajectory: String,
    /// True when the move ran to its end without a fault.
    pub ok: bool,
    /// True when SCHED_FIFO was refused and the loop ran SCHED_OTHER.
    pub degraded: bool,
    /// True for a lock-step simulated run.
    pub deterministic: bool,
    /// The fault that ended the move, or null.
    pub fault: Option<FaultReport>,
    /// Motors driven.
    #[serde(default)]
    pub n_motors: usize,
    /// Servo cycles executed (of the path; the settle is apart).
    pub cycles: u64,
    /// Samples the path has (duration / period + 1), if known.
    pub planned_samples: Option<u64>,
    /// Servo period, µs.
    pub period_us: u32,
    /// Gathered every N cycles.
    pub gather_every: u32,
    /// Rows in gather.csv.
    pub gathered_rows: u64,
    /// Counts per radian used for the rad figures.
    pub counts_per_rad: f64,
    /// Error figures per motor, over the path (the settle at its end is in `settle`).
    pub motors: Vec<MotorSummary>,
    /// The servo period the configured gains were tuned at, µs.
    #[serde(default)]
    pub gains_period_us: u32,
    /// Per motor: the gains the law ran with, rescaled from `gains_period_us` to `period_us`.
    #[serde(default)]
    pub gains: Vec<GainsReport>,
    /// The hold at the end of the path, if it began.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle: Option<SettleSummary>,
    /// Timing figures.
    pub timing: TimingSummary,
    /// Warnings of the run (degraded real time, dropped rows).
    pub warnings: Vec<String>,
    /// The pid of the run's `qmarc-starter` (the controller's parent): whose files these are.
    #[serde(default)]
    pub starter_pid: u32,
    /// The files this move wrote (summary.json among them), where they are.
    #[serde(default)]
    pub files: Vec<std::path::PathBuf>,
    /// `home` only: per motor where the top switch was found and cleared and where the motor
    /// ended (counts in the frame before homing; each counter reads 0 there afterwards).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub homing: Option<serde_json::Value>,
}

impl Summary {
    /// The summary the starter writes when the controller died before writing its own: what
    /// it knows (the motors, the cycles the move reached, why).
    pub fn controller_lost(
        mode: &str,
        n_motors: usize,
        period_us: u32,
        cycles: u64,
        message: String,
    ) -> Summary {
        Summary {
            mode: mode.to_string(),
            trajectory: String::new(),
            ok: false,
            degraded: false,
            deterministic: false,
            fault: Some(FaultReport {
                kind: FaultKind::ControllerLost.name().to_string(),
                motor: None,
                cycle: cycles,
                message,
                hw_time_ns: None,
            }),
            n_motors,
            cycles,
            planned_samples: None,
            period_us,
            gather_every: 0,
            gathered_rows: 0,
            counts_per_rad: 0.0,
            motors: Vec::new(),
            gains_period_us: 0,
            gains: Vec::new(),
            settle: None,
            timing: TimingSummary::default(),
            warnings: Vec::new(),
            starter_pid: std::process::id(),
            files: Vec::new(),
            homing: None,
        }
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
        let s = MotorSummary::new(&e, 2.0);
        assert_eq!(
            (s.min_error_rad, s.accumulated_abs_error_rad, s.sum_squares_error_rad2),
            (-1.5, 3.0, 3.5)
        );
    }

    #[test]
    fn status_words_map_to_fault_kinds() {
        let check = |s: Status, kind: FaultKind, motor: Option<usize>| {
            let f = Fault::from_status(s, 7).unwrap();
            assert_eq!((f.kind, f.motor, f.cycle), (kind, motor, 7), "{s}");
        };
        assert_eq!(Fault::from_status(Status::OK, 1), None);
        check(Status::limit_bottom(2), FaultKind::LimitSwitch, Some(2));
        check(Status::limit_top(0) | Status::WATCHDOG, FaultKind::Watchdog, None);
        check(Status::SHUTDOWN, FaultKind::HwserverShutdown, None);
        check(Status::encoder_overflow(1), FaultKind::EncoderFault, Some(1));
        check(Status::UNKNOWN_MESSAGE, FaultKind::ProtocolError, None);
        let mut f = Fault::from_status(Status::limit_top(0), 1234).unwrap();
        assert!(f.message().ends_with(
            "the hwserver did not acknowledge disabling the motors (on hardware the charge-pump \
             relay drops them when the hwserver stops)"
        ));
        f.disabled = true;
        assert_eq!(
            f.message(),
            "motor 1 hit its top limit switch at cycle 1234; all motors disabled"
        );
        let r = f.report();
        assert_eq!((r.kind.as_str(), r.motor, r.cycle), ("limit_switch", Some(1), 1234));
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
        assert_eq!(t.missed, 1);
        assert_eq!(t.wake_latency.max_ns(), 60_000);
        assert_eq!(t.outside_40us, 2, "+50 µs, then a skipped period");
        assert_eq!(t.read.percentiles().max_us, 20.0);
        assert_eq!(t.output_latency.max_ns(), 100_000);
    }
}
