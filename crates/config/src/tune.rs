//! `[tune]`: `qmarc-starter tune`, the automatic tuning of the gains on a path: which gains,
//! within which bounds, against which objective, and what a tuned gain set must satisfy.

use crate::ConfigLoadError;
use crate::source::{S, Source, num, positive, within};
use serde::{Deserialize, Serialize};

/// The names of the gains tuning can change ([`TuneParam`]), in the order of
/// [`TuneSettings::bounds`].
pub const TUNE_PARAMS: [&str; 6] = ["kp", "ki", "kd", "kvff", "kaff", "kjff"];

/// One gain of a motor that tuning changes (`tune.params`, `--params`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TuneParam {
    /// Proportional gain.
    Kp,
    /// Integral gain.
    Ki,
    /// Derivative gain.
    Kd,
    /// Velocity feed-forward.
    Kvff,
    /// Acceleration feed-forward.
    Kaff,
    /// Jerk feed-forward (not in eq. 3-1).
    Kjff,
}

impl TuneParam {
    /// Every gain, in the order of [`TUNE_PARAMS`] and [`TuneSettings::bounds`].
    pub const ALL: [TuneParam; 6] = [
        TuneParam::Kp,
        TuneParam::Ki,
        TuneParam::Kd,
        TuneParam::Kvff,
        TuneParam::Kaff,
        TuneParam::Kjff,
    ];

    /// The gains of eq. 3-1 (all but Kjff): what is tuned unless `tune.params` says more.
    pub const EQ_3_1: [TuneParam; 5] =
        [TuneParam::Kp, TuneParam::Ki, TuneParam::Kd, TuneParam::Kvff, TuneParam::Kaff];

    /// The gain named `name`.
    pub fn named(name: &str) -> Option<TuneParam> {
        TuneParam::ALL.into_iter().find(|p| p.name() == name)
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        TUNE_PARAMS[self.index()]
    }

    /// Its index in [`TUNE_PARAMS`] (and `tune.bounds`).
    pub fn index(self) -> usize {
        self as usize
    }

    /// Its value in `g`.
    pub fn get(self, g: &crate::MotorGains) -> f64 {
        [g.kp, g.ki, g.kd, g.kvff, g.kaff, g.kjff][self.index()]
    }

    /// Sets it in `g`.
    pub fn set(self, g: &mut crate::MotorGains, v: f64) {
        *[&mut g.kp, &mut g.ki, &mut g.kd, &mut g.kvff, &mut g.kaff, &mut g.kjff][self.index()] = v;
    }

    /// Whether it is a feedback gain (Kp, Ki, Kd: scaled by the stability margin's step).
    pub fn feedback(self) -> bool {
        matches!(self, TuneParam::Kp | TuneParam::Ki | TuneParam::Kd)
    }
}

/// The names of [`TuneObjective`], in its order.
pub const TUNE_OBJECTIVES: [&str; 3] = ["abs", "sse", "max"];

/// What tuning minimises, per motor, over the path's cycles (thesis 5.2's error figures):
/// `--objective`, `tune.objective`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TuneObjective {
    /// Σ|e| over the path, rad (thesis 5.2: "the sum of absolute position error").
    Abs,
    /// Σe², rad².
    Sse,
    /// max |e|, rad.
    Max,
}

impl TuneObjective {
    /// Every objective, in the order of [`TUNE_OBJECTIVES`].
    pub const ALL: [TuneObjective; 3] =
        [TuneObjective::Abs, TuneObjective::Sse, TuneObjective::Max];

    /// Its name in the settings and on the command line.
    pub fn name(self) -> &'static str {
        TUNE_OBJECTIVES[self as usize]
    }
}

impl std::str::FromStr for TuneObjective {
    type Err = String;
    /// The objective named `v`; any other name is an error naming them all.
    fn from_str(v: &str) -> Result<TuneObjective, String> {
        TuneObjective::ALL.into_iter().find(|o| o.name() == v).ok_or_else(|| {
            format!("unknown objective `{v}`: one of {}", TUNE_OBJECTIVES.join(", "))
        })
    }
}

impl std::fmt::Display for TuneObjective {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// The tuning of the gains.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TuneSettings {
    /// The gains tuned, each once.
    pub params: Vec<TuneParam>,
    /// The objective: `abs` Σ|e|, `sse` Σe², `max` max |e|.
    pub objective: TuneObjective,
    /// Optimiser iterations per motor.
    pub budget: u32,
    /// `[min, max]` of each gain of [`TUNE_PARAMS`], in that order (`kp_bounds` …): no
    /// candidate leaves them.
    pub bounds: [[f64; 2]; 6],
    /// Largest share of the path's cycles a motor's DAC may spend saturated.
    pub max_saturated_fraction: f64,
    /// The stability check: a step of `step.size` held this long, s, must settle.
    pub step_s: f64,
    /// Settled: |error| within this many counts over the step's last fifth.
    pub settle_counts: f64,
    /// The step must also settle with the feedback gains (Kp, Ki, Kd) × this (≥ 1): the
    /// stability margin.
    pub margin: f64,
    /// Real moves (hardware, or `--paced`): no gain of a candidate may differ from the best
    /// gains so far by more than this fraction of them (candidates beyond it are not run).
    pub max_change: f64,
    /// Real moves: the most moves one tuning may make (path, steps and the moves back).
    pub max_moves: u32,
}

impl Default for TuneSettings {
    fn default() -> TuneSettings {
        TuneSettings {
            params: TuneParam::EQ_3_1.to_vec(),
            objective: TuneObjective::Abs,
            budget: 150,
            bounds: [[0.0, 2e6], [0.0, 1e4], [0.0, 1e5], [0.0, 1e6], [0.0, 1e7], [0.0, 2e7]],
            max_saturated_fraction: 0.01,
            step_s: 0.5,
            settle_counts: 5.0,
            margin: 1.2,
            max_change: 0.2,
            max_moves: 300,
        }
    }
}

impl TuneSettings {
    /// The bounds of `param`.
    pub fn bounds_of(&self, param: TuneParam) -> [f64; 2] {
        self.bounds[param.index()]
    }
}

/// The gains of a list of names, each once, out of [`TUNE_PARAMS`].
pub fn check_params(v: &[String]) -> Result<Vec<TuneParam>, String> {
    if v.is_empty() {
        return Err(format!("name at least one of {}", TUNE_PARAMS.join(", ")));
    }
    let mut params = Vec::with_capacity(v.len());
    for (i, p) in v.iter().enumerate() {
        let Some(param) = TuneParam::named(p) else {
            return Err(format!("unknown gain `{p}`: one of {}", TUNE_PARAMS.join(", ")));
        };
        if v[..i].contains(p) {
            return Err(format!("`{p}` is named twice"));
        }
        params.push(param);
    }
    Ok(params)
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTune {
    params: S<Vec<String>>,
    objective: S<String>,
    budget: S<i64>,
    kp_bounds: S<Vec<f64>>,
    ki_bounds: S<Vec<f64>>,
    kd_bounds: S<Vec<f64>>,
    kvff_bounds: S<Vec<f64>>,
    kaff_bounds: S<Vec<f64>>,
    kjff_bounds: S<Vec<f64>>,
    max_saturated_fraction: S<f64>,
    step_s: S<f64>,
    settle_counts: S<f64>,
    margin: S<f64>,
    max_change: S<f64>,
    max_moves: S<i64>,
}

/// `[min, max]` with 0 ≤ min < max, finite.
fn range(v: &Vec<f64>) -> Result<(), String> {
    match v.as_slice() {
        [lo, hi] if lo.is_finite() && hi.is_finite() && 0.0 <= *lo && lo < hi => Ok(()),
        _ => Err(format!("must be [min, max] with 0 ≤ min < max, found {v:?}")),
    }
}

impl RawTune {
    pub(crate) fn check(&self, src: &Source<'_>) -> Result<TuneSettings, ConfigLoadError> {
        let d = TuneSettings::default();
        let mut bounds = d.bounds;
        let raws = [
            &self.kp_bounds,
            &self.ki_bounds,
            &self.kd_bounds,
            &self.kvff_bounds,
            &self.kaff_bounds,
            &self.kjff_bounds,
        ];
        for (i, raw) in raws.iter().enumerate() {
            let field = format!("tune.{}_bounds", TUNE_PARAMS[i]);
            let b = src.take(raw, &field, d.bounds[i].to_vec(), range)?;
            bounds[i] = [b[0], b[1]];
        }
        let fraction = within(0.0, 1.0, "(a share of the cycles)");
        Ok(TuneSettings {
            params: src.read(&self.params, "tune.params", d.params, |v| check_params(v))?,
            objective: src.read(&self.objective, "tune.objective", d.objective, |v| v.parse())?,
            budget: src.int(&self.budget, "tune.budget", d.budget.into(), 1, 100_000)? as u32,
            bounds,
            max_saturated_fraction: src.take(
                &self.max_saturated_fraction,
                "tune.max_saturated_fraction",
                d.max_saturated_fraction,
                fraction,
            )?,
            step_s: src.take(&self.step_s, "tune.step_s", d.step_s, within(0.01, 60.0, "s"))?,
            settle_counts: src.take(
                &self.settle_counts,
                "tune.settle_counts",
                d.settle_counts,
                positive,
            )?,
            margin: src.take(&self.margin, "tune.margin", d.margin, within(1.0, 10.0, "×"))?,
            max_change: src.take(&self.max_change, "tune.max_change", d.max_change, |v| {
                if v.is_finite() && *v > 0.0 && *v <= 1.0 {
                    Ok(())
                } else {
                    Err(format!("must be > 0 and ≤ 1 (a fraction of each gain), found {}", num(*v)))
                }
            })?,
            max_moves: src.int(&self.max_moves, "tune.max_moves", d.max_moves.into(), 1, 100_000)?
                as u32,
        })
    }
}
