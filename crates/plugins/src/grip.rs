//! `move … --grip on|off`: [`GripAtEnd`] closes or opens the gripper at the end of a move's
//! path and holds the path's end until the gripper is there.
//!
//! It wraps the move's generator: the path runs as it is; in the cycle of its last sample the
//! gripper is told (the loop writes message 13 in that cycle); the command then holds the
//! path's end until a read finds the gripper closed (or open), and the move ends. A gripper
//! that is not there within twice its travel time and ten periods fails the move — the
//! robot holds where it is and every motor is disabled, as any failed path ends.

use qmarc_config::Settings;
use qmarc_controller::traj::{GeneratorReport, Sample, TrajStartError, TrajectoryGenerator};
use qmarc_proto::{Gripper, MAX_MOTORS, MotorFlags};

/// The move's generator `inner`, with the gripper closed or opened at its end when the
/// settings' move says so (`move.grip`).
pub fn at_end(s: &Settings, inner: Box<dyn TrajectoryGenerator>) -> Box<dyn TrajectoryGenerator> {
    match s.motion.grip {
        Some(close) => Box::new(GripAtEnd::new(inner, close, s.s626.gripper_close_s, s.period_s())),
        None => inner,
    }
}

/// The path of `move --grip on|off` without a target: one sample, where the robot is.
#[derive(Debug, Default)]
pub struct Here {
    at: [f64; MAX_MOTORS],
}

impl TrajectoryGenerator for Here {
    fn name(&self) -> &'static str {
        "move"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        self.at = *start;
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        Some(1)
    }

    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        Some(self.at.map(|c| (c, c)))
    }

    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        Some([0.0; MAX_MOTORS])
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if n > 0 {
            return Sample::Done;
        }
        *cmd = self.at;
        Sample::Ready
    }
}

/// A move's generator with the gripper closed (or opened) at the path's end.
pub struct GripAtEnd {
    inner: Box<dyn TrajectoryGenerator>,
    close: bool,
    /// Samples of the path (its generator's), known after `start`.
    path: u64,
    /// Samples the gripper is given after the path's last.
    wait: u64,
    /// The path's last command.
    end: [f64; MAX_MOTORS],
    /// The path's last sample has been commanded: the gripper is told.
    told: bool,
    /// A read has found the gripper where it was told to be.
    arrived: bool,
    /// The gripper read absent.
    absent: bool,
    /// The wait ran out.
    late: bool,
    travel_s: f64,
    period_s: f64,
}

impl GripAtEnd {
    /// `inner`, then the gripper closed (`close`) or opened; its jaws travel in `travel_s`
    /// (`s626.gripper_close_s`), the loop runs every `period_s`.
    pub fn new(
        inner: Box<dyn TrajectoryGenerator>,
        close: bool,
        travel_s: f64,
        period_s: f64,
    ) -> GripAtEnd {
        GripAtEnd {
            inner,
            close,
            path: 0,
            wait: (2.0 * travel_s / period_s).ceil() as u64 + 10,
            end: [0.0; MAX_MOTORS],
            told: false,
            arrived: false,
            absent: false,
            late: false,
            travel_s,
            period_s,
        }
    }

    fn word(&self) -> &'static str {
        if self.close { "close" } else { "open" }
    }

    /// Why it failed, in words, after a failed sample.
    pub fn failure(&self) -> Option<String> {
        if self.absent {
            return Some(format!(
                "the move was to {} the gripper, but no gripper is wired (s626.gripper_dio)",
                self.word()
            ));
        }
        if self.late {
            return Some(format!(
                "the gripper did not {} within {:.3} s of the move's end (twice \
                 s626.gripper_close_s = {} s, and ten periods): check its air, its valve and \
                 its wiring",
                self.word(),
                self.wait as f64 * self.period_s,
                self.travel_s
            ));
        }
        self.inner.report().failure
    }
}

impl TrajectoryGenerator for GripAtEnd {
    fn name(&self) -> &'static str {
        self.inner.name()
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        self.inner.start(start)?;
        self.path = self.inner.samples().unwrap_or(0);
        self.end = *start;
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        self.inner.samples().map(|s| s + self.wait)
    }

    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        self.inner.path_bounds()
    }

    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        self.inner.end_velocity()
    }

    #[inline]
    fn observe(&mut self, act: &[f64; MAX_MOTORS], flags: &[MotorFlags; MAX_MOTORS]) {
        self.inner.observe(act, flags);
    }

    #[inline]
    fn progress(&self) -> u32 {
        self.inner.progress()
    }

    fn first_command(&mut self) -> Result<Option<[f64; MAX_MOTORS]>, TrajStartError> {
        self.inner.first_command()
    }

    fn lead_in(&self) -> u64 {
        self.inner.lead_in()
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if n < self.path {
            let s = self.inner.sample(n, cmd);
            if s == Sample::Ready {
                self.end = *cmd;
                self.told |= n + 1 == self.path;
            }
            return s;
        }
        // The path's end held while the gripper travels.
        *cmd = self.end;
        self.told = true;
        if self.absent || (!self.arrived && n >= self.path + self.wait) {
            self.late = !self.absent;
            return Sample::Failed;
        }
        if self.arrived { Sample::Done } else { Sample::Ready }
    }

    #[inline]
    fn gripper(&mut self, state: Gripper) -> Option<bool> {
        if !self.told {
            return self.inner.gripper(state);
        }
        self.absent = state.0 & Gripper::ABSENT != 0;
        self.arrived |= state.reached(self.close);
        Some(self.close)
    }

    fn report(&self) -> GeneratorReport {
        GeneratorReport { failure: self.failure(), ..GeneratorReport::default() }
    }
}

#[cfg(test)]
mod tests;
