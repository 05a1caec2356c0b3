//! `[pick]`: the pick-and-place cycle as a path of its own (`run --method pick`, `tune run
//! --method pick`): the motion of `qmarc-bench pick` — grip at the pick point, lift, cross,
//! set down, release, and back — every leg a time-optimal, jerk-limited move at the motors'
//! limits, as `move --xyz` makes it. Online moves at those limits are what a conveyor
//! session asks of the robot, so this is the path to tune its gains on.

use crate::ConfigLoadError;
use crate::source::{S, Source};
use crate::trajectory::check_speed;
use serde::{Deserialize, Serialize};

/// Longest lift or cross of the cycle, mm: beyond any Delta's working space.
pub const MAX_PICK_MM: f64 = 2000.0;

/// Longest dwell at the pick and at the place, s.
pub const MAX_DWELL_S: f64 = 10.0;

/// The pick-and-place cycle.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct PickSettings {
    /// The pick point, mm in the robot's frame (the homed frame's x, y, z).
    pub at_mm: [f64; 3],
    /// The place point is this far along x from the pick point, mm.
    pub cross_mm: f64,
    /// How high the part is lifted above both points, mm.
    pub lift_mm: f64,
    /// A fraction of the motors' limits (velocity × s, acceleration × s², jerk × s³).
    pub speed: f64,
    /// The stand at the pick and at the place while the gripper closes or opens, s.
    pub dwell_s: f64,
}

impl Default for PickSettings {
    /// `qmarc-bench pick`'s cycle: the thesis' X-Z path's ends (5.2.1), 25 mm up, 300 mm
    /// across, 50 ms for the gripper.
    fn default() -> PickSettings {
        PickSettings {
            at_mm: [-150.0, 0.0, -600.0],
            cross_mm: 300.0,
            lift_mm: 25.0,
            speed: 1.0,
            dwell_s: 0.05,
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawPick {
    at_mm: S<Vec<f64>>,
    cross_mm: S<f64>,
    lift_mm: S<f64>,
    speed: S<f64>,
    dwell_s: S<f64>,
}

/// A length of the cycle: finite, within ±[`MAX_PICK_MM`].
fn check_mm(v: &f64) -> Result<(), String> {
    if v.is_finite() && v.abs() <= MAX_PICK_MM {
        Ok(())
    } else {
        Err(format!("must be a length within ±{MAX_PICK_MM} mm, found {v}"))
    }
}

impl RawPick {
    /// Checked (where the points are reachable is the generator's check: it needs the
    /// `[robot]`).
    pub(crate) fn check(&self, src: &Source<'_>) -> Result<PickSettings, ConfigLoadError> {
        let d = PickSettings::default();
        let at = src.read(&self.at_mm, "pick.at_mm", d.at_mm, |v| match v.as_slice() {
            [x, y, z] if [x, y, z].iter().all(|c| c.is_finite()) => Ok([*x, *y, *z]),
            _ => Err(format!("must be a point [x, y, z] in mm, found {v:?}")),
        })?;
        Ok(PickSettings {
            at_mm: at,
            cross_mm: src.take(&self.cross_mm, "pick.cross_mm", d.cross_mm, check_mm)?,
            lift_mm: src.take(&self.lift_mm, "pick.lift_mm", d.lift_mm, check_mm)?,
            speed: src.take(&self.speed, "pick.speed", d.speed, check_speed)?,
            dwell_s: src.take(&self.dwell_s, "pick.dwell_s", d.dwell_s, |v| {
                if v.is_finite() && (0.0..=MAX_DWELL_S).contains(v) {
                    Ok(())
                } else {
                    Err(format!("must be 0‥{MAX_DWELL_S} s, found {v}"))
                }
            })?,
        })
    }
}
