//! [`TrajectoryGenerator`]: the trajectory plug-in, and [`Step`], the thesis' default.

use crate::config::Settings;
use qmarc_proto::MAX_MOTORS;

/// What a generator says about a sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Sample {
    /// The command for this sample is in the output.
    Ready,
    /// The path has ended before this sample; the move is over.
    Done,
    /// An online generator has no knot for this sample yet (a fault: the robot cannot wait).
    Starved,
}

/// A generator could not start a path.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum TrajStartError {
    /// The path leaves the range positions can take.
    #[error("motor {motor}: the path reaches {value} counts at sample {sample}: {reason}")]
    OutOfRange {
        /// 1-based motor.
        motor: usize,
        /// Sample index.
        sample: u64,
        /// Position, counts.
        value: f64,
        /// What the limit is.
        reason: &'static str,
    },
}

/// A trajectory generator: the command position of every motor at each servo sample.
///
/// Real-time contract: construction (from validated settings) and [`TrajectoryGenerator::start`]
/// may allocate and fail, and run before any motor is enabled; offline generators compute
/// their whole command queue there. [`TrajectoryGenerator::sample`] runs every cycle, writes
/// into the caller's array and never allocates, locks, does I/O or panics. Paths are absolute
/// positions in counts in the software-counter frame.
pub trait TrajectoryGenerator: Send {
    /// Registered name.
    fn name(&self) -> &'static str;

    /// Prepares the path from the actual positions at the start of the move.
    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError>;

    /// Number of samples of the move (its duration / period + 1), if known after `start`; it
    /// sizes the gather buffer. `None` for a stream of unknown length.
    fn samples(&self) -> Option<u64>;

    /// The command of sample `n` (time n·T from the start) for every motor.
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample;
}

/// An ideal step of `size` counts on every motor, held for `duration` (thesis 3.8.1.1.4, the
/// base class' default path): sample 0 is the start position, every later sample the start
/// plus `size`.
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

    /// The step of the settings' `[step]` section.
    pub fn from_settings(s: &Settings) -> Step {
        Step::new(s.step.size, s.step.duration_s, s.period_s(), s.n_motors)
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
