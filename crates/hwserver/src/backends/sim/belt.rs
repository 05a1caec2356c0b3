//! The simulated robot's belt ([`SimBelt`]): the conveyor of `[conveyor]` moving as its speed,
//! speed steps and acceleration say ([`BeltMotion`]), read by an encoder of
//! `conveyor.mm_per_count` — the same belt the simulated camera sees, on the same clock.

use qmarc_conveyor::BeltMotion;
use qmarc_proto::{COUNTER_MASK, COUNTER_ZERO};

/// The belt under the simulated robot and its encoder.
#[derive(Debug, Clone, PartialEq)]
pub struct SimBelt {
    motion: BeltMotion,
    mm_per_count: f64,
    /// `CLOCK_MONOTONIC` ns at which the belt is at 0 and its speed steps' times start (the
    /// run's world, [`qmarc_config::RunSpec::epoch_ns`]); `None`: when the robot was made.
    epoch_ns: Option<u64>,
}

impl SimBelt {
    /// The belt of the settings' `[conveyor]`.
    pub fn of(s: &qmarc_config::Settings) -> SimBelt {
        let c = &s.conveyor;
        SimBelt {
            motion: BeltMotion::new(c.speed_mm_s, &c.speed_steps, c.acceleration_mm_s2),
            mm_per_count: c.mm_per_count,
            epoch_ns: None,
        }
    }

    /// The belt starts at `epoch_ns` of `CLOCK_MONOTONIC`.
    pub fn set_epoch(&mut self, epoch_ns: u64) {
        self.epoch_ns = Some(epoch_ns);
    }

    /// The encoder's raw 24-bit counter when the belt has run `t_s` (its time on the
    /// simulator's clock, whose 0 is `origin_ns` of `CLOCK_MONOTONIC` in real time): the
    /// belt's counts since its start, from [`COUNTER_ZERO`]. Allocates nothing.
    pub fn counter(&self, t_ns: u64, origin_ns: u64, lockstep: bool) -> u32 {
        let t_ns = match self.epoch_ns {
            Some(epoch) if !lockstep => (origin_ns + t_ns).saturating_sub(epoch),
            _ => t_ns,
        };
        let counts = (self.motion.at(t_ns as f64 * 1e-9).0 / self.mm_per_count).floor() as i64;
        COUNTER_ZERO.wrapping_add(counts as u32) & COUNTER_MASK
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qmarc_proto::counter_delta;

    fn belt(speed: f64, steps: &[[f64; 2]]) -> SimBelt {
        SimBelt {
            motion: BeltMotion::new(speed, steps, 1_000.0),
            mm_per_count: 0.05,
            epoch_ns: None,
        }
    }

    #[test]
    fn the_encoder_counts_the_belts_travel() {
        let b = belt(500.0, &[]);
        let at = |t_s: f64| counter_delta(COUNTER_ZERO, b.counter((t_s * 1e9) as u64, 0, true));
        assert_eq!(at(0.0), 0);
        // 500 mm/s for 1 s is 500 mm: 10 000 counts of 0.05 mm.
        assert_eq!(at(1.0), 10_000);
        assert_eq!(at(0.001), 10);
        // A belt that runs backwards counts down.
        let back = belt(-100.0, &[]);
        assert_eq!(counter_delta(COUNTER_ZERO, back.counter(1_000_000_000, 0, true)), -2_000);
    }

    #[test]
    fn in_real_time_the_belt_runs_from_the_worlds_epoch() {
        let mut b = belt(500.0, &[]);
        b.set_epoch(5_000_000_000);
        // The robot was made at 5.5 s of the monotonic clock; 0.5 s later the belt has run 1 s.
        let counts = counter_delta(COUNTER_ZERO, b.counter(500_000_000, 5_500_000_000, false));
        assert_eq!(counts, 10_000);
        // Before the epoch the belt has not started; in lock-step the epoch does not count.
        assert_eq!(counter_delta(COUNTER_ZERO, b.counter(0, 1_000, false)), 0);
        assert_eq!(counter_delta(COUNTER_ZERO, b.counter(500_000_000, 5_500_000_000, true)), 5_000);
    }

    #[test]
    fn a_speed_step_changes_the_counting_rate() {
        let b = belt(500.0, &[[1.0, 100.0]]);
        let at = |t_s: f64| counter_delta(COUNTER_ZERO, b.counter((t_s * 1e9) as u64, 0, true));
        // After the ramp (0.4 s at 1000 mm/s²) the belt counts 2000 counts/s.
        assert_eq!(at(3.0) - at(2.0), 2_000);
    }
}
