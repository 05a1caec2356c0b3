//! `move`: an online, jerk-limited move to a target the command line names
//! (`qmarc-starter move --to C1,C2,C3 | --xyz X,Y,Z [--linear] [--speed F]`). Not a table of
//! the settings file: the target is the move's own, checked here before anything starts.

use crate::{ConfigLoadError, Settings};
use serde::{Deserialize, Serialize};

/// Where a move goes.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub enum MoveTarget {
    /// Joint counts, one per motor in use (`--to`).
    Counts(Vec<f64>),
    /// The effector point, mm in the base frame (`--xyz`), and the joint counts that put it
    /// there (through the inverse kinematics, worked out when the target was set).
    Xyz {
        /// The point, mm.
        mm: [f64; 3],
        /// Its joint counts.
        counts: Vec<f64>,
    },
}

/// A move to a target.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MoveSettings {
    /// Where to.
    pub target: MoveTarget,
    /// A straight line in Cartesian space (`--linear`, with `--xyz` only); else each joint's
    /// own jerk-limited profile, time-synchronised.
    pub linear: bool,
    /// The motors' limits played this much slower: velocity × s, acceleration × s², jerk ×
    /// s³ (`--speed`, 0 < s ≤ 1).
    pub speed: f64,
}

impl Default for MoveSettings {
    fn default() -> MoveSettings {
        MoveSettings { target: MoveTarget::Counts(Vec::new()), linear: false, speed: 1.0 }
    }
}

impl MoveTarget {
    /// The target's joint counts.
    pub fn counts(&self) -> &[f64] {
        match self {
            MoveTarget::Counts(c) | MoveTarget::Xyz { counts: c, .. } => c,
        }
    }
}

/// Largest |joint target| of a move, counts: far beyond any arm's travel, small enough that
/// every count is exact in an `f64` command and in the hwserver's 64-bit counters.
pub const MAX_TARGET_COUNTS: f64 = (1u64 << 31) as f64;

fn refused(flag: &'static str, message: String) -> ConfigLoadError {
    ConfigLoadError::Override { flag, message }
}

impl Settings {
    /// Sets the move's target to the joint counts `counts` (`--to`): one finite number per
    /// motor, each within its `[[motor]]` soft limits.
    pub fn set_move_to(&mut self, counts: &[f64]) -> Result<(), ConfigLoadError> {
        if counts.len() != self.n_motors {
            return Err(refused(
                "--to",
                format!(
                    "one position per motor in use: {} numbers, found {}",
                    self.n_motors,
                    counts.len()
                ),
            ));
        }
        self.check_target("--to", counts)?;
        self.motion.target = MoveTarget::Counts(counts.to_vec());
        Ok(())
    }

    /// Sets the move's target to the effector point `mm` (`--xyz`): the `[robot]` table must
    /// describe the robot, the point must be in its workspace and its joint counts within
    /// the soft limits.
    pub fn set_move_xyz(&mut self, mm: [f64; 3]) -> Result<(), ConfigLoadError> {
        let robot = self.robot().ok_or_else(|| {
            refused(
                "--xyz",
                format!(
                    "{} has no [robot] table for {} motors: a point needs the Delta's \
                     geometry and three motors (use --to with joint counts)",
                    self.source.display(),
                    self.n_motors
                ),
            )
        })?;
        if let Some(bad) = mm.iter().find(|v| !v.is_finite()) {
            return Err(refused("--xyz", format!("must be finite numbers, found {bad}")));
        }
        let point = qmarc_kinematics::Point::new(mm[0] / 1e3, mm[1] / 1e3, mm[2] / 1e3);
        let counts = robot.counts_of(&point).map_err(|e| {
            refused(
                "--xyz",
                format!("{:.1}, {:.1}, {:.1} mm is unreachable: {e}", mm[0], mm[1], mm[2]),
            )
        })?;
        self.check_target("--xyz", &counts)?;
        self.motion.target = MoveTarget::Xyz { mm, counts: counts.to_vec() };
        Ok(())
    }

    /// Sets how fast (`--speed`).
    pub fn set_move_speed(&mut self, speed: f64) -> Result<(), ConfigLoadError> {
        crate::trajectory::check_speed(&speed).map_err(|m| refused("--speed", m))?;
        self.motion.speed = speed;
        Ok(())
    }

    /// Makes the move a straight line (`--linear`): its target must be a point.
    pub fn set_move_linear(&mut self) -> Result<(), ConfigLoadError> {
        if !matches!(self.motion.target, MoveTarget::Xyz { .. }) {
            return Err(refused(
                "--linear",
                "a straight line needs a Cartesian target: give it with --xyz".to_string(),
            ));
        }
        self.motion.linear = true;
        Ok(())
    }

    /// Each joint target finite, within ±[`MAX_TARGET_COUNTS`] and its soft limits.
    fn check_target(&self, flag: &'static str, counts: &[f64]) -> Result<(), ConfigLoadError> {
        for (m, (&c, safety)) in counts.iter().zip(&self.safety).enumerate() {
            if !c.is_finite() || c.abs() > MAX_TARGET_COUNTS {
                return Err(refused(
                    flag,
                    format!("motor {}: {c} counts is not a position (±{MAX_TARGET_COUNTS})", m + 1),
                ));
            }
            let [lo, hi] = safety.soft_limits;
            if !(lo..=hi).contains(&c) {
                return Err(refused(
                    flag,
                    format!(
                        "motor {} would go to {c:.1} counts, outside its soft limits \
                         [{lo}, {hi}] (motor.soft_limits in {})",
                        m + 1,
                        self.source.display()
                    ),
                ));
            }
        }
        Ok(())
    }
}
