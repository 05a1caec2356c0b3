//! Homing (thesis 3.10.1.1), as a trajectory generator that watches the switches.
//!
//! One motor at a time, the others held where they are: move at a constant velocity toward
//! the top limit switch (starting on it, first move off it, so that the trip is at its edge);
//! when it trips, creep back until it clears — if it is still active `clear_within_counts`
//! (thesis: 10) back from where it tripped, something is wrong (a stuck switch, a broken wire)
//! and homing fails; then move to the home offset (counts from where the switch cleared, away
//! from it) and let it settle. When every motor is home, the move ends and the caller resets
//! every counter so that home reads 0 (`qmarc-controller-process`), which makes the frame homed. The frame
//! comes from where each switch cleared, not from where the motor came to rest, so a sluggish
//! position loop does not shift it.
//!
//! It reads the switches' *current* state from each read's [`MotorFlags`] (the hwserver's
//! latching monitor is off while homing: a homing expects its switch to trip). A switch other
//! than the one being sought fails the homing.

use qmarc_config::{HomingSettings, MotorSafety, Settings};
use qmarc_controller::traj::{
    Findings, GeneratorReport, Sample, TrajStartError, TrajectoryGenerator,
};
use qmarc_proto::state::FaultKind;
use qmarc_proto::{MAX_MOTORS, MotorFlags};

/// The words for a homing progress number ([`TrajectoryGenerator::progress`]):
/// `homing motor 2: backing off the top switch`; `None` for 0.
pub fn describe_progress(detail: u32) -> Option<String> {
    let motor = detail >> 8;
    let what = match detail & 0xff {
        1 => "leaving the top switch it started on",
        2 => "approaching the top switch",
        3 => "backing off the top switch",
        4 => "moving to home",
        5 => "settling at home",
        _ => return None,
    };
    (motor > 0).then(|| format!("homing motor {motor}: {what}"))
}

/// Why homing failed (numbers only: it is decided in the loop).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum HomingFailure {
    /// The top switch was not found within `max_travel_counts`.
    NoSwitch {
        /// 0-based motor.
        motor: usize,
        /// Travel so far, counts.
        travel: f64,
    },
    /// The switch did not clear within `clear_within_counts` back from where it tripped.
    NotCleared {
        /// 0-based motor.
        motor: usize,
        /// Counts backed off.
        backed_off: f64,
    },

    /// Another switch tripped.
    UnexpectedSwitch {
        /// 0-based motor whose switch it is.
        motor: usize,
        /// Its top switch (else bottom).
        top: bool,
        /// 0-based motor being homed.
        homing: usize,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
enum Phase {
    /// Started on the top switch: move away until it clears, then approach it again, so that
    /// the trip is at the switch's edge.
    LeaveSwitch,
    Approach,
    Backoff,
    ToOffset,
    Settle,
    Done,
}

/// The homing generator.
#[derive(Debug, Clone)]
#[doc(alias = "setHomePos")]
#[doc(alias = "homeCtrlLoop")]
pub struct Homing {
    n_motors: usize,
    period_s: f64,
    settings: HomingSettings,
    motors: [MotorSafety; MAX_MOTORS],
    motor: usize,
    phase: Phase,
    /// No sample of the current motor has run yet (one that starts on its top switch leaves
    /// it first).
    fresh: bool,
    cmd: [f64; MAX_MOTORS],
    act: [f64; MAX_MOTORS],
    flags: [MotorFlags; MAX_MOTORS],
    origin: f64,
    /// Where the switch tripped: at most one period's travel past where it was last seen
    /// open (a host stall between the two must not count against the switch).
    trip: f64,
    /// Where the motor being homed was last seen with its top switch open.
    open_seen: f64,
    /// The sample index of the last sample that moved homing on: the next moves it on by as
    /// many periods as went by (missed periods of a host stall too, so the command keeps
    /// pace with time, as the plant did).
    last_n: Option<u64>,
    target: f64,
    settle_left: u64,
    reports: [MotorHome; MAX_MOTORS],
    failure: Option<HomingFailure>,
    /// Feedback has arrived (the servo seeds the law with one `sample` before the loop).
    observed: bool,
    /// Per motor: the switches active since homing began and continuously since (a motor
    /// not yet homed may rest on one; once it clears it must not come back).
    resting: [MotorFlags; MAX_MOTORS],
}

impl Homing {
    /// Homing with the settings' `[homing]` and per-motor offsets and directions.
    pub fn from_settings(s: &Settings) -> Homing {
        let mut motors = [MotorSafety::default(); MAX_MOTORS];
        motors[..s.safety.len()].copy_from_slice(&s.safety);
        Homing::new(s.n_motors, s.period_s(), s.homing, motors)
    }

    /// Homing for `n_motors` at `period_s`.
    pub fn new(
        n_motors: usize,
        period_s: f64,
        settings: HomingSettings,
        motors: [MotorSafety; MAX_MOTORS],
    ) -> Homing {
        Homing {
            n_motors: n_motors.min(MAX_MOTORS),
            period_s,
            settings,
            motors,
            motor: 0,
            phase: Phase::Approach,
            fresh: true,
            cmd: [0.0; MAX_MOTORS],
            act: [0.0; MAX_MOTORS],
            flags: [MotorFlags::default(); MAX_MOTORS],
            origin: 0.0,
            trip: 0.0,
            open_seen: 0.0,
            last_n: None,
            target: 0.0,
            settle_left: 0,
            reports: [MotorHome::default(); MAX_MOTORS],
            failure: None,
            observed: false,
            resting: [MotorFlags::default(); MAX_MOTORS],
        }
    }

    /// The reports of the motors homed so far and of the one being homed.
    pub fn reports(&self) -> &[MotorHome] {
        &self.reports[..(self.motor + 1).min(self.n_motors)]
    }

    fn begin(&mut self, motor: usize) {
        self.motor = motor;
        self.phase = Phase::Approach;
        self.fresh = true;
        self.origin = self.cmd[motor];
        self.open_seen = self.act[motor];
        self.reports[motor] = MotorHome { motor: motor + 1, ..MotorHome::default() };
    }

    /// A switch that must not be active now, of any motor: of a motor already homed; of the
    /// one being homed other than its top switch (its bottom switch is allowed while it moves
    /// away from it), or its top switch after it cleared; of a motor not yet homed, any switch
    /// but one it has rested on since homing began.
    fn unexpected_switch(&self) -> Option<HomingFailure> {
        let m = self.motor;
        for k in 0..self.n_motors {
            let f = self.flags[k];
            let resting = if k > m { self.resting[k] } else { MotorFlags::default() };
            let top_ok = resting.top()
                || (k == m
                    && matches!(self.phase, Phase::LeaveSwitch | Phase::Approach | Phase::Backoff));
            let bottom_ok = resting.bottom() || (k == m && self.phase == Phase::Approach);
            if f.top() && !top_ok {
                return Some(HomingFailure::UnexpectedSwitch { motor: k, top: true, homing: m });
            }
            if f.bottom() && !bottom_ok {
                return Some(HomingFailure::UnexpectedSwitch { motor: k, top: false, homing: m });
            }
        }
        None
    }

    /// `(motor + 1) << 8 | phase + 1`: the motor being homed and its phase.
    fn phase_code(&self) -> u32 {
        ((self.motor as u32 + 1) << 8) + (self.phase as u32 + 1)
    }

    fn fail(&mut self, why: HomingFailure) -> Sample {
        self.failure = Some(why);
        Sample::Failed
    }

    /// One sample of the motor being homed, `periods` after the last: moves its command by
    /// the phase it is in (as far as that many periods take it) and moves on to the next
    /// phase (or motor) when the phase's condition is met.
    fn advance(&mut self, periods: u64) -> Result<(), HomingFailure> {
        let m = self.motor;
        let dir = self.motors[m].top_direction;
        let one = self.settings.velocity_counts_per_s * self.period_s;
        let step = one * periods as f64;
        // Cleared here, not after the sample: `begin` of the next motor runs within a sample.
        let first = std::mem::replace(&mut self.fresh, false);
        match self.phase {
            Phase::LeaveSwitch => self.leave_switch(m, dir, step)?,
            Phase::Approach if first && self.flags[m].top() => {
                self.reports[m].started_on_switch = true;
                self.phase = Phase::LeaveSwitch;
            }
            Phase::Approach => self.approach(m, dir, one, periods)?,
            Phase::Backoff => self.back_off(m, dir, periods)?,
            Phase::ToOffset => {
                let left = self.target - self.cmd[m];
                if left.abs() <= step {
                    self.cmd[m] = self.target;
                    self.phase = Phase::Settle;
                    self.settle_left = (self.settings.settle_s / self.period_s).round() as u64;
                } else {
                    self.cmd[m] += step.copysign(left);
                }
            }
            Phase::Settle => self.settle(m, periods),
            Phase::Done => {}
        }
        Ok(())
    }

    /// Started on the switch: move away from it until it clears.
    fn leave_switch(&mut self, m: usize, dir: f64, step: f64) -> Result<(), HomingFailure> {
        if self.flags[m].top() {
            self.cmd[m] -= dir * step;
            let travel = (self.cmd[m] - self.origin).abs();
            if travel > self.settings.max_travel_counts {
                return Err(HomingFailure::NotCleared { motor: m, backed_off: travel });
            }
        } else {
            self.origin = self.cmd[m];
            self.open_seen = self.act[m];
            self.phase = Phase::Approach;
        }
        Ok(())
    }

    /// Towards the top switch at the homing velocity (`step` a period) until it trips.
    fn approach(
        &mut self,
        m: usize,
        dir: f64,
        step: f64,
        periods: u64,
    ) -> Result<(), HomingFailure> {
        if self.flags[m].top() {
            // Stop where it is and back off from there. The switch tripped somewhere since it
            // was last seen open: a period's travel after that, or here if that is nearer.
            self.reports[m].switch_found_counts = Some(self.act[m]);
            let earliest = self.open_seen + dir * step;
            self.trip = if (self.act[m] - earliest) * dir < 0.0 { self.act[m] } else { earliest };
            self.cmd[m] = self.act[m];
            self.phase = Phase::Backoff;
        } else {
            self.open_seen = self.act[m];
            self.cmd[m] += dir * step * periods as f64;
            let travel = (self.cmd[m] - self.origin).abs();
            if travel > self.settings.max_travel_counts {
                return Err(HomingFailure::NoSwitch { motor: m, travel });
            }
        }
        Ok(())
    }

    /// Off the switch at the creep velocity until it clears: home is the offset from there.
    fn back_off(&mut self, m: usize, dir: f64, periods: u64) -> Result<(), HomingFailure> {
        if !self.flags[m].top() {
            self.reports[m].switch_cleared_counts = Some(self.act[m]);
            self.target = self.act[m] - dir * self.motors[m].home_offset_counts;
            self.reports[m].home_counts = Some(self.target);
            self.phase = Phase::ToOffset;
            // A host stall (periods missed before this sample) can carry the motor past its
            // command (it runs on its last output meanwhile): the move home then starts where
            // the motor is, never pulling it back toward the switch it just cleared.
            if periods > 1 && (self.cmd[m] - self.act[m]) * dir > 0.0 {
                self.cmd[m] = self.act[m];
            }
        } else {
            let backed_off = (self.trip - self.act[m]) * dir;
            if backed_off >= self.settings.clear_within_counts {
                return Err(HomingFailure::NotCleared { motor: m, backed_off });
            }
            self.cmd[m] -= dir * self.settings.creep_counts_per_s * self.period_s * periods as f64;
        }
        Ok(())
    }

    /// Holds home for the settle time (`periods` more of it gone by), then the next motor
    /// (or done).
    fn settle(&mut self, m: usize, periods: u64) {
        if self.settle_left == 0 {
            self.reports[m].ended_counts = Some(self.act[m]);
            self.reports[m].home = true;
            if m + 1 < self.n_motors {
                self.begin(m + 1);
            } else {
                self.motor = self.n_motors;
                self.phase = Phase::Done;
            }
        } else {
            self.settle_left = self.settle_left.saturating_sub(periods);
        }
    }

    /// Why it failed, in words, after a failed sample.
    pub fn failure(&self) -> Option<String> {
        let s = &self.settings;
        self.failure.map(|f| match f {
            HomingFailure::NoSwitch { motor, travel } => format!(
                "homing motor {}: no top switch within {travel:.0} counts (homing.max_travel_counts {})",
                motor + 1,
                s.max_travel_counts
            ),
            HomingFailure::NotCleared { motor, backed_off } => format!(
                "homing motor {}: its top switch was still active {backed_off:.1} counts back from \
                 where it tripped (it must clear within {} counts): a stuck switch or a wiring fault",
                motor + 1,
                s.clear_within_counts
            ),

            HomingFailure::UnexpectedSwitch { motor, top, homing } => format!(
                "homing motor {}: motor {}'s {} limit switch tripped",
                homing + 1,
                motor + 1,
                if top { "top" } else { "bottom" }
            ),
        })
    }
}

impl TrajectoryGenerator for Homing {
    fn name(&self) -> &'static str {
        "home"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        self.cmd = *start;
        self.act = *start;
        self.failure = None;
        self.observed = false;
        self.last_n = None;
        self.begin(0);
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        None
    }

    #[inline]
    fn observe(&mut self, act: &[f64; MAX_MOTORS], flags: &[MotorFlags; MAX_MOTORS]) {
        self.act = *act;
        self.flags = *flags;
        for (r, f) in self.resting.iter_mut().zip(flags) {
            // The first feedback: what each motor rests on; later, only what stays active.
            *r = if self.observed { MotorFlags(r.0 & f.0) } else { *f };
        }
        self.observed = true;
    }

    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if self.failure.is_some() {
            return Sample::Failed;
        }
        if self.phase == Phase::Done {
            return Sample::Done;
        }
        if !self.observed {
            *cmd = self.cmd; // before the loop: hold, nothing seen yet
            return Sample::Ready;
        }
        if let Some(why) = self.unexpected_switch() {
            return self.fail(why);
        }
        let periods = self.last_n.map_or(1, |last| n.saturating_sub(last).max(1));
        self.last_n = Some(n);
        if let Err(why) = self.advance(periods) {
            return self.fail(why);
        }
        *cmd = self.cmd;
        Sample::Ready
    }

    fn failure_kind(&self) -> FaultKind {
        FaultKind::HomingFailed
    }

    /// `(motor + 1) << 8 | phase + 1` while homing, 0 before and after.
    #[inline]
    fn progress(&self) -> u32 {
        if self.phase == Phase::Done || !self.observed {
            return 0;
        }
        self.phase_code()
    }

    /// The homed frame once every motor is home; where each motor's switch and home were
    /// (the report's `homing`).
    fn report(&self) -> GeneratorReport {
        let mut home = [0.0; MAX_MOTORS];
        for (h, r) in home.iter_mut().zip(&self.reports).take(self.n_motors) {
            *h = r.home_counts.unwrap_or(0.0);
        }
        GeneratorReport {
            failure: self.failure(),
            homed_frame: (self.phase == Phase::Done).then_some(home),
            findings: serde_json::to_value(self.reports())
                .ok()
                .map(|value| Findings { section: "homing", value }),
        }
    }
}

/// Where homing found and left one motor, counts in the frame before homing.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MotorHome {
    /// 1-based motor.
    pub motor: usize,
    /// Where the top switch was first seen active (`None`: not reached — the homing ended
    /// before it found the switch).
    pub switch_found_counts: Option<f64>,
    /// Where it cleared while backing off (`None`: not reached).
    pub switch_cleared_counts: Option<f64>,
    /// Home: the home offset from where the switch cleared. It reads 0 afterwards (`None`:
    /// not reached).
    pub home_counts: Option<f64>,
    /// Where the motor stood when the next one started (it reads `ended − home` afterwards;
    /// `None`: it did not get there).
    pub ended_counts: Option<f64>,
    /// The motor was already on its top switch when its homing began.
    pub started_on_switch: bool,
    /// It got home (false: homing failed on this motor).
    pub home: bool,
}

#[cfg(test)]
mod tests;
