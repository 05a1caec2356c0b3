//! [`MovePlan`]: what a move is apart from its path and law — mode, motors, period,
//! gathering, time base, hold and settle times — and the [`MoveLimits`] it is held to.

use qmarc_config::{GatherFields, Mode};
use qmarc_proto::MAX_MOTORS;

/// Samples gathered by default when a generator cannot say how long its path is (a
/// stream): 60 s at 400 µs (`gather.stream_max_s`).
pub const STREAM_GATHER_SAMPLES: u64 = 150_000;

/// The limits a move is held to (thesis 3.10; PMAC Ixx11).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MoveLimits {
    /// Software position limits `(min, max)` per motor, counts; `None`: off (not homed, or
    /// `--unhomed`).
    pub soft: Option<[(f64, f64); MAX_MOTORS]>,
    /// Largest |command − actual| per motor, counts.
    pub max_following_error: [f64; MAX_MOTORS],
    /// Largest |Σ (command − actual)| per motor, counts.
    pub max_integrated_error: [f64; MAX_MOTORS],
    /// Missed periods in a row that end the move.
    pub max_missed_in_row: u64,
}

impl MoveLimits {
    /// No limits at all.
    pub fn none() -> MoveLimits {
        MoveLimits {
            soft: None,
            max_following_error: [f64::INFINITY; MAX_MOTORS],
            max_integrated_error: [f64::INFINITY; MAX_MOTORS],
            max_missed_in_row: u64::MAX,
        }
    }
}

/// What a move is, apart from its path and law.
#[derive(Debug, Clone, PartialEq)]
pub struct MovePlan {
    /// What the move does.
    pub mode: Mode,
    /// Motors driven.
    pub n_motors: usize,
    /// Servo period, ns.
    pub period_ns: u64,
    /// Gather every N cycles.
    pub gather_every: u32,
    /// Which fields the data files carry.
    pub gather_fields: GatherFields,
    /// Simulated time: the sample index is the cycle count and gathered time is n·T.
    pub deterministic: bool,
    /// When the trajectory starves: cycles to hold the last command before disabling.
    pub starve_hold_cycles: u64,
    /// When the path ends: cycles to hold its last command, loop closed, before disabling.
    pub settle_cycles: u64,
    /// Samples the gather buffer holds for a path of unknown length (a stream).
    pub stream_gather_samples: u64,
    /// A path of unknown length keeps its last rows (the buffer a ring: a session that serves
    /// for hours keeps its last `stream_gather_samples`), not its first.
    pub gather_keeps_last: bool,
    /// Limits checked before and during the move.
    pub limits: MoveLimits,
    /// Refuse to move unless every motor's frame is homed.
    pub require_homed: bool,
    /// Latch limit switches in the hwserver (off while homing: homing watches its switch).
    pub monitor_switches: bool,
    /// The gripper's output bit (bit c: DIO channel c, `s626.gripper_dio`); 0: no gripper.
    pub gripper_mask: u32,
    /// The gather page the rows go into (shared memory that outlives the controller,
    /// `qmarc_proto::gather_page`); `None`: the heap.
    pub gather_page: Option<std::path::PathBuf>,
}

impl MovePlan {
    /// A plan for `n_motors` at `period_ns`: gather every cycle, real time, no limits, no
    /// homing required, switches monitored.
    pub fn new(mode: Mode, n_motors: usize, period_ns: u64) -> MovePlan {
        MovePlan {
            mode,
            n_motors,
            period_ns,
            gather_every: 1,
            gather_fields: GatherFields::default(),
            deterministic: false,
            starve_hold_cycles: 0,
            settle_cycles: 0,
            stream_gather_samples: STREAM_GATHER_SAMPLES,
            gather_keeps_last: false,
            limits: MoveLimits::none(),
            require_homed: false,
            monitor_switches: true,
            gripper_mask: 0,
            gather_page: None,
        }
    }
}
