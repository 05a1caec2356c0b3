//! [`RealEvaluator`]: each candidate a real move through the process set, paced by the
//! timer — on hardware, or on the simulated robot with `--paced` to rehearse it.
//!
//! The moves themselves are the caller's ([`Mover`]: the starter runs `qmarc-hwserver` and
//! `qmarc-controller` as for any move); this reads what each left in its folder. The path
//! must end where it starts (each evaluation starts where the last ended); a stability step
//! is followed by the step back. At most `tune.max_moves` moves are made, a faulted move
//! ends the tuning (the robot is no longer at the path's start), and a stop signal ends it
//! between moves: the best gains so far are kept.

use crate::eval::{
    EvalError, Evaluator, Figures, PathRun, StepRun, fault_of, move_settings, residuals,
    saturated_share, step_settings,
};
use qmarc_config::{Mode, MotorGains, Settings};
use qmarc_report::Summary;
use qmarc_report::series::Series;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};

/// Makes one move of `mode` with these settings and returns its summary and the folder of
/// its data; `Err` when no move was made (said in words).
pub type Mover<'a> = dyn FnMut(Mode, &Settings) -> Result<(Summary, PathBuf), String> + 'a;

/// Evaluates candidates by real moves.
pub struct RealEvaluator<'a> {
    base: Settings,
    mover: &'a mut Mover<'a>,
    stop: &'a AtomicBool,
    moves: u32,
    /// Moves allowed beyond `tune.max_moves` ([`Evaluator::final_move`]).
    reserve: u32,
}

impl<'a> RealEvaluator<'a> {
    /// Moves with `base` (the path's settings) through `mover`; `stop` ends it between moves.
    pub fn new(base: &Settings, mover: &'a mut Mover<'a>, stop: &'a AtomicBool) -> Self {
        RealEvaluator { base: base.clone(), mover, stop, moves: 0, reserve: 0 }
    }

    /// Refuses when fewer than `n` moves are left of the budget.
    fn budget_for(&self, n: u32) -> Result<(), EvalError> {
        if self.moves + n > self.base.tune.max_moves + self.reserve {
            return Err(EvalError::MoveBudget(self.moves));
        }
        Ok(())
    }

    /// One move, within the move budget and unless stopped.
    fn make(&mut self, mode: Mode, s: &Settings) -> Result<(Summary, Series), EvalError> {
        if self.stop.load(Ordering::Relaxed) {
            return Err(EvalError::Interrupted);
        }
        self.budget_for(1)?;
        self.moves += 1;
        let (summary, dir) = (self.mover)(mode, s).map_err(EvalError::Move)?;
        if summary.fault.as_ref().is_some_and(|f| f.kind == qmarc_proto::state::FaultKind::Aborted)
        {
            return Err(EvalError::Interrupted);
        }
        let series = Series::read(&dir, s.period_s()).map_err(EvalError::Move)?;
        Ok((summary, series))
    }
}

/// The (cmd, act) rows of `series`.
fn cmd_act(series: &Series) -> Vec<([f64; 4], [f64; 4])> {
    (0..series.cycle.len())
        .map(|i| {
            let mut row = ([0.0; 4], [0.0; 4]);
            for m in 0..series.n_motors().min(4) {
                row.0[m] = series.cmd[m][i];
                row.1[m] = series.act[m][i];
            }
            row
        })
        .collect()
}

impl Evaluator for RealEvaluator<'_> {
    fn path(&mut self, gains: &[MotorGains]) -> Result<PathRun, EvalError> {
        let s = move_settings(&self.base, gains);
        let (summary, series) = self.make(Mode::Run, &s)?;
        // The settle's rows come last; the path's are the rest.
        let settle = summary.settle.as_ref().map_or(0, |x| x.cycles) as usize;
        let rows = series.cycle.len().saturating_sub(settle);
        let motors = (0..s.n_motors)
            .map(|m| {
                let dacs = series.dac.get(m).map_or(&[][..], |d| &d[..rows.min(d.len())]);
                Figures::of(&summary, m, saturated_share(dacs.iter().copied()))
            })
            .collect();
        Ok(PathRun { motors, fault: fault_of(&summary) })
    }

    fn step(&mut self, gains: &[MotorGains], safe: &[MotorGains]) -> Result<StepRun, EvalError> {
        // The step and the step back, or neither: the robot ends at the path's start.
        self.budget_for(2)?;
        let s = step_settings(&self.base, gains);
        let (summary, series) = self.make(Mode::Step, &s)?;
        let run = StepRun {
            residual_counts: residuals(&cmd_act(&series), s.n_motors),
            fault: fault_of(&summary),
        };
        if run.fault.is_none() {
            // Back to the path's start, with gains known to settle.
            let mut back = step_settings(&self.base, safe);
            back.step.size = -s.step.size;
            let (summary, _) = self.make(Mode::Step, &back)?;
            if let Some(f) = fault_of(&summary) {
                return Err(EvalError::Faulted(format!("the step back: {f}")));
            }
        }
        Ok(run)
    }

    fn moves(&self) -> u32 {
        self.moves
    }

    fn real(&self) -> bool {
        true
    }

    fn final_move(&mut self) {
        self.reserve = 1;
    }
}
