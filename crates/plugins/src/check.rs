//! The open-loop first motion (`qmarc-starter check`): each motor in turn gets `[check] volts`
//! for `pulse_s`, then rests at 0 V for `rest_s`, while its counter is watched — does a
//! positive command count up, by about what the feed-forward expects, and does no other
//! motor move? — before any closed-loop move trusts the signs.
//!
//! Two plug-ins share one [`Schedule`]: [`Check`], the generator, whose command is where each
//! motor is (the loop's error checks see nothing to correct) and which watches the travel;
//! [`OpenLoop`], the law, which outputs the scheduled voltage and nothing else. The loop's
//! other guards stay on: a limit switch, the emergency stop, the watchdog end it at once.

use qmarc_config::Settings;
use qmarc_controller::law::{ServoInput, ServoLaw};
use qmarc_controller::traj::{
    Findings, GeneratorReport, Sample, TrajStartError, TrajectoryGenerator,
};
use qmarc_proto::state::FaultKind;
use qmarc_proto::{DAC_FULL_SCALE_V, DAC_MAX, MAX_MOTORS, MotorFlags};

/// When each motor is driven: one slot per motor, a pulse at its start and a rest after it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Schedule {
    /// Motors checked, in turn.
    pub n_motors: usize,
    /// Samples of a pulse.
    pub pulse: u64,
    /// Samples of a slot (pulse and rest).
    pub slot: u64,
    /// The pulse's DAC code.
    pub code: i32,
    /// The pulse's volts (the code's).
    pub volts: f64,
    /// The servo period, s.
    pub period_s: f64,
}

impl Schedule {
    /// The schedule of the settings' `[check]`.
    pub fn from_settings(s: &Settings) -> Schedule {
        let period = s.period_s();
        let pulse = ((s.check.pulse_s / period).round() as u64).max(1);
        // At least one read after the pulse: the one that shows its whole move.
        let rest = ((s.check.rest_s / period).round() as u64).max(1);
        let code = (s.check.volts / DAC_FULL_SCALE_V * f64::from(DAC_MAX)).round() as i32;
        Schedule {
            n_motors: s.n_motors,
            pulse,
            slot: pulse + rest,
            code,
            volts: f64::from(code) * DAC_FULL_SCALE_V / f64::from(DAC_MAX),
            period_s: period,
        }
    }

    /// The motor driven at sample `n` (samples 1 ‥ pulse of its slot), if any.
    #[inline]
    pub fn driven(&self, n: u64) -> Option<usize> {
        let k = n.checked_sub(1)?;
        let motor = (k / self.slot) as usize;
        (motor < self.n_motors && k % self.slot < self.pulse).then_some(motor)
    }

    /// Samples of the whole check: sample 0, then a slot per motor.
    pub fn samples(&self) -> u64 {
        1 + self.n_motors as u64 * self.slot
    }
}

/// The check's generator: the command is where each motor is; it records how each moved in
/// its slot and stops the check when one goes further than `[check] max_travel_counts`.
#[derive(Debug, Clone)]
pub struct Check {
    schedule: Schedule,
    max_travel: f64,
    start: [f64; MAX_MOTORS],
    act: [f64; MAX_MOTORS],
    /// Where every motor was when the current slot began.
    slot_start: [f64; MAX_MOTORS],
    /// The motor whose slot's start is booked.
    slot: Option<usize>,
    /// Its pulse's move is booked whole.
    pulse_booked: bool,
    reports: [MotorCheckReport; MAX_MOTORS],
    /// The motor that went too far, and how far.
    too_far: Option<(usize, f64)>,
}

impl Check {
    /// The check of the settings' `[check]`.
    pub fn from_settings(s: &Settings) -> Check {
        Check::new(Schedule::from_settings(s), s.check.max_travel_counts)
    }

    /// The check of `schedule`, stopped beyond `max_travel` counts.
    pub fn new(schedule: Schedule, max_travel: f64) -> Check {
        Check {
            schedule,
            max_travel,
            start: [0.0; MAX_MOTORS],
            act: [0.0; MAX_MOTORS],
            slot_start: [0.0; MAX_MOTORS],
            slot: None,
            pulse_booked: false,
            reports: [MotorCheckReport::default(); MAX_MOTORS],
            too_far: None,
        }
    }

    /// Books sample `n`'s positions into the motor whose slot it is. A read shows what the
    /// outputs up to the sample before did: the first read of a slot is before its pulse (it
    /// is where the slot starts), the first read at or after the pulse's end shows its whole
    /// move, the reads after it the coasting. By the first read seen of each, not by exact
    /// sample numbers: a missed period moves a boundary by one sample, never loses it.
    #[inline]
    fn book(&mut self, n: u64) {
        let s = self.schedule;
        let Some(k) = n.checked_sub(1) else { return };
        let motor = (k / s.slot) as usize;
        if motor >= s.n_motors {
            return;
        }
        if self.slot != Some(motor) {
            self.slot = Some(motor);
            self.slot_start = self.act;
            self.pulse_booked = false;
        }
        let at = k % s.slot;
        let r = &mut self.reports[motor];
        if !self.pulse_booked {
            r.moved_counts = self.act[motor] - self.slot_start[motor];
            for other in (0..s.n_motors).filter(|&o| o != motor) {
                let d = (self.act[other] - self.slot_start[other]).abs();
                if d > r.others_moved.1 {
                    r.others_moved = (other + 1, d);
                }
            }
            self.pulse_booked = at >= s.pulse;
            r.done = self.pulse_booked;
        } else {
            r.coasted_counts = self.act[motor] - self.slot_start[motor] - r.moved_counts;
        }
    }

    /// What each motor did for its voltage, so far.
    pub fn checked(&self) -> &[MotorCheckReport] {
        &self.reports[..self.schedule.n_motors]
    }

    /// Why it failed, in words, after a failed sample.
    pub fn failure(&self) -> Option<String> {
        self.too_far.map(|(m, travel)| {
            format!(
                "motor {} moved {travel:.0} counts from where it started, more than \
                 check.max_travel_counts = {}",
                m + 1,
                self.max_travel
            )
        })
    }
}

impl TrajectoryGenerator for Check {
    fn name(&self) -> &'static str {
        "check"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        self.start = *start;
        self.act = *start;
        self.slot_start = *start;
        self.slot = None;
        self.pulse_booked = false;
        let s = self.schedule;
        for (m, r) in self.reports.iter_mut().enumerate() {
            let seconds = s.pulse as f64 * s.period_s;
            *r = MotorCheckReport { motor: m + 1, volts: s.volts, seconds, ..Default::default() };
        }
        self.too_far = None;
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        Some(self.schedule.samples())
    }

    #[inline]
    fn observe(&mut self, act: &[f64; MAX_MOTORS], _: &[MotorFlags; MAX_MOTORS]) {
        self.act = *act;
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if n >= self.schedule.samples() {
            return Sample::Done;
        }
        self.book(n);
        for m in 0..self.schedule.n_motors {
            let travel = (self.act[m] - self.start[m]).abs();
            if travel > self.max_travel {
                self.too_far = Some((m, travel));
                return Sample::Failed;
            }
        }
        *cmd = self.act;
        Sample::Ready
    }

    fn failure_kind(&self) -> FaultKind {
        FaultKind::TooMuchTravel
    }

    /// What each motor did for its voltage (the report's `check`).
    fn report(&self) -> GeneratorReport {
        GeneratorReport {
            failure: self.failure(),
            homed_frame: None,
            findings: serde_json::to_value(self.checked())
                .ok()
                .map(|value| Findings { section: "check", value }),
        }
    }
}

/// What one motor did in the open-loop check (`qmarc-starter check`), counts.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MotorCheckReport {
    /// 1-based motor.
    pub motor: usize,
    /// The voltage it got, V.
    pub volts: f64,
    /// For how long, s.
    pub seconds: f64,
    /// How far it moved while driven, counts (positive: up, as a positive voltage should).
    pub moved_counts: f64,
    /// How far it went on in the rest after, counts.
    pub coasted_counts: f64,
    /// The largest distance another motor moved while this one was driven, and which (1-based;
    /// 0: none moved): crossed DACs or counters show here.
    pub others_moved: (usize, f64),
    /// Its pulse ran to its end.
    pub done: bool,
}

/// The check's law: the scheduled voltage on the motor whose pulse it is, 0 V on every other;
/// commands and positions are not looked at (the loop is open).
#[derive(Debug, Clone)]
pub struct OpenLoop {
    schedule: Schedule,
}

impl OpenLoop {
    /// The law of the settings' `[check]`.
    pub fn from_settings(s: &Settings) -> OpenLoop {
        OpenLoop { schedule: Schedule::from_settings(s) }
    }
}

impl ServoLaw for OpenLoop {
    fn name(&self) -> &'static str {
        "open-loop"
    }

    fn reset(&mut self, _: &[f64; MAX_MOTORS], _: &[f64; MAX_MOTORS]) {}

    #[inline]
    fn step(&mut self, input: &ServoInput<'_>, dac: &mut [i32; MAX_MOTORS]) {
        *dac = [0; MAX_MOTORS];
        if let Some(m) = self.schedule.driven(input.n) {
            dac[m] = self.schedule.code;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn schedule() -> Schedule {
        Schedule { n_motors: 2, pulse: 3, slot: 5, code: 164, volts: 0.2, period_s: 0.001 }
    }

    #[test]
    fn each_motor_is_driven_in_turn_for_its_pulse() {
        let s = schedule();
        let driven: Vec<Option<usize>> = (0..12).map(|n| s.driven(n)).collect();
        let (o, a, b) = (None, Some(0), Some(1));
        assert_eq!(driven, [o, a, a, a, o, o, b, b, b, o, o, o]);
        assert_eq!(s.samples(), 11);
        let mut law = OpenLoop { schedule: s };
        let mut dac = [7; MAX_MOTORS];
        let zero = [0.0; MAX_MOTORS];
        law.step(&ServoInput { n: 7, elapsed: 1, cmd: &zero, act: &zero }, &mut dac);
        assert_eq!(dac, [0, 164, 0, 0]);
    }

    /// A plant that moves motor m by `gain` counts per sample while it is driven (and motor
    /// 1 a little when motor 2 is, crossed wiring), the generator's booking of it.
    #[test]
    fn the_check_books_each_motors_move_and_stops_one_that_runs_away() {
        let s = schedule();
        let run = |gain: [f64; 2], max_travel: f64, missed: &[u64]| {
            let mut g = Check::new(s, max_travel);
            g.start(&[10.0, 20.0, 0.0, 0.0]).unwrap();
            let mut act = [10.0, 20.0, 0.0, 0.0];
            let mut cmd = [0.0; MAX_MOTORS];
            let flags = [MotorFlags::default(); MAX_MOTORS];
            for n in 0..s.samples() + 1 {
                if let Some(m) = s.driven(n.saturating_sub(1)) {
                    act[m] += gain[m];
                    if m == 1 {
                        act[0] += 0.5;
                    }
                }
                if missed.contains(&n) {
                    continue; // a missed period: no read, no sample
                }
                g.observe(&act, &flags);
                match g.sample(n, &mut cmd) {
                    Sample::Ready => assert_eq!(cmd, act, "the command is where it is"),
                    other => return (g, other),
                }
            }
            (g, Sample::Ready)
        };
        let (g, end) = run([4.0, -2.0], 100.0, &[]);
        assert_eq!(end, Sample::Done);
        let r = g.checked();
        assert_eq!((r[0].moved_counts, r[0].done, r[0].others_moved), (12.0, true, (0, 0.0)));
        assert_eq!((r[1].moved_counts, r[1].others_moved), (-6.0, (1, 1.5)));
        assert_eq!((r[0].volts, r[0].seconds, r[0].motor, r[1].motor), (0.2, 0.003, 1, 2));
        // Missed periods where motor 1's pulse ends (sample 4) and where motor 2's slot
        // begins (sample 6): the first reads after them book it, one step late at worst.
        let (g, end) = run([4.0, -2.0], 100.0, &[4, 6]);
        assert_eq!(end, Sample::Done);
        let r = g.checked();
        assert_eq!((r[0].moved_counts, r[0].done), (12.0, true));
        assert_eq!((r[1].moved_counts, r[1].done, r[1].others_moved), (-4.0, true, (1, 1.0)));
        let (g, end) = run([40.0, -2.0], 100.0, &[]);
        assert_eq!(end, Sample::Failed);
        assert_eq!(
            g.failure().unwrap(),
            "motor 1 moved 120 counts from where it started, more than \
             check.max_travel_counts = 100"
        );
        assert_eq!(g.failure_kind(), FaultKind::TooMuchTravel);
    }
}
