//! `move`: an online, jerk-limited move to a target the command line names
//! (`qmarc-starter move --to C1,C2,C3 | --xyz X,Y,Z [--linear] [--speed F]`). Not a table of
//! the settings file: the target is the move's own, checked here before anything starts.

use crate::{ConfigLoadError, Settings};
use qmarc_kinematics::mm;
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
    /// The gripper closed (`Some(true)`) or opened at the end of the move (`--grip on|off`);
    /// `None`: left as it is.
    #[serde(default)]
    pub grip: Option<bool>,
}

impl Default for MoveSettings {
    fn default() -> MoveSettings {
        MoveSettings {
            target: MoveTarget::Counts(Vec::new()),
            linear: false,
            speed: 1.0,
            grip: None,
        }
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

/// Why a target is not one to move to.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TargetError {
    /// Not one position per motor in use.
    #[error("one position per motor in use: {motors} numbers, found {found}")]
    Count {
        /// Motors in use.
        motors: usize,
        /// Positions given.
        found: usize,
    },
    /// A number that is not a position.
    #[error(
        "motor {motor}: {value} is not a position (finite, within ±{MAX_TARGET_COUNTS} counts)"
    )]
    NotAPosition {
        /// 1-based motor (or coordinate).
        motor: usize,
        /// The number.
        value: f64,
    },
    /// No `[robot]` table (or not three motors): a point means nothing.
    #[error(
        "{file} has no [robot] table for {motors} motors: a point needs the Delta's geometry \
         and three motors (give joint counts instead)"
    )]
    NoRobot {
        /// The settings file.
        file: String,
        /// Motors in use.
        motors: usize,
    },
    /// The point is out of the arms' reach.
    #[error("{}, {}, {} mm is unreachable: {why}", mm(*x), mm(*y), mm(*z))]
    Unreachable {
        /// The point, mm.
        x: f64,
        /// The point, mm.
        y: f64,
        /// The point, mm.
        z: f64,
        /// The kinematics' reason.
        why: String,
    },
    /// A motor's target is outside its soft limits.
    #[error(
        "motor {motor} would go to {counts:.1} counts, outside its soft limits [{lo}, {hi}] \
         (motor.soft_limits in {file})"
    )]
    SoftLimits {
        /// 1-based motor.
        motor: usize,
        /// Its target, counts.
        counts: f64,
        /// Its soft limits, counts.
        lo: f64,
        /// Its soft limits, counts.
        hi: f64,
        /// The settings file.
        file: String,
    },
}

fn refused(flag: &'static str, message: String) -> ConfigLoadError {
    ConfigLoadError::Override { flag, message }
}

impl Settings {
    /// The joint counts of the effector point `mm`, within the soft limits.
    pub fn counts_of_point(&self, mm: [f64; 3]) -> Result<Vec<f64>, TargetError> {
        let robot = self.robot().ok_or_else(|| TargetError::NoRobot {
            file: self.source.display().to_string(),
            motors: self.n_motors,
        })?;
        if let Some((i, &bad)) = mm.iter().enumerate().find(|(_, v)| !v.is_finite()) {
            return Err(TargetError::NotAPosition { motor: i + 1, value: bad });
        }
        let [x, y, z] = mm;
        let counts = robot.counts_of_mm(mm).map_err(|e| TargetError::Unreachable {
            x,
            y,
            z,
            why: e.to_string(),
        })?;
        self.check_target(&counts)?;
        Ok(counts.to_vec())
    }

    /// `counts` as a target: one finite number per motor in use, each within
    /// ±[`MAX_TARGET_COUNTS`] and its soft limits.
    pub fn check_target(&self, counts: &[f64]) -> Result<(), TargetError> {
        if counts.len() != self.n_motors {
            return Err(TargetError::Count { motors: self.n_motors, found: counts.len() });
        }
        for (m, (&c, safety)) in counts.iter().zip(&self.safety).enumerate() {
            if !c.is_finite() || c.abs() > MAX_TARGET_COUNTS {
                return Err(TargetError::NotAPosition { motor: m + 1, value: c });
            }
            let [lo, hi] = safety.soft_limits;
            if !(lo..=hi).contains(&c) {
                return Err(TargetError::SoftLimits {
                    motor: m + 1,
                    counts: c,
                    lo,
                    hi,
                    file: self.source.display().to_string(),
                });
            }
        }
        Ok(())
    }

    /// Sets the move's target to the joint counts `counts` (`--to`): one finite number per
    /// motor, each within its `[[motor]]` soft limits.
    pub fn set_move_to(&mut self, counts: &[f64]) -> Result<(), ConfigLoadError> {
        self.check_target(counts).map_err(|e| refused("--to", e.to_string()))?;
        self.motion.target = MoveTarget::Counts(counts.to_vec());
        Ok(())
    }

    /// Sets the move's target to the effector point `mm` (`--xyz`): the `[robot]` table must
    /// describe the robot, the point must be in its workspace and its joint counts within
    /// the soft limits.
    pub fn set_move_xyz(&mut self, mm: [f64; 3]) -> Result<(), ConfigLoadError> {
        let counts = self.counts_of_point(mm).map_err(|e| refused("--xyz", e.to_string()))?;
        self.motion.target = MoveTarget::Xyz { mm, counts };
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

    /// Closes (`close`) or opens the gripper at the end of the move (`--grip on|off`): one
    /// must be wired (`s626.gripper_dio`).
    pub fn set_move_grip(&mut self, close: bool) -> Result<(), ConfigLoadError> {
        if self.s626.gripper_dio.is_none() {
            return Err(refused(
                "--grip",
                format!(
                    "no gripper is wired: set [s626] gripper_dio in {} to its output",
                    self.source.display()
                ),
            ));
        }
        self.motion.grip = Some(close);
        Ok(())
    }
}
