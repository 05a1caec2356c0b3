//! [`PickCycle`] (`run --method pick`, `[pick]`): the pick-and-place cycle of `qmarc-bench
//! pick` as a path of its own — at the pick point, the gripper's dwell, up `lift_mm`,
//! across `cross_mm` along x, down to the place, the dwell, and back the same way to the
//! pick point. Every leg is [`rest_to_rest`], the time-optimal jerk-limited move that
//! `move --xyz` makes, at `pick.speed` of the motors' limits; so the path asks of the motors
//! what online moves at their limits ask, and `tune run --method pick` tunes the gains for
//! them (a knot file in whole counts could not carry these profiles: its spline would not
//! be the jerk-limited move).

use crate::motion::MotionLimits;
use crate::moveto::rest_to_rest;
use crate::source::{CommandQueue, QUEUE_BUDGET_BYTES, TrajBuildError};
use qmarc_config::{PickSettings, Settings};
use qmarc_controller::traj::{TrajStartError, TrajectoryGenerator, check_start};
use qmarc_kinematics::{ARMS, Robot};
use qmarc_proto::MAX_MOTORS;

/// The cycle's path, sampled once when built.
#[derive(Debug, Clone)]
pub struct PickCycle {
    queue: CommandQueue,
    n_motors: usize,
    start_tolerance: f64,
}

/// The points of the cycle, mm: pick, above it, above the place, the place.
pub fn cycle_points(p: &PickSettings) -> [[f64; 3]; 4] {
    let [x, y, z] = p.at_mm;
    let place = [x + p.cross_mm, y, z];
    let up = |q: [f64; 3]| [q[0], q[1], q[2] + p.lift_mm];
    [p.at_mm, up(p.at_mm), up(place), place]
}

impl PickCycle {
    /// The cycle of `pick` for `robot`, under `limits` (already at the cycle's speed), one
    /// sample every `period_s`.
    pub fn new(
        robot: &Robot,
        pick: &PickSettings,
        limits: &MotionLimits,
        period_s: f64,
    ) -> Result<PickCycle, TrajBuildError> {
        let counts = |mm: [f64; 3]| -> Result<[f64; MAX_MOTORS], TrajBuildError> {
            let c = robot.counts_of_mm(mm).map_err(|e| {
                TrajBuildError::Pick(format!(
                    "[pick]: {:.1}, {:.1}, {:.1} mm is out of reach: {e}",
                    mm[0], mm[1], mm[2]
                ))
            })?;
            let mut q = [0.0; MAX_MOTORS];
            q[..ARMS].copy_from_slice(&c);
            Ok(q)
        };
        let [pick_at, above_pick, above_place, place] = cycle_points(pick).map(counts);
        let (pick_at, above_pick, above_place, place) =
            (pick_at?, above_pick?, above_place?, place?);
        let dwell = (pick.dwell_s / period_s).round() as usize;
        let legs = [
            (pick_at, above_pick),
            (above_pick, above_place),
            (above_place, place),
            (place, above_place),
            (above_place, above_pick),
            (above_pick, pick_at),
        ];
        let mut commands = vec![pick_at; dwell + 1];
        for (i, (from, to)) in legs.into_iter().enumerate() {
            let leg = rest_to_rest(&from, &to, ARMS, limits, period_s)
                .map_err(|e| TrajBuildError::Pick(format!("[pick]: {e}")))?;
            commands.extend_from_slice(&leg[1..]);
            if i == 2 {
                commands.extend(std::iter::repeat_n(place, dwell));
            }
            let bytes = commands.len() * std::mem::size_of::<[f64; MAX_MOTORS]>();
            if bytes as u64 > QUEUE_BUDGET_BYTES {
                return Err(TrajBuildError::Pick(format!(
                    "[pick]: the cycle needs more than {QUEUE_BUDGET_BYTES} bytes of command \
                     queue (a slower speed or a longer dwell than a cycle can be)"
                )));
            }
        }
        Ok(PickCycle {
            queue: CommandQueue::at_rest(commands),
            n_motors: ARMS,
            start_tolerance: 0.0,
        })
    }

    /// The cycle of the settings' `[pick]` and `[robot]`, at `pick.speed` of the motors'
    /// limits.
    pub fn from_settings(s: &Settings) -> Result<PickCycle, TrajBuildError> {
        let robot = s.robot().ok_or_else(|| {
            TrajBuildError::Pick(format!(
                "{} has no [robot] table for 3 motors: the pick cycle needs the Delta's geometry",
                s.source.display()
            ))
        })?;
        let limits = MotionLimits::of(s).at_speed(s.pick.speed);
        let cycle = PickCycle::new(&robot, &s.pick, &limits, s.period_s())?;
        Ok(PickCycle { start_tolerance: s.trajectory.start_tolerance_counts, ..cycle })
    }

    /// Its samples, one per period.
    pub fn commands(&self) -> &[[f64; MAX_MOTORS]] {
        self.queue.commands()
    }
}

impl TrajectoryGenerator for PickCycle {
    fn name(&self) -> &'static str {
        "pick"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        check_start(start, &self.queue.commands()[0], self.n_motors, self.start_tolerance)
    }

    fn first_command(&mut self) -> Result<Option<[f64; MAX_MOTORS]>, TrajStartError> {
        Ok(Some(self.queue.commands()[0]))
    }

    crate::source::follows_queue!(queue, sample);
}

#[cfg(test)]
mod tests;
