//! `[check]`: the first motion of a new robot (`qmarc-starter check`): each motor in turn gets
//! a small, short voltage with the loop open while its counter is watched, to see that the
//! amplifier, the motor and the encoder agree in direction and scale before any closed-loop
//! move.

use crate::ConfigLoadError;
use crate::source::{S, Source, positive_at_most, within};
use serde::{Deserialize, Serialize};

/// Most volts `check` may put on a motor: a fifth of the DAC's ±10 V.
pub const MAX_CHECK_VOLTS: f64 = 2.0;

/// Longest pulse of `check`, s.
pub const MAX_CHECK_PULSE_S: f64 = 1.0;

/// The open-loop check.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CheckSettings {
    /// The voltage each motor gets, V (positive: the direction counts should go up).
    pub volts: f64,
    /// How long, s.
    pub pulse_s: f64,
    /// The rest after each pulse, 0 V, before the next motor, s.
    pub rest_s: f64,
    /// A motor that moves further than this from where it started stops the check, counts.
    pub max_travel_counts: f64,
}

impl Default for CheckSettings {
    /// 0.2 V for 0.1 s: about 500 counts (3.8° at the arm) on the thesis' robot at 4×.
    fn default() -> CheckSettings {
        CheckSettings { volts: 0.2, pulse_s: 0.1, rest_s: 0.3, max_travel_counts: 2_000.0 }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCheck {
    volts: S<f64>,
    pulse_s: S<f64>,
    rest_s: S<f64>,
    max_travel_counts: S<f64>,
}

impl RawCheck {
    pub(crate) fn check(&self, src: &Source<'_>) -> Result<CheckSettings, ConfigLoadError> {
        let d = CheckSettings::default();
        Ok(CheckSettings {
            volts: src.take(
                &self.volts,
                "check.volts",
                d.volts,
                positive_at_most(MAX_CHECK_VOLTS, "V"),
            )?,
            pulse_s: src.take(
                &self.pulse_s,
                "check.pulse_s",
                d.pulse_s,
                positive_at_most(MAX_CHECK_PULSE_S, "s"),
            )?,
            rest_s: src.take(&self.rest_s, "check.rest_s", d.rest_s, within(0.0, 5.0, "s"))?,
            max_travel_counts: src.take(
                &self.max_travel_counts,
                "check.max_travel_counts",
                d.max_travel_counts,
                positive_at_most(f64::from(1u32 << 23), "counts"),
            )?,
        })
    }
}
