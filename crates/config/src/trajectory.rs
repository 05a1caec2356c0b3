//! `[trajectory]`: the `run` move (thesis 3.12, A.2.3) and what holds for every path.

use crate::source::{S, Source, non_negative, not_empty, one_of, positive_at_most, within};
use crate::{ConfigLoadError, Names};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// The `run` move.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TrajectorySettings {
    /// Longest move, s: a knot file's path, a stream's, a step (it bounds every count and
    /// allocation that follows from a time).
    pub max_duration_s: f64,
    /// Registered generator that reads knots (`spline`, `pvt`).
    pub method: String,
    /// Knot file; `-` is standard input. `None` until given.
    pub knots: Option<PathBuf>,
    /// The path must start within this many counts of where each motor is.
    pub start_tolerance_counts: f64,
    /// A stream's first knots (a spline stream's whole file) must arrive within this many s.
    pub stream_wait_s: f64,
    /// When a stream runs dry: hold the last command this long, then disable, ms.
    pub starve_hold_ms: f64,
    /// When a path ends (`step` and `run`): hold its last command with the loop closed this
    /// long before disabling, s.
    pub settle_s: f64,
    /// `run` first moves the motors to the path's start (`--approach`): a jerk-limited move
    /// from where they are, reported apart from the path.
    #[serde(default)]
    pub approach: bool,
    /// The approach's speed: the motors' limits played this much slower (0 < s ≤ 1: velocity
    /// × s, acceleration × s², jerk × s³).
    #[serde(default = "default_approach_speed")]
    pub approach_speed: f64,
}

fn default_approach_speed() -> f64 {
    TrajectorySettings::default().approach_speed
}

/// Longest wait for a stream's first knots, s: an hour.
pub const MAX_STREAM_WAIT_S: f64 = 3_600.0;

/// Default longest path, s: 24 h.
pub const DEFAULT_MAX_DURATION_S: f64 = 86_400.0;

impl Default for TrajectorySettings {
    fn default() -> TrajectorySettings {
        TrajectorySettings {
            max_duration_s: DEFAULT_MAX_DURATION_S,
            method: "spline".to_string(),
            knots: None,
            start_tolerance_counts: 100.0,
            stream_wait_s: 10.0,
            starve_hold_ms: 50.0,
            settle_s: 0.2,
            approach: false,
            approach_speed: 0.25,
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawTrajectory {
    method: S<String>,
    knots: S<String>,
    start_tolerance_counts: S<f64>,
    stream_wait_s: S<f64>,
    starve_hold_ms: S<f64>,
    settle_s: S<f64>,
    max_duration_s: S<f64>,
    approach: S<bool>,
    approach_speed: S<f64>,
}

/// A speed fraction: 0 < s ≤ 1.
pub(crate) fn check_speed(v: &f64) -> Result<(), String> {
    if v.is_finite() && *v > 0.0 && *v <= 1.0 {
        Ok(())
    } else {
        Err(format!(
            "must be > 0 and ≤ 1 (a fraction of the motors' limits), found {}",
            crate::num(*v)
        ))
    }
}

impl RawTrajectory {
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        names: &Names,
    ) -> Result<TrajectorySettings, ConfigLoadError> {
        let d = TrajectorySettings::default();
        let knots = src.take(&self.knots, "trajectory.knots", String::new(), not_empty)?;
        Ok(TrajectorySettings {
            max_duration_s: src.take(
                &self.max_duration_s,
                "trajectory.max_duration_s",
                d.max_duration_s,
                |v| {
                    if v.is_finite() && *v > 0.0 && *v <= 1e7 {
                        Ok(())
                    } else {
                        Err(format!("must be > 0 and ≤ 10000000 s, found {}", crate::num(*v)))
                    }
                },
            )?,
            method: src.take(
                &self.method,
                "trajectory.method",
                d.method,
                one_of(if names.any_plugin { &[] } else { &names.methods }, "trajectory method"),
            )?,
            knots: (!knots.is_empty()).then(|| PathBuf::from(knots)),
            start_tolerance_counts: src.take(
                &self.start_tolerance_counts,
                "trajectory.start_tolerance_counts",
                d.start_tolerance_counts,
                non_negative,
            )?,
            stream_wait_s: src.take(
                &self.stream_wait_s,
                "trajectory.stream_wait_s",
                d.stream_wait_s,
                positive_at_most(MAX_STREAM_WAIT_S, "s"),
            )?,
            starve_hold_ms: src.take(
                &self.starve_hold_ms,
                "trajectory.starve_hold_ms",
                d.starve_hold_ms,
                within(0.0, 10_000.0, "ms"),
            )?,
            settle_s: src.take(
                &self.settle_s,
                "trajectory.settle_s",
                d.settle_s,
                within(0.0, 10.0, "s"),
            )?,
            approach: src.take(&self.approach, "trajectory.approach", d.approach, |_| Ok(()))?,
            approach_speed: src.take(
                &self.approach_speed,
                "trajectory.approach_speed",
                d.approach_speed,
                check_speed,
            )?,
        })
    }
}
