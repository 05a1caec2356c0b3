//! `[general]`: motors, servo period, the law and the encoder scale.

use crate::source::{S, Source, one_of, positive};
use crate::{ConfigLoadError, Names};
use qmarc_proto::MAX_MOTORS;
use serde::Deserialize;

/// The `[general]` values (flattened into [`crate::Settings`]).
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct General {
    pub n_motors: usize,
    pub period_us: u32,
    pub gains_period_us: u32,
    pub law: String,
    pub fe_scale: f64,
    pub counts_per_rev: f64,
    pub gear_ratio: f64,
}

impl Default for General {
    fn default() -> General {
        General {
            n_motors: 3,
            period_us: 400,
            gains_period_us: 400,
            law: "pidff".to_string(),
            // Left out, eq. 3-1 as written: a settings file from before the key keeps the
            // loop it was tuned with. The shipped files set 96 (docs/deltabot.md).
            fe_scale: 1.0,
            counts_per_rev: 4096.0,
            gear_ratio: 12.0,
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawGeneral {
    n_motors: S<i64>,
    period_us: S<i64>,
    gains_period_us: S<i64>,
    law: S<String>,
    fe_scale: S<f64>,
    counts_per_rev: S<f64>,
    gear_ratio: S<f64>,
}

/// The servo period's range, µs.
pub(crate) fn check_period(us: i64) -> Result<(), String> {
    if (100..=100_000).contains(&us) {
        Ok(())
    } else {
        Err(format!("servo period must be 100‥100000 µs, found {us}"))
    }
}

impl RawGeneral {
    /// Where `n_motors` is (the file's start when it is not set).
    pub(crate) fn n_motors_span(&self) -> std::ops::Range<usize> {
        crate::source::span_of(&self.n_motors)
    }

    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        names: &Names,
    ) -> Result<General, ConfigLoadError> {
        let d = General::default();
        let period = |v: &S<i64>, field: &str, default: u32| {
            src.take(v, field, i64::from(default), |v| check_period(*v)).map(|v| v as u32)
        };
        Ok(General {
            n_motors: src.int(
                &self.n_motors,
                "general.n_motors",
                d.n_motors as i64,
                1,
                MAX_MOTORS as i64,
            )? as usize,
            period_us: period(&self.period_us, "general.period_us", d.period_us)?,
            gains_period_us: period(
                &self.gains_period_us,
                "general.gains_period_us",
                d.gains_period_us,
            )?,
            law: src.take(
                &self.law,
                "general.law",
                d.law,
                one_of(if names.any_plugin { &[] } else { &names.laws }, "servo law"),
            )?,
            fe_scale: src.take(&self.fe_scale, "general.fe_scale", d.fe_scale, positive)?,
            counts_per_rev: src.take(
                &self.counts_per_rev,
                "general.counts_per_rev",
                d.counts_per_rev,
                positive,
            )?,
            gear_ratio: src.take(&self.gear_ratio, "general.gear_ratio", d.gear_ratio, positive)?,
        })
    }
}
