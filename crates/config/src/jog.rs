//! `[jog]`: moving one motor by hand (`qmarc-starter jog --motor M --counts N`, the
//! console's jog keys), jerk-limited, slowly, with or without a homed frame.

use crate::ConfigLoadError;
use crate::source::{S, Source};
use crate::trajectory::check_speed;
use serde::{Deserialize, Serialize};

/// Largest jog, counts.
pub const MAX_JOG_COUNTS: i64 = 1 << 23;

/// A jog.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct JogSettings {
    /// The motor jogged, 1-based (`--motor`).
    pub motor: usize,
    /// How far, counts (`--counts`).
    pub counts: i64,
    /// Its speed in a homed frame: the motor's limits played this much slower (velocity × s,
    /// acceleration × s², jerk × s³).
    pub speed: f64,
    /// Its speed where the frame is not homed (nothing says where the switches are).
    pub unhomed_speed: f64,
}

impl Default for JogSettings {
    fn default() -> JogSettings {
        JogSettings { motor: 1, counts: 100, speed: 0.1, unhomed_speed: 0.025 }
    }
}

/// A jog distance within ±[`MAX_JOG_COUNTS`], not 0.
pub(crate) fn check_jog_counts(counts: i64) -> Result<(), String> {
    if counts != 0 && counts.abs() <= MAX_JOG_COUNTS {
        Ok(())
    } else {
        Err(format!("a jog must be 1‥{MAX_JOG_COUNTS} counts either way, found {counts}"))
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawJog {
    motor: S<i64>,
    counts: S<i64>,
    speed: S<f64>,
    unhomed_speed: S<f64>,
}

impl RawJog {
    /// Checked for `n_motors`.
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        n_motors: usize,
    ) -> Result<JogSettings, ConfigLoadError> {
        let d = JogSettings::default();
        let speed = src.take(&self.speed, "jog.speed", d.speed, check_speed)?;
        Ok(JogSettings {
            motor: src.int(&self.motor, "jog.motor", d.motor as i64, 1, n_motors as i64)? as usize,
            counts: src.take(&self.counts, "jog.counts", d.counts, |v| check_jog_counts(*v))?,
            speed,
            unhomed_speed: src.take(
                &self.unhomed_speed,
                "jog.unhomed_speed",
                d.unhomed_speed,
                |v| {
                    check_speed(v)?;
                    if *v <= speed {
                        Ok(())
                    } else {
                        Err(format!(
                            "must be at most jog.speed = {speed}: an unhomed jog is the slower"
                        ))
                    }
                },
            )?,
        })
    }
}
