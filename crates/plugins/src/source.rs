//! What every generator that reads knots shares: where knots come from ([`KnotSource`]),
//! a precomputed command queue ([`CommandQueue`]) and the memory it may take
//! ([`QUEUE_BUDGET_BYTES`])
//! and why a path cannot be built ([`TrajBuildError`], [`SplineError`]).

use qmarc_config::Settings;
use qmarc_controller::traj::{Sample, TrajStartError, bounds_of};
use qmarc_knots::KnotFileError;
use qmarc_proto::MAX_MOTORS;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};

/// Most memory a generator's command queue may take, bytes (`mlockall` keeps it resident).
pub const QUEUE_BUDGET_BYTES: u64 = 256 << 20;

/// Sample `n` of a command queue computed before the move (the spline's, a jog's): its
/// command into `cmd`, or [`Sample::Done`] past its end.
#[inline]
pub fn sample_queue(queue: &[[f64; MAX_MOTORS]], n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
    match queue.get(n as usize) {
        Some(c) => {
            *cmd = *c;
            Sample::Ready
        }
        None => Sample::Done,
    }
}

/// The [`qmarc_controller::traj::TrajectoryGenerator`] methods of a generator that plays its
/// [`CommandQueue`] field `$queue`: its samples, path bounds and end velocity — and with
/// `sample`, its samples themselves.
macro_rules! follows_queue {
    ($queue:ident) => {
        fn samples(&self) -> Option<u64> {
            self.$queue.samples()
        }

        fn path_bounds(&self) -> Option<[(f64, f64); qmarc_proto::MAX_MOTORS]> {
            self.$queue.bounds()
        }

        fn end_velocity(&self) -> Option<[f64; qmarc_proto::MAX_MOTORS]> {
            self.$queue.end_velocity()
        }
    };
    ($queue:ident, sample) => {
        $crate::source::follows_queue!($queue);

        #[inline]
        fn sample(
            &mut self,
            n: u64,
            cmd: &mut [f64; qmarc_proto::MAX_MOTORS],
        ) -> qmarc_controller::traj::Sample {
            self.$queue.sample(n, cmd)
        }
    };
}
pub(crate) use follows_queue;

/// A command queue computed before the move — the spline's, a jog's, a line's: one command a
/// sample, then the velocity the path ends with. A generator that follows one answers the
/// loop's questions from it: nothing while it is empty (not planned yet).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CommandQueue {
    commands: Vec<[f64; MAX_MOTORS]>,
    end_velocity: [f64; MAX_MOTORS],
}

impl CommandQueue {
    /// `commands`, at rest after the last.
    pub fn at_rest(commands: Vec<[f64; MAX_MOTORS]>) -> CommandQueue {
        CommandQueue { commands, end_velocity: [0.0; MAX_MOTORS] }
    }

    /// `commands`, moving at `end_velocity` (counts/s) after the last.
    pub fn ending_with(
        commands: Vec<[f64; MAX_MOTORS]>,
        end_velocity: [f64; MAX_MOTORS],
    ) -> CommandQueue {
        CommandQueue { commands, end_velocity }
    }

    /// The commands, one a sample.
    pub fn commands(&self) -> &[[f64; MAX_MOTORS]] {
        &self.commands
    }

    /// Its commands, given up.
    pub fn into_commands(self) -> Vec<[f64; MAX_MOTORS]> {
        self.commands
    }

    /// Nothing planned yet.
    pub fn is_empty(&self) -> bool {
        self.commands.is_empty()
    }

    /// [`TrajectoryGenerator::samples`](qmarc_controller::traj::TrajectoryGenerator::samples).
    pub fn samples(&self) -> Option<u64> {
        (!self.is_empty()).then_some(self.commands.len() as u64)
    }

    /// [`TrajectoryGenerator::path_bounds`](qmarc_controller::traj::TrajectoryGenerator::path_bounds).
    pub fn bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        (!self.is_empty()).then(|| bounds_of(&self.commands))
    }

    /// [`TrajectoryGenerator::end_velocity`](qmarc_controller::traj::TrajectoryGenerator::end_velocity).
    pub fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        (!self.is_empty()).then_some(self.end_velocity)
    }

    /// Sample `n`: its command into `cmd`, or [`Sample::Done`] past the end.
    #[inline]
    pub fn sample(&self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        sample_queue(&self.commands, n, cmd)
    }
}

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

/// Bad knots met as the move starts (a stream's): the loop's start error carries them.
pub(crate) fn knots_failed(e: KnotFileError) -> TrajStartError {
    TrajStartError::Generator(Box::new(e))
}

impl From<TrajBuildError> for TrajStartError {
    /// A path read as the move starts (a stream) that cannot be built.
    fn from(e: TrajBuildError) -> Self {
        TrajStartError::Generator(Box::new(e))
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
    Spline(SplineError),
    /// A step larger than a motor's following-error limit: it would fault at its first cycle.
    #[error(
        "a step of {size} counts is more than motor {motor}'s max_following_error_counts = \
         {limit}: the error right after an ideal step is the step, so it would end in a \
         following-error fault at once (give a smaller --size)"
    )]
    StepTooLarge {
        /// 1-based motor.
        motor: usize,
        /// The step, counts.
        size: i64,
        /// Its following-error limit, counts.
        limit: f64,
    },
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
    /// A move's target does not name every motor (`move --to`).
    #[error("the move's target has {positions} positions for {motors} motors")]
    Target {
        /// Positions given.
        positions: usize,
        /// Motors in use.
        motors: usize,
    },
    /// A straight line cannot be built (no `[robot]`, a point out of reach, limits).
    #[error("{0}")]
    Line(String),
    /// The pick cycle cannot be built (no `[robot]`, a point out of reach, limits).
    #[error("{0}")]
    Pick(String),
}

/// The knots cannot carry a spline.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SplineError {
    /// Fewer than two knots.
    #[error("a spline needs at least 2 knots, found {0}")]
    TooFew(usize),
    /// Times and values differ in number.
    #[error("{times} times but {values} values")]
    Mismatch {
        /// Number of times.
        times: usize,
        /// Number of values.
        values: usize,
    },
    /// Times are not finite and strictly increasing.
    #[error("knot times must be finite and strictly increasing (knot {0})")]
    NotIncreasing(usize),
}
