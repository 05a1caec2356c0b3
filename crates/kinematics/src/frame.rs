//! [`JointFrame`]: arm angles ⇄ joint counts, and [`Robot`]: a geometry in that frame, so
//! points and counts convert directly.

use crate::{ARMS, Angles, Geometry, KinematicsError, Point};
use serde::{Deserialize, Serialize};

/// The joint-count frame: counts = counts_per_rad · (θ − θ_home), so an arm at its home angle
/// reads 0 (the homed frame).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct JointFrame {
    /// θ_home per arm: the arm angle at which the homed frame reads 0, rad.
    pub home_rad: [f64; ARMS],
    /// Encoder counts per arm radian (counts/rev · gear ratio / 2π).
    pub counts_per_rad: f64,
}

impl JointFrame {
    /// Counts of the arm angles `theta`, not rounded.
    pub fn counts(&self, theta: &Angles) -> [f64; ARMS] {
        std::array::from_fn(|i| self.counts_per_rad * (theta[i] - self.home_rad[i]))
    }

    /// Arm angles of `counts`.
    pub fn angles(&self, counts: &[f64; ARMS]) -> Angles {
        Angles::from_fn(|i, _| self.home_rad[i] + counts[i] / self.counts_per_rad)
    }

    /// Joint velocities in counts/s of arm velocities in rad/s.
    pub fn counts_per_s(&self, theta_dot: &Angles) -> [f64; ARMS] {
        std::array::from_fn(|i| self.counts_per_rad * theta_dot[i])
    }
}

/// A Delta in its joint-count frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Robot {
    /// Its dimensions.
    pub geometry: Geometry,
    /// Its joint-count frame.
    pub frame: JointFrame,
}

impl Robot {
    /// Joint counts (not rounded) that put the effector at `p`.
    pub fn counts_of(&self, p: &Point) -> Result<[f64; ARMS], KinematicsError> {
        Ok(self.frame.counts(&self.geometry.inverse(p)?))
    }

    /// Joint counts (not rounded) that put the effector at x, y, z in mm: [`Robot::mm_of`]
    /// undone.
    pub fn counts_of_mm(&self, mm: [f64; 3]) -> Result<[f64; ARMS], KinematicsError> {
        self.counts_of(&Point::new(mm[0] / 1e3, mm[1] / 1e3, mm[2] / 1e3))
    }

    /// Where the effector is at the joint counts `counts`.
    pub fn point_of(&self, counts: &[f64; ARMS]) -> Result<Point, KinematicsError> {
        self.geometry.forward(&self.frame.angles(counts))
    }

    /// Where the effector is at the joint counts `counts`: x, y, z in mm.
    pub fn mm_of(&self, counts: &[f64; ARMS]) -> Result<[f64; 3], KinematicsError> {
        let p = self.point_of(counts)?;
        Ok([p.x * 1e3, p.y * 1e3, p.z * 1e3])
    }
}
