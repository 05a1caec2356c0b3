//! `[jog]`: moving one motor by hand (`qmarc-starter jog --motor M --counts N`), or the
//! effector along x, y or z (`jog --axis x --mm D`), the console's jog keys; jerk-limited,
//! slowly, a motor with or without a homed frame, the effector in the homed one.

use crate::ConfigLoadError;
use crate::source::{S, Source};
use crate::trajectory::check_speed;
use serde::{Deserialize, Serialize};

/// Largest jog, counts.
pub const MAX_JOG_COUNTS: i64 = 1 << 23;

/// Largest Cartesian jog, mm.
pub const MAX_JOG_MM: f64 = 100.0;

/// The names of the Cartesian axes, as `--axis` takes them.
pub const AXES: [&str; 3] = ["x", "y", "z"];

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
    /// A Cartesian jog: the effector along this axis (0 x, 1 y, 2 z; `--axis`) by `mm`, a
    /// straight line; `None`: the motor's jog.
    #[serde(default)]
    pub axis: Option<usize>,
    /// How far a Cartesian jog goes, mm (`--mm`; the console's keys go this far each way).
    #[serde(default = "default_jog_mm")]
    pub mm: f64,
}

fn default_jog_mm() -> f64 {
    5.0
}

impl Default for JogSettings {
    fn default() -> JogSettings {
        JogSettings {
            motor: 1,
            counts: 100,
            speed: 0.1,
            unhomed_speed: 0.025,
            axis: None,
            mm: default_jog_mm(),
        }
    }
}

/// A Cartesian jog distance within ±[`MAX_JOG_MM`], not 0.
pub(crate) fn check_jog_mm(mm: f64) -> Result<(), String> {
    if mm.is_finite() && mm != 0.0 && mm.abs() <= MAX_JOG_MM {
        Ok(())
    } else {
        Err(format!("a Cartesian jog must be 0‥{MAX_JOG_MM} mm either way, not 0, found {mm}"))
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
    mm: S<f64>,
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
            axis: None,
            mm: src.take(&self.mm, "jog.mm", d.mm, |v| check_jog_mm(*v))?,
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
