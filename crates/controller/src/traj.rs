//! [`TrajectoryGenerator`]: the trajectory plug-in, and [`Step`], the thesis' default.

use crate::config::Settings;
use crate::knots::KnotFileError;
use crate::summary::FaultKind;
use qmarc_proto::{MAX_MOTORS, MotorFlags};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

/// What a generator says about a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sample {
    /// The command for this sample is in the output.
    Ready,
    /// The path has ended before this sample; the move is over.
    Done,
    /// An online generator has no knot for this sample yet (a fault: the robot cannot wait).
    Starved,
    /// The generator cannot go on (a bad knot in a stream); [`TrajectoryGenerator::failure`]
    /// says why, after the move.
    Failed,
}

/// Most memory a generator's command queue may take, bytes (`mlockall` keeps it resident).
pub const QUEUE_BUDGET_BYTES: u64 = 256 << 20;

/// Where knots come from (`--knots` / `trajectory.knots`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum KnotSource {
    /// A regular file: read and checked completely before anything starts.
    File(PathBuf),
    /// Standard input (`-`): read as the move starts (inherited from the starter).
    Stdin,
    /// A FIFO or other non-regular file: opened and read as the move starts.
    Stream(PathBuf),
}

impl KnotSource {
    /// The source named by `path`: `-` is standard input, a regular file a file, anything
    /// else (a FIFO) a stream. Streams are not opened here.
    pub fn from_path(path: &Path) -> Result<KnotSource, KnotFileError> {
        if path == Path::new("-") {
            if std::io::IsTerminal::is_terminal(&std::io::stdin()) {
                return Err(KnotFileError::Read {
                    file: "-".to_string(),
                    reason: "standard input is a terminal, not a stream of knots: pipe them \
                             in (`qmarc-starter run --knots - < path.txt`, or from a program)"
                        .to_string(),
                });
            }
            return Ok(KnotSource::Stdin);
        }
        let meta = std::fs::metadata(path).map_err(|e| KnotFileError::Read {
            file: path.display().to_string(),
            reason: e.to_string(),
        })?;
        if meta.is_dir() {
            return Err(KnotFileError::Read {
                file: path.display().to_string(),
                reason: "it is a directory".to_string(),
            });
        }
        Ok(if meta.is_file() {
            KnotSource::File(path.to_path_buf())
        } else {
            KnotSource::Stream(path.to_path_buf())
        })
    }

    /// The source of the settings' `trajectory.knots`.
    pub fn from_settings(s: &Settings) -> Result<KnotSource, TrajBuildError> {
        let path = s.trajectory.knots.as_deref().ok_or(TrajBuildError::NoKnots)?;
        Ok(KnotSource::from_path(path)?)
    }

    /// True for sources read only as the move starts.
    pub fn is_stream(&self) -> bool {
        !matches!(self, KnotSource::File(_))
    }

    /// The name errors use: the path, or `-`.
    pub fn name(&self) -> String {
        match self {
            KnotSource::File(p) | KnotSource::Stream(p) => p.display().to_string(),
            KnotSource::Stdin => "-".to_string(),
        }
    }

    /// Opens the source for reading.
    pub fn open(&self) -> Result<(String, Box<dyn BufRead + Send>), KnotFileError> {
        let name = self.name();
        let reader: Box<dyn BufRead + Send> = match self {
            KnotSource::Stdin => Box::new(BufReader::new(std::io::stdin())),
            KnotSource::File(p) | KnotSource::Stream(p) => {
                Box::new(BufReader::new(std::fs::File::open(p).map_err(|e| {
                    KnotFileError::Read { file: name.clone(), reason: e.to_string() }
                })?))
            }
        };
        Ok((name, reader))
    }
}

/// A generator could not be built from the settings.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TrajBuildError {
    /// The method needs knots and none were named.
    #[error("this trajectory needs a knot file: give --knots FILE or set trajectory.knots")]
    NoKnots,
    /// The knot file is bad.
    #[error(transparent)]
    Knots(#[from] KnotFileError),
    /// The knots cannot carry a spline.
    #[error("{0}")]
    Spline(crate::spline::SplineError),
    /// The move is shorter than one servo period.
    #[error("the move lasts {seconds} s, less than one servo period ({period_us} µs)")]
    TooShort {
        /// Duration, s.
        seconds: f64,
        /// The period, µs.
        period_us: u32,
    },
    /// The command queue would not fit its memory budget.
    #[error(
        "the path lasts {seconds} s: its {samples} samples need {bytes} bytes of command queue, \
         more than the {budget}-byte budget (shorten the path or lengthen the period)"
    )]
    Budget {
        /// Duration of the path, s.
        seconds: f64,
        /// Samples.
        samples: u64,
        /// Bytes needed.
        bytes: u64,
        /// [`QUEUE_BUDGET_BYTES`].
        budget: u64,
    },
}

/// A generator could not start a path.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
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
         {tolerance}-count start tolerance away: move it there first"
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
    /// The knots read at the start are bad.
    #[error(transparent)]
    Knots(#[from] KnotFileError),
    /// The path read at the start cannot be built.
    #[error(transparent)]
    Build(#[from] TrajBuildError),
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

    /// After [`Sample::Failed`]: why, for the summary. Not called in the loop.
    fn failure(&self) -> Option<String> {
        None
    }

    /// The fault kind a [`Sample::Failed`] stands for.
    fn failure_kind(&self) -> FaultKind {
        FaultKind::TrajectoryError
    }

    /// Feedback of this cycle, before [`TrajectoryGenerator::sample`]: the actual positions
    /// and each motor's switches, enable and homed flags. Generators that react to the robot
    /// (homing) use it; the default ignores it. Same contract as `sample`.
    #[inline]
    fn observe(&mut self, act: &[f64; MAX_MOTORS], flags: &[MotorFlags; MAX_MOTORS]) {
        let _ = (act, flags);
    }

    /// After `start`: the smallest and largest command of each motor over the whole path,
    /// if known before the move (checked against the software limits); `None` for streams.
    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        None
    }

    /// Where the generator is, as a number for the progress file (homing: which motor and
    /// what it is doing; see [`crate::homing::describe_progress`]). Same contract as `sample`.
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

    /// After a move without a fault: the positions (in the frame of the move) that are to read
    /// 0 from now on, making the frame homed — homing's home positions. Default: none.
    fn homed_frame(&self) -> Option<[f64; MAX_MOTORS]> {
        None
    }

    /// After the move: what this generator has to say in `summary.json` (homing reports where
    /// it found the switches). Not called in the loop.
    fn summary(&self) -> Option<serde_json::Value> {
        None
    }
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

/// An ideal step of `size` counts on every motor, held for `duration` (thesis 3.8.1.1.4, the
/// base class' default path): sample 0 is the start position, every later sample the start
/// plus `size`.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    size: f64,
    last_sample: u64,
    n_motors: usize,
    start: [f64; MAX_MOTORS],
}

impl Step {
    /// A step of `size_counts` lasting `duration_s` at period `period_s`, for `n_motors`.
    pub fn new(size_counts: i64, duration_s: f64, period_s: f64, n_motors: usize) -> Step {
        Step {
            size: size_counts as f64,
            last_sample: (duration_s / period_s).round() as u64,
            n_motors: n_motors.min(MAX_MOTORS),
            start: [0.0; MAX_MOTORS],
        }
    }

    /// The step of the settings' `[step]` section; it must last at least one servo period.
    pub fn from_settings(s: &Settings) -> Result<Step, TrajBuildError> {
        if s.step.duration_s < s.period_s() {
            return Err(TrajBuildError::TooShort {
                seconds: s.step.duration_s,
                period_us: s.period_us,
            });
        }
        Ok(Step::new(s.step.size, s.step.duration_s, s.period_s(), s.n_motors))
    }
}

impl TrajectoryGenerator for Step {
    fn name(&self) -> &'static str {
        "step"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        for (m, &p) in start.iter().enumerate().take(self.n_motors) {
            let target = p + self.size;
            if !target.is_finite() || target.abs() >= 9.0e15 {
                return Err(TrajStartError::OutOfRange {
                    motor: m + 1,
                    sample: 1,
                    value: target,
                    reason: "beyond the exact range of the 64-bit software counter",
                });
            }
        }
        self.start = *start;
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        Some(self.last_sample + 1)
    }

    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        let target = self.start.map(|s| s + self.size);
        Some(bounds_of([&self.start, &target]))
    }

    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        Some([0.0; MAX_MOTORS])
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if n > self.last_sample {
            return Sample::Done;
        }
        let offset = if n == 0 { 0.0 } else { self.size };
        for (m, (c, start)) in cmd.iter_mut().zip(&self.start).enumerate() {
            *c = if m < self.n_motors { start + offset } else { 0.0 };
        }
        Sample::Ready
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_holds_start_then_target_for_duration_over_period_plus_one_samples() {
        let mut s = Step::new(1000, 0.002, 0.0004, 2);
        assert_eq!(s.samples(), Some(6));
        s.start(&[10.0, -5.0, 99.0, 99.0]).unwrap();
        let mut cmd = [0.0; MAX_MOTORS];
        assert_eq!(s.sample(0, &mut cmd), Sample::Ready);
        assert_eq!(cmd, [10.0, -5.0, 0.0, 0.0]);
        for n in 1..=5 {
            assert_eq!(s.sample(n, &mut cmd), Sample::Ready);
            assert_eq!(cmd, [1010.0, 995.0, 0.0, 0.0]);
        }
        assert_eq!(s.sample(6, &mut cmd), Sample::Done);
    }

    #[test]
    fn step_refuses_targets_beyond_the_counter() {
        let mut s = Step::new(1 << 23, 1.0, 0.0004, 1);
        let e = s.start(&[9.0e15, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(e.to_string().starts_with("motor 1: the path reaches"), "{e}");
    }
}
