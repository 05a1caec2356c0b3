//! [`MoveRecord`]: what a finished move leaves, as one plain value. The loop hands it over
//! when the move ends ([`crate::servo::Servo::into_record`]); the report, tuning, the plots
//! and the console read only this, never the live loop.

use crate::fault::Fault;
use crate::gather::Gather;
use crate::stats::{ErrorStats, TimingStats};
use crate::traj::Findings;
use qmarc_proto::MAX_MOTORS;

/// A part of a move apart from its path (the approach before it, the settle after it).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Stretch {
    /// Its samples (the approach: planned; the settle: those held).
    pub samples: u64,
    /// Its cycles that ran.
    pub cycles: u64,
    /// The error figures over it.
    pub errors: ErrorStats,
}

/// What a finished move leaves.
#[derive(Debug, Clone, PartialEq)]
pub struct MoveRecord {
    /// Name of the trajectory generator.
    pub generator: &'static str,
    /// Cycles of the path executed (the error figures' cycles; the approach and the settle
    /// are apart).
    pub cycles: u64,
    /// Samples of the path, if known.
    pub planned_samples: Option<u64>,
    /// The fault that ended the move, if any.
    pub fault: Option<Fault>,
    /// The generator's own explanation of that fault, where it has one (a bad knot in a
    /// stream, why homing failed).
    pub failure: Option<String>,
    /// The error figures of the path.
    pub errors: ErrorStats,
    /// Command − actual of every motor in the last cycle: the error at the end of the settle,
    /// or of the path when there was none.
    pub last_error: [f64; MAX_MOTORS],
    /// Each motor's velocity at the end of the path, counts/s, if the generator knows it.
    pub end_velocity: Option<[f64; MAX_MOTORS]>,
    /// The approach to the path's start, if the move had one.
    pub approach: Option<Stretch>,
    /// The settle at the end of the path, if it began (its error at the end is
    /// `last_error`).
    pub settle: Option<Stretch>,
    /// Tick 0 on the system clock, ns since the Unix epoch: a gathered row's time on the
    /// wall is this plus its `time_s`.
    pub started_wall_ns: u64,
    /// The first sample index of the path (after the approach).
    pub path_from: u64,
    /// The first sample index of the settle, if it began.
    pub settle_from: Option<u64>,
    /// The loop's timing figures.
    pub timing: TimingStats,
    /// Per motor: was its frame homed.
    pub homed: [bool; MAX_MOTORS],
    /// The homed frame homing found, if it did.
    pub homed_frame: Option<[f64; MAX_MOTORS]>,
    /// The generator's own findings (homing's: where it found and left each motor; the
    /// check's: what each motor did), for their section of the report.
    pub findings: Option<Findings>,
    /// Live samples the loop dropped because their ring was full.
    pub telemetry_dropped: u32,
    /// The gathered rows.
    pub gather: Gather,
}

impl MoveRecord {
    /// Whether the gathered row of sample `cycle` belongs to the path (not to the approach
    /// before it nor to the settle after it). By sample index, not by cycles executed: missed
    /// periods skip samples.
    pub fn is_path_sample(&self, cycle: u64) -> bool {
        cycle >= self.path_from && self.settle_from.is_none_or(|from| cycle < from)
    }
}
