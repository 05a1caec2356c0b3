//! `summary.json`: everything about one move, as the starter, the console and the tests read
//! it. The schema lives here, apart from the figures the loop keeps (`qmarc_controller::stats`).

use crate::effector::{EffectorSummary, GatheredErrors};
pub use crate::figures::MotorSummary;
use qmarc_config::{Mode, MotorGains};
use qmarc_controller::fault::Fault;
use qmarc_controller::stats::TimingStats;
/// Where homing found and left one motor (the homing generator's record, as it is).
pub use qmarc_plugins::homing::MotorHome;
use qmarc_proto::state::FaultKind;
use qmarc_timer::Percentiles;
use serde::{Deserialize, Serialize};

/// A fault in `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct FaultReport {
    /// What happened (`"limit_switch"`, `"aborted"`, …).
    pub kind: FaultKind,
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

/// The gains a motor's law ran with (rescaled to the servo period, see
/// [`qmarc_config::Settings::effective_gains`]).
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
    /// Kjff (0: eq. 3-1).
    #[serde(default)]
    pub kjff: f64,
}

impl From<MotorGains> for GainsReport {
    fn from(g: MotorGains) -> GainsReport {
        GainsReport { kp: g.kp, ki: g.ki, kd: g.kd, kvff: g.kvff, kaff: g.kaff, kjff: g.kjff }
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

/// The approach to a path's start (`run --approach`) in `summary.json`: the error figures of
/// the move leave it out; these are its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ApproachSummary {
    /// Samples of the approach (its planned length).
    pub samples: u64,
    /// Cycles of it that ran (fewer if a fault ended it, or missed periods skipped some).
    pub cycles: u64,
    /// Its duration, s.
    pub seconds: f64,
    /// Per motor: where it started, counts (where the motors were).
    pub from_counts: Vec<f64>,
    /// Per motor: the largest |command − actual| during it, counts.
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

/// What a warning is about: tools and tests tell warnings apart by their kind; the user reads
/// the message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WarningKind {
    /// The servo loop did not get what real time needs (SCHED_FIFO, locked memory, a CPU).
    RealTime,
    /// Rows of a stream were not kept: the gather buffer was full.
    GatherDropped,
    /// The path ends moving: its last command was held so that the motors stop.
    EndsMoving,
    /// The gains were tuned at another period and rescaled to this one.
    GainsRescaled,
    /// A motor did not follow its command.
    NotFollowed,
    /// `--unhomed`: the software position limits were off.
    Unhomed,
    /// Motors not homed: the software position limits did not hold for them.
    NotHomed,
    /// The live telemetry did not run, or dropped samples.
    Telemetry,
    /// A stop signal while the data were written: the data files were not written.
    DataNotWritten,
    /// The results could not be written where asked: they are in the rescue folder.
    Rescued,
    /// Figures that are not numbers.
    NotNumbers,
    /// The controller died mid-move: the data files hold the rows it had gathered, from its
    /// gather page, cut short at its last cycle.
    CutShort,
    /// A warning of a `summary.json` written before warnings had kinds (a plain string).
    Unsorted,
}

/// A warning of a run: its kind and what the user reads. It reads as its message (`Deref` to
/// `str`, `Display`). In `summary.json` it is `{"kind": …, "message": …}`; a plain string (a
/// summary written before warnings had kinds) reads as [`WarningKind::Unsorted`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(from = "WarningJson")]
pub struct Warning {
    /// What it is about.
    pub kind: WarningKind,
    /// What the user reads.
    pub message: String,
}

/// A warning as `summary.json` may hold it.
#[derive(Deserialize)]
#[serde(untagged)]
enum WarningJson {
    /// This version's.
    Kinded { kind: WarningKind, message: String },
    /// An older summary's.
    Plain(String),
}

impl From<WarningJson> for Warning {
    fn from(w: WarningJson) -> Warning {
        match w {
            WarningJson::Kinded { kind, message } => Warning { kind, message },
            WarningJson::Plain(message) => Warning { kind: WarningKind::Unsorted, message },
        }
    }
}

impl Warning {
    /// A warning of `kind` saying `message`.
    pub fn new(kind: WarningKind, message: impl Into<String>) -> Warning {
        Warning { kind, message: message.into() }
    }
}

impl std::ops::Deref for Warning {
    type Target = str;
    fn deref(&self) -> &str {
        &self.message
    }
}

impl std::fmt::Display for Warning {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.message)
    }
}

impl PartialEq<&str> for Warning {
    fn eq(&self, other: &&str) -> bool {
        self.message == *other
    }
}

/// Homing's part of `summary.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HomingReport {
    /// Per motor, counts in the frame before homing.
    pub motors: Vec<MotorHome>,
    /// What the hwserver read right after the counters were preset, if it got that far.
    pub after: Option<AfterHoming>,
}

/// The positions and homed flags the hwserver read after homing preset the counters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AfterHoming {
    /// Position per motor, counts (0 at home, give or take how it settled).
    pub positions_counts: Vec<f64>,
    /// Per motor: the frame is homed.
    pub homed: Vec<bool>,
}

/// [`TimingSummary::method`] of a move no timer paced (`--unpaced`): each cycle followed the
/// last at once, so its periods, latencies and misses mean nothing.
pub const UNPACED: &str = "unpaced";

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
    /// Of those, the ones lost in host stalls (a wake at least 1 ms late).
    #[serde(default)]
    pub missed_in_stalls: u64,
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
            missed_in_stalls: t.missed_in_stalls,
            read_us: t.read.percentiles().into(),
            compute_us: t.compute.percentiles().into(),
            output_latency_us: t.output_latency.percentiles().into(),
        }
    }
}

/// `summary.json`: everything about one move.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Summary {
    /// What the move did.
    pub mode: Mode,
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
    /// Per motor, the figures of `motors` over the gathered rows of the path only: the
    /// thesis summed Table 5-2 over data gathered every 4th cycle.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub gathered: Option<GatheredErrors>,
    /// The end-effector error over the gathered rows of the path (command against actual
    /// through the forward kinematics), mm, when `[robot]` describes the robot.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub effector: Option<EffectorSummary>,
    /// The servo period the configured gains were tuned at, µs.
    #[serde(default)]
    pub gains_period_us: u32,
    /// Per motor: the gains the law ran with, rescaled from `gains_period_us` to `period_us`.
    #[serde(default)]
    pub gains: Vec<GainsReport>,
    /// The hold at the end of the path, if it began.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settle: Option<SettleSummary>,
    /// The approach to the path's start before it (`run --approach`), if the move had one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub approach: Option<ApproachSummary>,
    /// Timing figures.
    pub timing: TimingSummary,
    /// Warnings of the run (degraded real time, dropped rows), each with its kind.
    pub warnings: Vec<Warning>,
    /// The pid of the run's `qmarc-starter` (the controller's parent): whose files these are.
    #[serde(default)]
    pub starter_pid: u32,
    /// The files this move wrote (summary.json among them), where they are.
    #[serde(default)]
    pub files: Vec<std::path::PathBuf>,
    /// `home` only: per motor where the top switch was found and cleared and where home is,
    /// and what the hwserver read right after the counters were preset.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub homing: Option<HomingReport>,
    /// `check` only: what each motor did for its voltage, and what to change.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub check: Option<Vec<crate::check::MotorCheck>>,
    /// `conveyor` only: what became of the parts the camera saw (`parts.csv` row by row).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub conveyor: Option<ConveyorSummary>,
    /// A conveyor session in a cell (`--cell`): this robot's share of the cell's parts.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell: Option<CellSummary>,
}

/// A robot's share of its cell's parts (docs/cell.md), as its `parts.csv` has them.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct CellSummary {
    /// The cell's name (`--cell`).
    pub name: String,
    /// This robot's (`[cell] robot`).
    pub robot: String,
    /// Parts this robot picked.
    pub picked: usize,
    /// Parts it saw pass: another robot's, claimed or picked by it or handed on to it.
    pub passed: usize,
    /// Parts it missed: it was the last robot that could reach them.
    pub missed: usize,
}

/// A conveyor session's parts, as `parts.csv` has them.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConveyorSummary {
    /// Parts picked off the belt and placed.
    pub picked: usize,
    /// Parts that left the window unpicked (or could not be reached inside it).
    pub missed: usize,
    /// Parts seen and neither picked nor missed when the session ended.
    pub pending: usize,
    /// Picked parts a minute over the session (its first gathered row to its last).
    pub picks_per_min: f64,
    /// The effector (the forward kinematics of the actual positions) against the part's grip
    /// point, where the belt had carried it, in the cycle the gripper was told to close, mm,
    /// over the picked parts.
    pub grip_error_mm: ErrorFigures,
    /// The same, every cycle from then until the gripper had closed, mm: its largest.
    pub closing_error_max_mm: f64,
    /// Detections the camera sent (a part is seen in several frames).
    pub detections: u64,
    /// A paced session's latencies (none in lock-step, where the camera's clock is the
    /// simulation's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub latency_ms: Option<ConveyorLatency>,
}

/// How fast a part goes from the camera to the command, ms.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ConveyorLatency {
    /// A part's first exposure to the part in the controller's queue (the camera's own
    /// `camera.latency_s` included), over the parts seen.
    pub exposure_to_queue: Latencies,
    /// A part handed to the loop to the tick of the cycle whose command began its intercept,
    /// over the parts handed.
    pub queue_to_command: Latencies,
}

/// Nearest-rank percentiles of some durations, ms (0 for none).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Latencies {
    /// How many.
    pub count: usize,
    /// The median.
    pub p50: f64,
    /// The 99th percentile.
    pub p99: f64,
    /// The largest.
    pub max: f64,
}

impl Latencies {
    /// The percentiles of `ns` (nanoseconds), in ms.
    pub fn of_ns(ns: &[u64]) -> Latencies {
        let mut v = ns.to_vec();
        v.sort_unstable();
        let rank = |q: f64| {
            let k = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len().max(1)) - 1;
            v.get(k).map_or(0.0, |&x| x as f64 * 1e-6)
        };
        Latencies { count: v.len(), p50: rank(0.5), p99: rank(0.99), max: rank(1.0) }
    }
}

/// The largest and the RMS of some errors (0 for none).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct ErrorFigures {
    /// The largest.
    pub max: f64,
    /// The root mean square.
    pub rms: f64,
}

impl ErrorFigures {
    /// The figures of `errors`.
    pub fn of(errors: &[f64]) -> ErrorFigures {
        if errors.is_empty() {
            return ErrorFigures { max: 0.0, rms: 0.0 };
        }
        let max = errors.iter().copied().fold(0.0, f64::max);
        let rms = (errors.iter().map(|e| e * e).sum::<f64>() / errors.len() as f64).sqrt();
        ErrorFigures { max, rms }
    }
}

impl Summary {
    /// Reads `summary.json` in `dir`; the error names the file.
    pub fn read(dir: &std::path::Path) -> Result<Summary, String> {
        let path = dir.join("summary.json");
        let text = std::fs::read(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        serde_json::from_slice(&text).map_err(|e| format!("{}: {e}", path.display()))
    }

    /// The error figures that are not numbers (NaN or infinite: null in `summary.json`), by
    /// name: a move with any is not ok.
    pub fn figures_not_numbers(&self) -> Vec<String> {
        let mut bad = Vec::new();
        let gathered = self.gathered.as_ref().map_or(&[][..], |g| &g.motors[..]);
        for (set, motors) in [("", &self.motors[..]), ("gathered ", gathered)] {
            for (i, m) in motors.iter().enumerate() {
                let figures = [
                    m.min_error_counts,
                    m.max_error_counts,
                    m.accumulated_abs_error_counts,
                    m.sum_squares_error_counts2,
                ];
                if figures.iter().any(|f| !f.is_finite()) {
                    bad.push(format!("{set}motor {}'s error", i + 1));
                }
            }
        }
        if let Some(e) = &self.effector {
            for (axis, a) in [("x", e.x), ("y", e.y), ("z", e.z), ("distance", e.distance)] {
                if [a.min_mm, a.max_mm, a.rms_mm, a.max_abs_mm].iter().any(|f| !f.is_finite()) {
                    bad.push(format!("the end-effector's {axis} error"));
                }
            }
        }
        bad
    }

    /// A move with figures that are not numbers is not ok: says which, in a warning.
    pub fn judge_figures(&mut self) {
        let bad = self.figures_not_numbers();
        if !bad.is_empty() {
            self.ok = false;
            self.warnings.push(Warning::new(
                WarningKind::NotNumbers,
                format!(
                    "figures that are not numbers (null in summary.json): {}; the move is not ok",
                    bad.join(", ")
                ),
            ));
        }
    }

    /// What the move was in words: `step`, `home`, `run (spline)`.
    pub fn what(&self) -> String {
        if self.trajectory.is_empty() || self.trajectory == self.mode.to_string() {
            self.mode.to_string()
        } else {
            format!("{} ({})", self.mode, self.trajectory)
        }
    }

    /// The summary the starter writes when the controller died before writing its own: what
    /// it knows (the motors, the cycles the move reached, why).
    pub fn controller_lost(
        (mode, deterministic): (Mode, bool),
        n_motors: usize,
        period_us: u32,
        cycles: u64,
        message: String,
    ) -> Summary {
        Summary {
            mode,
            trajectory: String::new(),
            ok: false,
            degraded: false,
            deterministic,
            fault: Some(FaultReport {
                kind: FaultKind::ControllerLost,
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
            gathered: None,
            effector: None,
            gains_period_us: 0,
            gains: Vec::new(),
            settle: None,
            approach: None,
            timing: TimingSummary::default(),
            warnings: Vec::new(),
            starter_pid: std::process::id(),
            files: Vec::new(),
            homing: None,
            check: None,
            conveyor: None,
            cell: None,
        }
    }
}

impl From<&Fault> for FaultReport {
    /// The JSON form of a fault, its message in words.
    fn from(f: &Fault) -> FaultReport {
        FaultReport {
            kind: f.kind,
            motor: f.motor.map(|m| m + 1),
            cycle: f.cycle,
            message: f.message(),
            hw_time_ns: (f.hw_time_ns > 0).then_some(f.hw_time_ns),
        }
    }
}

#[cfg(test)]
mod tests;
