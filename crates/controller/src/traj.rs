//! [`TrajectoryGenerator`]: the trajectory plug-in the loop samples every cycle, and what it
//! answers. The generators themselves (step, spline, PVT, homing) and their registry are in
//! `qmarc-plugins`.

use crate::fault::FaultKind;
use qmarc_proto::{Gripper, MAX_MOTORS, MotorFlags};

/// What a generator says about a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sample {
    /// The command for this sample is in the output.
    Ready,
    /// The path has ended before this sample; the move is over.
    Done,
    /// An online generator has no knot for this sample yet (a fault: the robot cannot wait).
    Starved,
    /// The generator cannot go on (a bad knot in a stream); [`TrajectoryGenerator::report`]
    /// says why, after the move.
    Failed,
}

/// A generator could not start a path.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum TrajStartError {
    /// The path leaves the range positions can take.
    #[error("motor {motor}: the path reaches {value} counts at sample {sample}: {reason}")]
    OutOfRange {
        /// 1-based motor.
        motor: usize,
        /// Sample index.
        sample: u64,
        /// Position, counts.
        value: f64,
        /// What the limit is.
        reason: &'static str,
    },
    /// The path starts away from where the robot is.
    #[error(
        "motor {motor} is at {actual} counts but the path starts at {path} counts, more than the \
         {tolerance}-count start tolerance away: move it there first (`run --approach` does)"
    )]
    FarFromStart {
        /// 1-based motor.
        motor: usize,
        /// Where it is, counts.
        actual: f64,
        /// Where the path starts, counts.
        path: f64,
        /// `trajectory.start_tolerance_counts`.
        tolerance: f64,
    },
    /// The generator's own reason (a stream's bad knots, a path that cannot be built): the
    /// plug-in's typed error, boxed, so the loop needs to know none of them.
    #[error(transparent)]
    Generator(Box<dyn std::error::Error + Send + Sync>),
    /// A stop signal arrived while waiting for a stream's knots.
    #[error("{stream}: interrupted by a stop signal while waiting for the knots")]
    Interrupted {
        /// The stream.
        stream: String,
    },
    /// A stream delivered too few knots in time.
    #[error(
        "{stream}: {got} of the first {needed} knots arrived within {waited_s} s \
         (trajectory.stream_wait_s; is anything writing to it?)"
    )]
    NoKnots {
        /// The stream.
        stream: String,
        /// Knots received.
        got: usize,
        /// Knots needed before the move.
        needed: usize,
        /// How long we waited.
        waited_s: f64,
    },
}

/// Checks that the path's first command is within `tolerance` counts of the robot's position.
pub fn check_start(
    actual: &[f64; MAX_MOTORS],
    first: &[f64; MAX_MOTORS],
    n_motors: usize,
    tolerance: f64,
) -> Result<(), TrajStartError> {
    match (0..n_motors).find(|&m| (actual[m] - first[m]).abs() > tolerance) {
        None => Ok(()),
        Some(m) => Err(TrajStartError::FarFromStart {
            motor: m + 1,
            actual: actual[m],
            path: first[m],
            tolerance,
        }),
    }
}

/// A trajectory generator: the command position of every motor at each servo sample.
///
/// Real-time contract: construction (from validated settings) and [`TrajectoryGenerator::start`]
/// may allocate and fail, and run before any motor is enabled; offline generators compute
/// their whole command queue there. [`TrajectoryGenerator::sample`] runs every cycle, writes
/// into the caller's array and never allocates, locks, does I/O or panics. Paths are absolute
/// positions in counts in the software-counter frame.
pub trait TrajectoryGenerator: Send {
    /// Registered name.
    fn name(&self) -> &'static str;

    /// Prepares the path from the actual positions at the start of the move.
    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError>;

    /// Number of samples of the move (its duration / period + 1), if known after `start`; it
    /// sizes the gather buffer. `None` for a stream of unknown length.
    fn samples(&self) -> Option<u64>;

    /// The command of sample `n` (time n·T from the start) for every motor. The servo calls
    /// it once for sample 0 before the loop, with no feedback observed yet, to seed the law;
    /// generators that act on feedback hold their command until they have observed.
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample;

    /// The fault kind a [`Sample::Failed`] stands for.
    fn failure_kind(&self) -> FaultKind {
        FaultKind::TrajectoryError
    }

    /// Feedback of this cycle, before [`TrajectoryGenerator::sample`]: the actual positions
    /// and each motor's switches, enable and homed flags — and once before
    /// [`TrajectoryGenerator::start`], with the positions the path starts from. Generators that
    /// react to the robot (homing, jog) use it; the default ignores it. Same contract as
    /// `sample`.
    #[inline]
    fn observe(&mut self, act: &[f64; MAX_MOTORS], flags: &[MotorFlags; MAX_MOTORS]) {
        let _ = (act, flags);
    }

    /// Every cycle before [`TrajectoryGenerator::sample`], with the belt encoder's counts of
    /// this cycle's read (a conveyor session's generator follows the parts on the belt with
    /// it; 0 where no belt is read). Same contract as `sample`. The default ignores it.
    #[inline]
    fn belt(&mut self, counts: i64) {
        let _ = counts;
    }

    /// Every cycle after [`TrajectoryGenerator::sample`], with the gripper as this cycle's
    /// read found it ([`Gripper::ABSENT`] when none is wired): whether it should be closed
    /// (`Some(true)`), open (`Some(false)`), or left as it is (`None`, the default). The loop
    /// writes it (message 13) only in a cycle where it differs from the output. Same contract
    /// as `sample`.
    #[inline]
    fn gripper(&mut self, state: Gripper) -> Option<bool> {
        let _ = state;
        None
    }

    /// After `start`: the smallest and largest command of each motor over the whole path,
    /// if known before the move (checked against the software limits); `None` for streams.
    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        None
    }

    /// Where the generator is, as a number for the progress file (homing: which motor and
    /// what it is doing; see `qmarc_plugins::homing::describe_progress`). Same contract as `sample`.
    /// Default: 0.
    #[inline]
    fn progress(&self) -> u32 {
        0
    }

    /// Each motor's velocity at the end of the path, counts/s, once known (after `start` for a
    /// path known before the move, after the move for a stream); `None` if unknown. A path
    /// that ends moving is held at its last command for `trajectory.settle_s`, with a warning.
    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        None
    }

    /// Before [`TrajectoryGenerator::start`]: the command of the path's first sample, where the
    /// generator can say it before the move (a knot file's first knot; a stream's, read for
    /// it), so that an approach can move there first. May read and fail like `start`. Default:
    /// none — the path starts where the robot is.
    fn first_command(&mut self) -> Result<Option<[f64; MAX_MOTORS]>, TrajStartError> {
        Ok(None)
    }

    /// After `start`: the samples at the start of the move that lead to the path (an approach
    /// to its start), which the loop reports apart from the path's error figures. Default: 0.
    fn lead_in(&self) -> u64 {
        0
    }

    /// After the move (never in the loop): what the generator found, in one report — why it
    /// failed, the homed frame a homing defines, and its own findings for the move's report.
    /// Default: nothing.
    fn report(&self) -> GeneratorReport {
        GeneratorReport::default()
    }
}

/// What a generator found in its move, told once it has ended ([`TrajectoryGenerator::report`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct GeneratorReport {
    /// After [`Sample::Failed`]: why, in words (the summary's fault message).
    pub failure: Option<String>,
    /// After a move without a fault: the positions (in the frame of the move) that are to
    /// read 0 from now on, making the frame homed — homing's home positions.
    pub homed_frame: Option<[f64; MAX_MOTORS]>,
    /// The generator's own findings, for the section of `summary.json` it names (homing's
    /// `homing`, the open-loop check's `check`): plain JSON, so that the loop knows no
    /// generator's types.
    pub findings: Option<Findings>,
}

/// A generator's findings: the section of the move's report they fill, and their value.
#[derive(Debug, Clone, PartialEq)]
pub struct Findings {
    /// The section (`"homing"`, `"check"`).
    pub section: &'static str,
    /// What was found, as the generator's type serializes it.
    pub value: serde_json::Value,
}

/// The per-motor bounds of a sequence of commands.
pub fn bounds_of<'a>(
    cmds: impl IntoIterator<Item = &'a [f64; MAX_MOTORS]>,
) -> [(f64, f64); MAX_MOTORS] {
    let mut b = [(f64::INFINITY, f64::NEG_INFINITY); MAX_MOTORS];
    for c in cmds {
        for (bm, &v) in b.iter_mut().zip(c) {
            *bm = (bm.0.min(v), bm.1.max(v));
        }
    }
    b
}
