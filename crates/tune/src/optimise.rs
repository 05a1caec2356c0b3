//! [`tune`]: per motor, argmin's Nelder–Mead over the chosen gains, each candidate a move.
//!
//! The motors are tuned one after the other, each against its own objective; every move runs
//! all motors, the others with their best gains so far. On the simulated robot the motors are
//! independent (no coupling is simulated), so this is the joint optimum; on a real Deltabot the
//! arms load each other a little and motor by motor is a coordinate-wise search.
//!
//! A candidate is feasible when its gains are within `tune` bounds, its path does not fault,
//! its DAC saturates on at most `tune.max_saturated_fraction` of the path's cycles and — for
//! a candidate that would be the best so far — a step settles with its gains and with its
//! feedback gains × `tune.margin`. An infeasible candidate costs more than any feasible one,
//! so the simplex leaves it. On real moves a candidate whose gains differ from the best ones
//! by more than `tune.max_change` is not run at all.

use crate::eval::{EvalError, Evaluator, Objective, Param, PathRun};
use argmin::core::{CostFunction, Executor};
use argmin::solver::neldermead::NelderMead;
use qmarc_config::{MotorGains, TuneSettings};
use std::cell::RefCell;

/// Why a candidate was not accepted.
#[derive(Debug, Clone, PartialEq)]
pub enum Verdict {
    /// Feasible; `best`: the best so far when it was run.
    Feasible {
        /// Whether it became the best.
        best: bool,
    },
    /// A gain outside `tune` bounds, or one the settings would refuse (not run).
    OutOfBounds,
    /// Beyond `tune.max_change` of the best gains on real moves (not run).
    TooFar,
    /// The path faulted.
    Fault(String),
    /// The DAC saturated on this share of the path's cycles.
    Saturates(f64),
    /// The stability step did not settle (the residual, counts; with the margin or not).
    Unsettled {
        /// Largest |e| over the step's last fifth, counts.
        residual: f64,
        /// With the feedback gains × `tune.margin`.
        margin: bool,
    },
}

impl Verdict {
    /// A word for tune.csv.
    pub fn word(&self) -> String {
        match self {
            Verdict::Feasible { best: true } => "best".into(),
            Verdict::Feasible { best: false } => "feasible".into(),
            Verdict::OutOfBounds => "out-of-bounds".into(),
            Verdict::TooFar => "beyond-max-change".into(),
            Verdict::Fault(_) => "fault".into(),
            Verdict::Saturates(f) => format!("saturates-{:.1}%", f * 100.0),
            Verdict::Unsettled { margin: false, .. } => "step-unsettled".into(),
            Verdict::Unsettled { margin: true, .. } => "margin-step-unsettled".into(),
        }
    }
}

/// One candidate evaluated.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// The motor tuned (0-based).
    pub motor: usize,
    /// Its evaluation number for this motor, from 1.
    pub evaluation: u32,
    /// The candidate gains of the motor.
    pub gains: MotorGains,
    /// The objective (`None` when not run or faulted).
    pub objective: Option<f64>,
    /// The best feasible objective so far for this motor.
    pub best: f64,
    /// What became of it.
    pub verdict: Verdict,
    /// Moves made so far in all.
    pub moves: u32,
}

/// What a tuning found.
#[derive(Debug, Clone)]
pub struct Tuned {
    /// The gains before.
    pub before: Vec<MotorGains>,
    /// The best feasible gains found (the gains before for a motor where none was better).
    pub after: Vec<MotorGains>,
    /// The path with the gains before.
    pub before_run: PathRun,
    /// Every candidate, in order.
    pub records: Vec<Record>,
    /// Why it ended early, if it did: the gains in `after` are the last safe ones.
    pub aborted: Option<EvalError>,
}

/// The state every cost evaluation shares.
struct Search<'a> {
    eval: &'a mut dyn Evaluator,
    tune: &'a TuneSettings,
    law: (f64, (u32, u32)),
    objective: Objective,
    params: &'a [Param],
    /// Per parameter: x = gain / scale.
    scale: Vec<f64>,
    best: Vec<MotorGains>,
    best_value: Vec<f64>,
    /// Costs of infeasible candidates: above every feasible one.
    penalty: f64,
    records: Vec<Record>,
    on_record: &'a mut dyn FnMut(&Record),
    aborted: Option<EvalError>,
    /// Evaluations of this motor so far.
    calls: u32,
    /// Evaluations of this Nelder–Mead round (its first simplex is unwrapped by the solver).
    round_calls: u32,
}

impl<'a> Search<'a> {
    /// A search of `plan` from the gains `best`, nothing feasible known yet; an infeasible
    /// candidate costs `penalty`.
    fn new(
        plan: &Plan<'a>,
        best: &[MotorGains],
        eval: &'a mut dyn Evaluator,
        on_record: &'a mut dyn FnMut(&Record),
        penalty: f64,
    ) -> Search<'a> {
        Search {
            eval,
            tune: plan.tune,
            law: plan.law,
            objective: plan.objective,
            params: plan.params,
            scale: Vec::new(),
            best: best.to_vec(),
            best_value: vec![f64::INFINITY; best.len()],
            penalty,
            records: Vec::new(),
            on_record,
            aborted: None,
            calls: 0,
            round_calls: 0,
        }
    }

    /// The gains of `motor` at `x`.
    fn gains_at(&self, motor: usize, x: &[f64]) -> MotorGains {
        let mut g = self.best[motor];
        for ((p, xi), s) in self.params.iter().zip(x).zip(&self.scale) {
            p.set(&mut g, xi * s);
        }
        g
    }

    /// How far `g` is outside the bounds (0 inside), in spans of the bounds.
    fn outside(&self, g: &MotorGains) -> f64 {
        self.params
            .iter()
            .map(|p| {
                let [lo, hi] = self.tune.bounds[p.index()];
                let v = p.get(g);
                ((lo - v).max(0.0) + (v - hi).max(0.0)) / (hi - lo)
            })
            .sum()
    }

    /// Whether `g` is beyond `tune.max_change` of the best gains of `motor`.
    fn too_far(&self, motor: usize, g: &MotorGains) -> bool {
        self.params.iter().any(|p| {
            let [lo, hi] = self.tune.bounds[p.index()];
            let best = p.get(&self.best[motor]);
            let room = self.tune.max_change * scale_of(best, [lo, hi]);
            (p.get(g) - best).abs() > room * (1.0 + 1e-9)
        })
    }

    /// The cost of `x` for `motor`, recorded. `Err` only once an evaluation failed, and only
    /// where the solver can take it (not in its first simplex, which it unwraps).
    fn cost(&mut self, motor: usize, x: &[f64]) -> Result<f64, EvalError> {
        self.calls += 1;
        self.round_calls += 1;
        if self.aborted.is_some() {
            return if self.round_calls > self.params.len() as u32 + 1 {
                Err(EvalError::Interrupted)
            } else {
                Ok(self.penalty)
            };
        }
        let g = self.gains_at(motor, x);
        let (objective, verdict) = match self.judge(motor, &g) {
            Ok(v) => v,
            Err(e) => {
                self.aborted = Some(e);
                return Ok(self.penalty);
            }
        };
        let cost = match (&verdict, objective) {
            (Verdict::Feasible { .. }, Some(v)) => v,
            (Verdict::OutOfBounds, _) => self.penalty * (1.0 + self.outside(&g)),
            _ => self.penalty,
        };
        let record = Record {
            motor,
            evaluation: self.calls,
            gains: g,
            objective,
            best: self.best_value[motor],
            verdict,
            moves: self.eval.moves(),
        };
        (self.on_record)(&record);
        self.records.push(record);
        Ok(cost)
    }

    /// Runs candidate `g` of `motor` as far as needed to judge it.
    fn judge(&mut self, motor: usize, g: &MotorGains) -> Result<(Option<f64>, Verdict), EvalError> {
        let (fe_scale, periods) = self.law;
        if self.outside(g) > 0.0
            || qmarc_config::effective_gains_problem(g, fe_scale, periods).is_some()
        {
            return Ok((None, Verdict::OutOfBounds));
        }
        if self.eval.real() && self.too_far(motor, g) {
            return Ok((None, Verdict::TooFar));
        }
        let mut all = self.best.clone();
        all[motor] = *g;
        let run = self.eval.path(&all)?;
        if let Some(f) = run.fault {
            if self.eval.real() {
                return Err(EvalError::Faulted(f));
            }
            return Ok((None, Verdict::Fault(f)));
        }
        let fig = run.motors[motor];
        let value = fig.objective(self.objective);
        if !value.is_finite() {
            return Ok((None, Verdict::Fault(format!("objective {value}"))));
        }
        if fig.saturated > self.tune.max_saturated_fraction {
            return Ok((Some(value), Verdict::Saturates(fig.saturated)));
        }
        if value >= self.best_value[motor] {
            return Ok((Some(value), Verdict::Feasible { best: false }));
        }
        if let Some(unsettled) = self.unsettled(motor, &all)? {
            return Ok((Some(value), unsettled));
        }
        self.best[motor] = *g;
        self.best_value[motor] = value;
        Ok((Some(value), Verdict::Feasible { best: true }))
    }

    /// The stability check of `motor` with gains `all`: a step settles, and settles again
    /// with the feedback gains × the margin.
    fn unsettled(
        &mut self,
        motor: usize,
        all: &[MotorGains],
    ) -> Result<Option<Verdict>, EvalError> {
        for margin in [false, true] {
            if margin && self.tune.margin <= 1.0 {
                break;
            }
            let mut gains = all.to_vec();
            if margin {
                for p in [Param::Kp, Param::Ki, Param::Kd] {
                    let [lo, hi] = self.tune.bounds[p.index()];
                    p.set(&mut gains[motor], (p.get(&all[motor]) * self.tune.margin).clamp(lo, hi));
                }
            }
            let step = self.eval.step(&gains, &self.best)?;
            if let Some(f) = step.fault {
                if self.eval.real() {
                    return Err(EvalError::Faulted(f));
                }
                return Ok(Some(Verdict::Unsettled { residual: f64::INFINITY, margin }));
            }
            let residual = step.residual_counts[motor];
            if residual > self.tune.settle_counts {
                return Ok(Some(Verdict::Unsettled { residual, margin }));
            }
        }
        Ok(None)
    }
}

/// The unit a gain is searched in, and the unit of `tune.max_change`: the gain itself, or 5 %
/// of its bounds' span for a gain near zero (a change relative to zero means nothing).
pub fn scale_of(gain: f64, [lo, hi]: [f64; 2]) -> f64 {
    gain.abs().max(0.05 * (hi - lo))
}

/// argmin's view of one motor's search.
struct MotorProblem<'s, 'a> {
    search: &'s RefCell<Search<'a>>,
    motor: usize,
}

impl CostFunction for MotorProblem<'_, '_> {
    type Param = Vec<f64>;
    type Output = f64;
    fn cost(&self, x: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok(self.search.borrow_mut().cost(self.motor, x)?)
    }
}

/// What to tune and how.
pub struct Plan<'a> {
    /// `[tune]` of the settings.
    pub tune: &'a TuneSettings,
    /// The gains changed.
    pub params: &'a [Param],
    /// What is minimised.
    pub objective: Objective,
    /// Optimiser iterations per motor.
    pub budget: u32,
    /// `general.fe_scale`, and the period the gains are tuned at and the one the law runs
    /// at: a candidate eq. 3-1 could not servo with (`effective_gains_problem`) is not run.
    pub law: (f64, (u32, u32)),
}

/// How [`tune`] judges the gains `all` as a candidate for `motor` when nothing feasible is
/// known yet (what the search does with each candidate, for checking the constraints):
/// its objective and verdict. On real moves, `best` are the gains the candidate may not
/// stray `tune.max_change` from.
pub fn judge(
    plan: &Plan<'_>,
    best: &[MotorGains],
    motor: usize,
    candidate: &MotorGains,
    eval: &mut dyn Evaluator,
) -> Result<(Option<f64>, Verdict), EvalError> {
    let mut ignore = |_: &Record| {};
    Search::new(plan, best, eval, &mut ignore, 0.0).judge(motor, candidate)
}

/// Tunes every motor of `before` in turn on `eval`'s path; `on_record` sees each candidate.
pub fn tune(
    plan: &Plan<'_>,
    before: &[MotorGains],
    eval: &mut dyn Evaluator,
    on_record: &mut dyn FnMut(&Record),
) -> Result<Tuned, EvalError> {
    let before_run = eval.path(before)?;
    if let Some(f) = &before_run.fault {
        return Err(if eval.real() {
            EvalError::Faulted(format!("the path with the gains before: {f}"))
        } else {
            EvalError::Move(format!(
                "the path faults with the gains before: {f}; make it run first (tuning starts from them)"
            ))
        });
    }
    let n = before.len();
    let worst = before_run.motors.iter().map(|f| f.objective(plan.objective)).fold(0.0, f64::max);
    let search = RefCell::new(Search::new(plan, before, eval, on_record, 1e3 * (1.0 + worst)));
    for motor in 0..n {
        if search.borrow().aborted.is_some() {
            break;
        }
        search_motor(&search, motor, plan)?;
    }
    let s = search.into_inner();
    Ok(Tuned {
        before: before.to_vec(),
        after: s.best,
        before_run,
        records: s.records,
        aborted: s.aborted,
    })
}

/// Nelder–Mead over `plan.params` of `motor`, from its gains before, restarted from the
/// best point with a fresh simplex whenever it converges (a converged simplex has often
/// only collapsed), a smaller one after a round that found nothing better, until
/// `plan.budget` iterations are spent.
fn search_motor(
    search: &RefCell<Search<'_>>,
    motor: usize,
    plan: &Plan<'_>,
) -> Result<(), EvalError> {
    {
        let mut s = search.borrow_mut();
        s.calls = 0;
        s.scale = plan
            .params
            .iter()
            .map(|p| scale_of(p.get(&s.best[motor]), plan.tune.bounds[p.index()]))
            .collect();
    }
    // On real moves the simplex stays within half the allowed change.
    let mut step = if search.borrow().eval.real() { 0.5 * plan.tune.max_change } else { 0.25 };
    let mut left = u64::from(plan.budget);
    while left > 0 && step > 1e-3 && search.borrow().aborted.is_none() {
        let before = search.borrow().best_value[motor];
        left = left.saturating_sub(simplex_round(search, motor, step, left)?.max(1));
        if search.borrow().best_value[motor] >= before * (1.0 - 1e-6) {
            step *= 0.5;
        }
    }
    Ok(())
}

/// One Nelder–Mead run of at most `iters` iterations from the best gains of `motor`, the
/// simplex `step` (scaled units) wide; returns the iterations it took.
fn simplex_round(
    search: &RefCell<Search<'_>>,
    motor: usize,
    step: f64,
    iters: u64,
) -> Result<u64, EvalError> {
    let x0: Vec<f64> = {
        let s = search.borrow();
        s.params.iter().zip(&s.scale).map(|(p, sc)| p.get(&s.best[motor]) / sc).collect()
    };
    let mut simplex = vec![x0.clone()];
    for i in 0..x0.len() {
        let mut v = x0.clone();
        v[i] += step;
        simplex.push(v);
    }
    let solver = NelderMead::new(simplex)
        .with_sd_tolerance(1e-9)
        .map_err(|e| EvalError::Move(format!("Nelder–Mead: {e}")))?;
    let problem = MotorProblem { search, motor };
    search.borrow_mut().round_calls = 0;
    let result = Executor::new(problem, solver).configure(|state| state.max_iters(iters)).run();
    match result {
        Ok(r) => Ok(r.state.iter),
        // An evaluation that failed ends the search with the best gains so far (kept in
        // `search`); any other solver error is a defect worth saying.
        Err(_) if search.borrow().aborted.is_some() => Ok(iters),
        Err(e) => Err(EvalError::Move(format!("Nelder–Mead: {e}"))),
    }
}
