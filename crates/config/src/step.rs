//! `[step]`: the tuning step (thesis 3.4 "Step Motor").

use crate::ConfigLoadError;
use crate::source::{S, Source};
use serde::{Deserialize, Serialize};

/// Largest step, counts.
pub const MAX_STEP_COUNTS: i64 = 1 << 23;

/// The step move.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct StepSettings {
    /// Step size in counts, applied to every motor.
    pub size: i64,
    /// Duration of the move in s.
    pub duration_s: f64,
}

impl Default for StepSettings {
    fn default() -> StepSettings {
        StepSettings { size: 1000, duration_s: 2.0 }
    }
}

/// A step size within ±[`MAX_STEP_COUNTS`].
pub(crate) fn check_step_size(size: i64) -> Result<(), String> {
    if size.abs() <= MAX_STEP_COUNTS {
        Ok(())
    } else {
        Err(format!("step size must be within ±{MAX_STEP_COUNTS} counts, found {size}"))
    }
}

/// A move duration within `max` (`trajectory.max_duration_s`).
pub(crate) fn check_duration(s: f64, max: f64) -> Result<(), String> {
    if s.is_finite() && s > 0.0 && s <= max {
        Ok(())
    } else {
        Err(format!(
            "duration must be > 0 and ≤ {} s (trajectory.max_duration_s), found {}",
            crate::num(max),
            crate::num(s)
        ))
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawStep {
    size: S<i64>,
    duration_s: S<f64>,
}

impl RawStep {
    /// Checked, its duration within `max_duration_s`.
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        max_duration_s: f64,
    ) -> Result<StepSettings, ConfigLoadError> {
        let d = StepSettings::default();
        Ok(StepSettings {
            size: src.take(&self.size, "step.size", d.size, |v| check_step_size(*v))?,
            duration_s: src.take(&self.duration_s, "step.duration_s", d.duration_s, |v| {
                check_duration(*v, max_duration_s)
            })?,
        })
    }
}
