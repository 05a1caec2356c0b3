//! What one candidate costs: the path's error figures per motor, whether a step settles, and
//! the [`Evaluator`]s that make the moves — [`SimEvaluator`] in lock-step inside this process,
//! or real moves through the process set (the starter's, on hardware).

use crate::local::{LocalError, run_local};
use qmarc_config::{Mode, MotorGains, RunSpec, Settings};
use qmarc_controller::gather::GatherRow;
use qmarc_proto::DAC_MAX;
use qmarc_report::Summary;
use std::sync::atomic::AtomicBool;

/// What tuning minimises per motor (`--objective`, `tune.objective`).
pub use qmarc_config::TuneObjective as Objective;

/// One gain of a motor that tuning changes.
pub use qmarc_config::TuneParam as Param;

/// The error figures of one motor over the path (thesis Table 5-2), and its DAC saturation.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Figures {
    /// Σ|e|, rad.
    pub abs_rad: f64,
    /// Σe², rad².
    pub sse_rad2: f64,
    /// Largest e, rad.
    pub max_rad: f64,
    /// Smallest e, rad.
    pub min_rad: f64,
    /// Share of the path's gathered cycles with the DAC at its limit.
    pub saturated: f64,
}

impl Figures {
    /// The value of `objective`.
    pub fn objective(&self, objective: Objective) -> f64 {
        match objective {
            Objective::Abs => self.abs_rad,
            Objective::Sse => self.sse_rad2,
            Objective::Max => self.max_rad.max(-self.min_rad),
        }
    }

    /// The figures of motor `m` of `summary`, with its saturated share.
    pub fn of(summary: &Summary, m: usize, saturated: f64) -> Figures {
        let s = &summary.motors[m];
        Figures {
            abs_rad: s.accumulated_abs_error_rad,
            sse_rad2: s.sum_squares_error_rad2,
            max_rad: s.max_error_rad,
            min_rad: s.min_error_rad,
            saturated,
        }
    }
}

/// The share of `dacs` (a motor's DAC codes) at the DAC's limit.
pub fn saturated_share(dacs: impl Iterator<Item = f64>) -> f64 {
    let (mut at, mut all) = (0u64, 0u64);
    for d in dacs {
        all += 1;
        at += u64::from(d.abs() >= f64::from(DAC_MAX));
    }
    if all == 0 { 0.0 } else { at as f64 / all as f64 }
}

/// The path run with one gain set.
#[derive(Debug, Clone, PartialEq)]
pub struct PathRun {
    /// Per motor.
    pub motors: Vec<Figures>,
    /// The fault that ended it, said as the summary says it.
    pub fault: Option<String>,
}

/// A step run with one gain set: per motor the largest |e| over its last fifth, counts.
#[derive(Debug, Clone, PartialEq)]
pub struct StepRun {
    /// Per motor.
    pub residual_counts: Vec<f64>,
    /// The fault that ended it.
    pub fault: Option<String>,
}

/// Tuning could not go on.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum EvalError {
    /// A stop signal (Ctrl-C) or the operator ended it.
    #[error("interrupted")]
    Interrupted,
    /// `tune.max_moves` moves were made.
    #[error("{0} moves made, the most tune.max_moves allows")]
    MoveBudget(u32),
    /// A real move faulted: the robot is no longer where the path starts.
    #[error("a move faulted: {0}")]
    Faulted(String),
    /// A move could not be made.
    #[error("{0}")]
    Move(String),
}

/// Makes the moves that evaluate candidates.
pub trait Evaluator {
    /// Runs the path with `gains` (every motor's).
    fn path(&mut self, gains: &[MotorGains]) -> Result<PathRun, EvalError>;
    /// Runs a step of `step.size` held `tune.step_s` with `gains`; on real moves the step back
    /// follows, made with `safe` (gains known to settle).
    fn step(&mut self, gains: &[MotorGains], safe: &[MotorGains]) -> Result<StepRun, EvalError>;
    /// Moves made so far.
    fn moves(&self) -> u32;
    /// Real moves (hardware, paced): `tune.max_change` bounds each candidate.
    fn real(&self) -> bool;
    /// Allows one move beyond the move budget: the path with the tuned gains, for the
    /// before/after table, once the search is over.
    fn final_move(&mut self) {}
}

/// The largest |cmd − act| of each of `n` motors over the last fifth of `rows`.
pub fn residuals(rows: &[([f64; 4], [f64; 4])], n: usize) -> Vec<f64> {
    let tail = &rows[rows.len() - rows.len() / 5..];
    (0..n).map(|m| tail.iter().map(|(c, a)| (c[m] - a[m]).abs()).fold(0.0, f64::max)).collect()
}

/// The settings of a tuning move: every cycle gathered with its DAC code (saturation is
/// counted on it), `gains` in place of the file's.
pub fn move_settings(base: &Settings, gains: &[MotorGains]) -> Settings {
    let mut s = base.clone();
    s.gather.every = 1;
    s.gather.fields.cmd = true;
    s.gather.fields.act = true;
    s.gather.fields.dac = true;
    s.motors[..gains.len()].copy_from_slice(gains);
    s
}

/// The settings of the stability step: a step of `step.size` held `tune.step_s`.
pub fn step_settings(base: &Settings, gains: &[MotorGains]) -> Settings {
    let mut s = move_settings(base, gains);
    s.step.duration_s = base.tune.step_s;
    s
}

/// Evaluates candidates on the simulated robot in lock-step inside this process
/// ([`run_local`]): a move costs its computing time only.
pub struct SimEvaluator<'a> {
    path: RunSpec,
    step: RunSpec,
    stop: &'a AtomicBool,
    moves: u32,
}

impl<'a> SimEvaluator<'a> {
    /// Evaluates on `spec`'s path (its settings, its knot file); `stop` ends it.
    pub fn new(spec: &RunSpec, stop: &'a AtomicBool) -> SimEvaluator<'a> {
        let step = RunSpec { mode: Mode::Step, ..spec.clone() };
        SimEvaluator { path: spec.clone(), step, stop, moves: 0 }
    }

    /// Runs `spec` with `settings`.
    fn run(
        &mut self,
        which: Mode,
        settings: Settings,
    ) -> Result<crate::local::LocalMove, EvalError> {
        if self.stop.load(std::sync::atomic::Ordering::Relaxed) {
            return Err(EvalError::Interrupted);
        }
        let base = if which == Mode::Step { &self.step } else { &self.path };
        let spec = RunSpec { settings, ..base.clone() };
        self.moves += 1;
        run_local(&spec, self.stop).map_err(|e: LocalError| EvalError::Move(e.to_string()))
    }
}

/// The (cmd, act) of every gathered row.
fn cmd_act(rows: &[GatherRow]) -> Vec<([f64; 4], [f64; 4])> {
    rows.iter().map(|r| (r.cmd, r.act)).collect()
}

/// The fault of `summary` in words.
pub fn fault_of(summary: &Summary) -> Option<String> {
    summary.fault.as_ref().map(|f| f.message.clone())
}

impl Evaluator for SimEvaluator<'_> {
    fn path(&mut self, gains: &[MotorGains]) -> Result<PathRun, EvalError> {
        let settings = move_settings(&self.path.settings, gains);
        let n = settings.n_motors;
        let done = self.run(Mode::Run, settings)?;
        let rows = done.record.gather.rows();
        let path_rows: Vec<&GatherRow> =
            rows.iter().filter(|r| done.record.is_path_sample(r.cycle)).collect();
        let motors = (0..n)
            .map(|m| {
                let sat = saturated_share(path_rows.iter().map(|r| f64::from(r.dac[m])));
                Figures::of(&done.summary, m, sat)
            })
            .collect();
        Ok(PathRun { motors, fault: fault_of(&done.summary) })
    }

    fn step(&mut self, gains: &[MotorGains], _: &[MotorGains]) -> Result<StepRun, EvalError> {
        let settings = step_settings(&self.step.settings, gains);
        let n = settings.n_motors;
        let done = self.run(Mode::Step, settings)?;
        let rows = cmd_act(done.record.gather.rows());
        Ok(StepRun { residual_counts: residuals(&rows, n), fault: fault_of(&done.summary) })
    }

    fn moves(&self) -> u32 {
        self.moves
    }

    fn real(&self) -> bool {
        false
    }
}
