//! `[homing]`: how `home` moves (thesis 3.10.1.1).

use crate::ConfigLoadError;
use crate::source::{S, Source, within};
use serde::{Deserialize, Serialize};

/// How homing moves.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct HomingSettings {
    /// Speed toward the top switch and to the home offset, counts/s.
    pub velocity_counts_per_s: f64,
    /// Speed backing off the switch, counts/s.
    pub creep_counts_per_s: f64,
    /// The switch must clear within this many counts of backing off (thesis: 10).
    pub clear_within_counts: f64,
    /// The switch must be found within this travel, counts.
    pub max_travel_counts: f64,
    /// Time each motor rests at home before the next one starts, s.
    pub settle_s: f64,
}

/// Largest homing distance, counts: what the 24-bit counters can measure.
pub const MAX_HOMING_COUNTS: f64 = 8_388_608.0;

impl HomingSettings {
    /// The longest homing of one motor, s, whose home lies `home_offset_counts` from its
    /// switch: away from a switch it starts on and back (twice the travel), off the switch at
    /// the creep speed, to the offset, and the rest at home.
    pub fn longest_s(&self, home_offset_counts: f64) -> f64 {
        (2.0 * self.max_travel_counts + home_offset_counts) / self.velocity_counts_per_s
            + self.clear_within_counts / self.creep_counts_per_s
            + self.settle_s
    }
}

impl Default for HomingSettings {
    fn default() -> HomingSettings {
        HomingSettings {
            velocity_counts_per_s: 2_000.0,
            creep_counts_per_s: 100.0,
            clear_within_counts: 10.0,
            max_travel_counts: 30_000.0,
            settle_s: 0.2,
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawHoming {
    velocity_counts_per_s: S<f64>,
    creep_counts_per_s: S<f64>,
    clear_within_counts: S<f64>,
    max_travel_counts: S<f64>,
    settle_s: S<f64>,
}

impl RawHoming {
    /// Where the homing speed is set (the file's start when it is not).
    pub(crate) fn velocity_span(&self) -> std::ops::Range<usize> {
        crate::source::span_of(&self.velocity_counts_per_s)
    }

    pub(crate) fn check(&self, src: &Source<'_>) -> Result<HomingSettings, ConfigLoadError> {
        let d = HomingSettings::default();
        // Speeds of at least a count per second and distances within the counters' range:
        // homing's duration is bounded (and checked against the longest move with the home
        // offsets, `HomingSettings::longest_s`).
        let speed = |v: &S<f64>, key: &str, default: f64| {
            src.take(v, &format!("homing.{key}"), default, within(1.0, 1e7, "counts/s"))
        };
        let distance = |v: &S<f64>, key: &str, default: f64| {
            src.take(v, &format!("homing.{key}"), default, within(1.0, MAX_HOMING_COUNTS, "counts"))
        };
        Ok(HomingSettings {
            velocity_counts_per_s: speed(
                &self.velocity_counts_per_s,
                "velocity_counts_per_s",
                d.velocity_counts_per_s,
            )?,
            creep_counts_per_s: speed(
                &self.creep_counts_per_s,
                "creep_counts_per_s",
                d.creep_counts_per_s,
            )?,
            clear_within_counts: distance(
                &self.clear_within_counts,
                "clear_within_counts",
                d.clear_within_counts,
            )?,
            max_travel_counts: distance(
                &self.max_travel_counts,
                "max_travel_counts",
                d.max_travel_counts,
            )?,
            settle_s: src.take(
                &self.settle_s,
                "homing.settle_s",
                d.settle_s,
                within(0.0, 10.0, "s"),
            )?,
        })
    }
}
