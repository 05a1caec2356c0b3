//! [`Step`]: the thesis' default path (3.8.1.1.4).

use crate::source::TrajBuildError;
use qmarc_config::Settings;
use qmarc_controller::traj::{Sample, TrajStartError, TrajectoryGenerator, bounds_of};
use qmarc_proto::MAX_MOTORS;

/// An ideal step of `size` counts on every motor, held for `duration` (thesis 3.8.1.1.4, the
/// base class' default path): sample 0 is the start position, every later sample the start
/// plus `size`.
///
/// The thesis' tuning move is a step by definition, so no velocity or acceleration limit can
/// hold for it (its one-period jump is what the step response measures); what bounds it is
/// the following-error limit, which the error right after the step equals: a step beyond a
/// motor's `max_following_error_counts` is refused before the move.
#[derive(Debug, Clone, PartialEq)]
pub struct Step {
    size: f64,
    last_sample: u64,
    n_motors: usize,
    start: [f64; MAX_MOTORS],
}

impl Step {
    /// A step of `size_counts` lasting `duration_s` at period `period_s`, for `n_motors`.
    pub fn new(size_counts: i64, duration_s: f64, period_s: f64, n_motors: usize) -> Step {
        Step {
            size: size_counts as f64,
            last_sample: (duration_s / period_s).round() as u64,
            n_motors: n_motors.min(MAX_MOTORS),
            start: [0.0; MAX_MOTORS],
        }
    }

    /// The step of the settings' `[step]` section; it must last at least one servo period.
    pub fn from_settings(s: &Settings) -> Result<Step, TrajBuildError> {
        if s.step.duration_s < s.period_s() {
            return Err(TrajBuildError::TooShort {
                seconds: s.step.duration_s,
                period_us: s.period_us,
            });
        }
        for (m, safety) in s.safety.iter().enumerate().take(s.n_motors) {
            let limit = safety.max_following_error_counts;
            if s.step.size.unsigned_abs() as f64 > limit {
                return Err(TrajBuildError::StepTooLarge {
                    motor: m + 1,
                    size: s.step.size,
                    limit,
                });
            }
        }
        Ok(Step::new(s.step.size, s.step.duration_s, s.period_s(), s.n_motors))
    }
}

impl TrajectoryGenerator for Step {
    fn name(&self) -> &'static str {
        "step"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        for (m, &p) in start.iter().enumerate().take(self.n_motors) {
            let target = p + self.size;
            if !target.is_finite() || target.abs() >= 9.0e15 {
                return Err(TrajStartError::OutOfRange {
                    motor: m + 1,
                    sample: 1,
                    value: target,
                    reason: "beyond the exact range of the 64-bit software counter",
                });
            }
        }
        self.start = *start;
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        Some(self.last_sample + 1)
    }

    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        let target = self.start.map(|s| s + self.size);
        Some(bounds_of([&self.start, &target]))
    }

    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        Some([0.0; MAX_MOTORS])
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if n > self.last_sample {
            return Sample::Done;
        }
        let offset = if n == 0 { 0.0 } else { self.size };
        for (m, (c, start)) in cmd.iter_mut().zip(&self.start).enumerate() {
            *c = if m < self.n_motors { start + offset } else { 0.0 };
        }
        Sample::Ready
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn step_holds_start_then_target_for_duration_over_period_plus_one_samples() {
        let mut s = Step::new(1000, 0.002, 0.0004, 2);
        assert_eq!(s.samples(), Some(6));
        s.start(&[10.0, -5.0, 99.0, 99.0]).unwrap();
        let mut cmd = [0.0; MAX_MOTORS];
        assert_eq!(s.sample(0, &mut cmd), Sample::Ready);
        assert_eq!(cmd, [10.0, -5.0, 0.0, 0.0]);
        for n in 1..=5 {
            assert_eq!(s.sample(n, &mut cmd), Sample::Ready);
            assert_eq!(cmd, [1010.0, 995.0, 0.0, 0.0]);
        }
        assert_eq!(s.sample(6, &mut cmd), Sample::Done);
    }

    #[test]
    fn step_refuses_targets_beyond_the_counter() {
        let mut s = Step::new(1 << 23, 1.0, 0.0004, 1);
        let e = s.start(&[9.0e15, 0.0, 0.0, 0.0]).unwrap_err();
        assert!(e.to_string().starts_with("motor 1: the path reaches"), "{e}");
    }
}
