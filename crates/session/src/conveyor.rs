//! The conveyor session (`qmarc-starter conveyor`, issue 44): a serving session whose loop
//! picks the parts the camera sees off the moving belt.
//!
//! Two ends, as the serving session has: the dispatcher ([`dispatch::Dispatcher`], a thread
//! of the controller, never the loop's) reads the camera's detections, keeps the part queue
//! ([`qmarc_conveyor::PartQueue`]: the frames of one part merged, each part claimed once,
//! missed parts said) and hands the loop one [`Pick`] at a time; the loop's generator
//! ([`picker::Picker`]) intercepts the part on the belt, moves with it while the gripper
//! closes, places it at `conveyor.place_mm` and says what it did ([`PickEvent`]). The belt is
//! the loop's own: every cycle's read carries its encoder, so the part's place is known to
//! the count in the cycle that commands the motors.

use qmarc_config::Settings;
use qmarc_kinematics::{KinematicsError, Robot};
use qmarc_proto::MAX_MOTORS;

pub mod dispatch;
pub mod picker;
pub mod tracker;

/// A part the loop is to pick: where it lay on the belt when the encoder read
/// `latched_counts`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pick {
    /// The part queue's id.
    pub id: u32,
    /// Along the belt at `latched_counts`, mm.
    pub belt_mm: f64,
    /// Across the belt, mm.
    pub across_mm: f64,
    /// The belt encoder then, counts.
    pub latched_counts: i64,
}

/// What the loop did with a pick, cycle by cycle (the cycle is the gather row's).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PickEvent {
    /// The loop took the pick: its intercept begins with this cycle's command.
    Intercepting {
        /// The part.
        id: u32,
        /// The cycle.
        cycle: u64,
    },
    /// The effector reached the part, moving with it: the gripper is told to close.
    Gripping {
        /// The part.
        id: u32,
        /// The cycle.
        cycle: u64,
    },
    /// The gripper has closed on the part: it is off the belt.
    Lifted {
        /// The part.
        id: u32,
    },
    /// The part is at the place: the gripper is told to open.
    Placed {
        /// The part.
        id: u32,
        /// The cycle.
        cycle: u64,
    },
    /// The pick was given up before the part was off the belt ([`GaveUp`]).
    GaveUp {
        /// The part.
        id: u32,
        /// Why.
        why: GaveUp,
    },
}

/// Why a pick was given up.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GaveUp {
    /// The part left the window before the gripper had closed on it.
    LeftWindow,
    /// The part's point is out of the robot's reach.
    OutOfReach,
    /// No jerk-limited profile to it.
    NoProfile,
    /// The session was told to stop before the part was reached.
    Stopped,
    /// Another robot of the cell has the part (its claim was the earlier), and the gripper
    /// had not been told to close on it.
    Elsewhere,
}

/// The belt in the robot's frame: belt coordinates to points and joint counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BeltFrame {
    /// The belt's travel (a horizontal unit vector), robot frame.
    pub direction: [f64; 3],
    /// Across the belt.
    pub across: [f64; 3],
    /// Belt coordinate 0 on the surface, mm.
    pub origin_mm: [f64; 3],
    /// The encoder, mm per count.
    pub mm_per_count: f64,
    /// A part's grip point above the surface (its top), mm.
    pub grip_up_mm: f64,
    /// The window, belt coordinates, mm.
    pub window_mm: [f64; 2],
    /// The robot.
    pub robot: Robot,
}

impl BeltFrame {
    /// The belt of `s`, if it describes the robot (`[robot]`, three motors).
    pub fn of(s: &Settings) -> Option<BeltFrame> {
        let c = &s.conveyor;
        Some(BeltFrame {
            direction: c.direction,
            across: c.across(),
            origin_mm: c.origin_mm,
            mm_per_count: c.mm_per_count,
            grip_up_mm: s.camera.part_height_mm,
            window_mm: c.window_mm,
            robot: s.robot()?,
        })
    }

    /// Where part `p` is along the belt when the encoder reads `counts`, mm.
    pub fn along(&self, p: &Pick, counts: i64) -> f64 {
        p.belt_mm + (counts - p.latched_counts) as f64 * self.mm_per_count
    }

    /// [`BeltFrame::along`] at the belt's estimated `counts` (not whole: the picker's
    /// [`tracker::BeltTracker`]).
    pub fn along_at(&self, p: &Pick, counts: f64) -> f64 {
        p.belt_mm + (counts - p.latched_counts as f64) * self.mm_per_count
    }

    /// The distance from the effector (the forward kinematics of the motors' `act` counts) to
    /// the grip point of the part seen at `belt_mm` and `across_mm` when the belt read
    /// `latched` counts, with the belt at `conv` counts, mm: `parts.csv`'s `error_mm`.
    pub fn effector_error_mm(
        &self,
        act: [f64; 3],
        conv: f64,
        (belt_mm, across_mm, latched): (f64, f64, f64),
    ) -> Option<f64> {
        let effector = self.robot.mm_of(&act).ok()?;
        let along = belt_mm + (conv - latched) * self.mm_per_count;
        let part = self.grip_point_mm(along, across_mm);
        Some((0..3).map(|i| (effector[i] - part[i]).powi(2)).sum::<f64>().sqrt())
    }

    /// The robot-frame grip point (the part's top centre) of a part `along` the belt and
    /// `across` it, mm.
    pub fn grip_point_mm(&self, along: f64, across: f64) -> [f64; 3] {
        std::array::from_fn(|i| {
            let up = if i == 2 { self.grip_up_mm } else { 0.0 };
            self.origin_mm[i] + along * self.direction[i] + across * self.across[i] + up
        })
    }

    /// The joint counts that put the effector on the grip point of a part `along` the belt
    /// and `across` it. Allocates nothing.
    pub fn counts(&self, along: f64, across: f64) -> Result<[f64; MAX_MOTORS], KinematicsError> {
        self.counts_up(along, across, 0.0)
    }

    /// The joint counts of the point `up_mm` above that grip point.
    pub fn counts_up(
        &self,
        along: f64,
        across: f64,
        up_mm: f64,
    ) -> Result<[f64; MAX_MOTORS], KinematicsError> {
        let mut p = self.grip_point_mm(along, across);
        p[2] += up_mm;
        self.counts_at_mm(p)
    }

    /// The joint counts that put the effector on the robot-frame point `p`, mm (the place,
    /// a point of the belt). Allocates nothing.
    pub fn counts_at_mm(&self, p: [f64; 3]) -> Result<[f64; MAX_MOTORS], KinematicsError> {
        let c = self.robot.counts_of_mm(p)?;
        let mut out = [0.0; MAX_MOTORS];
        out[..c.len()].copy_from_slice(&c);
        Ok(out)
    }
}

#[cfg(test)]
mod tests;
