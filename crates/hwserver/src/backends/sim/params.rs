//! [`SimParams`]: the simulated robot of one run — its plant, motors, period and clock — and
//! their checks.

use qmarc_config::{Settings, SimPlant};
use qmarc_proto::MAX_MOTORS;

/// Parameters of the simulated robot: the settings' plant ([`SimPlant`], every constant of the
/// model; the defaults are the values of `../shared/notes/deltabot.md`, an assumption, not
/// measured data) with the motors, the period and the clock of one run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimParams {
    /// Motors simulated (1‥[`MAX_MOTORS`]).
    pub n_motors: usize,
    /// Servo period in ns: the step of lock-step mode.
    pub period_ns: u64,
    /// Lock-step clock (deterministic) instead of real time.
    pub lockstep: bool,
    /// Position of each motor at start, counts in the homed frame.
    pub start_counts: [f64; MAX_MOTORS],
    /// The plant, switches, frame and fault injection (motors 1-based; see
    /// [`super::SimDeltabot::estop_button`] for an emergency stop pressed from outside).
    pub plant: SimPlant,
    /// The outputs message 13 may write: the 626's free outputs, as the settings wire them
    /// ([`qmarc_config::S626Settings::free_outputs`]; the gripper is one of them).
    pub free_outputs: u32,
}

impl Default for SimParams {
    /// The settings' plant ([`SimPlant::default`], where each constant is defined once), three
    /// motors at 400 µs, paced, no fault injected.
    fn default() -> SimParams {
        SimParams {
            n_motors: 3,
            period_ns: 400_000,
            lockstep: false,
            start_counts: [0.0; MAX_MOTORS],
            plant: SimPlant::default(),
            free_outputs: qmarc_config::S626Settings::default().free_outputs(3),
        }
    }
}

/// A [`SimParams`] value is out of range.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum SimParamsError {
    /// A parameter is outside its range.
    #[error("simulator parameter `{name}` = {value} is invalid: {expected}")]
    OutOfRange {
        /// Parameter name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is allowed.
        expected: &'static str,
    },
}

impl SimParams {
    /// The simulated robot of `s` (`[sim]`, the motors and period of `[general]`), in
    /// lock-step when `lockstep`.
    pub fn from_settings(s: &Settings, lockstep: bool) -> SimParams {
        let mut start_counts = [0.0; MAX_MOTORS];
        for (c, v) in start_counts.iter_mut().zip(&s.sim.start_counts) {
            *c = *v;
        }
        SimParams {
            n_motors: s.n_motors,
            period_ns: s.period_ns(),
            lockstep,
            start_counts,
            plant: s.sim.plant,
            free_outputs: s.s626.free_outputs(s.n_motors),
        }
    }

    /// Checks every parameter.
    pub fn validate(&self) -> Result<(), SimParamsError> {
        let bad = |name, value, expected| Err(SimParamsError::OutOfRange { name, value, expected });
        let p = &self.plant;
        if !(1..=MAX_MOTORS).contains(&self.n_motors) {
            return bad("motors", self.n_motors as f64, "1 to 4");
        }
        if self.period_ns == 0 {
            return bad("period", 0.0, "a positive period");
        }
        let positive = [("kv", p.kv), ("tau_s", p.tau_s), ("coast_tau_s", p.coast_tau_s)];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return bad(name, v, "finite and > 0");
            }
        }
        if !(p.velocity_loop_hz.is_finite() && p.velocity_loop_hz >= 0.0) {
            return bad("velocity_loop_hz", p.velocity_loop_hz, "finite and ≥ 0");
        }
        if p.velocity_loop_hz > 0.0 && !(p.velocity_loop_zeta > 0.0 && p.velocity_loop_zeta < 1.0) {
            return bad("velocity_loop_zeta", p.velocity_loop_zeta, "between 0 and 1");
        }
        for v in [p.top_switch_counts, p.bottom_switch_counts] {
            if !v.is_finite() {
                return bad("switch position", v, "finite");
            }
        }
        if p.top_switch_counts == p.bottom_switch_counts {
            return bad("top_switch", p.top_switch_counts, "different from bottom_switch");
        }
        for m in [p.stall_motor, p.stuck_top_motor, p.reversed_motor].into_iter().flatten() {
            if !(1..=self.n_motors).contains(&m) {
                return bad("fault-injection motor", m as f64, "one of the simulated motors");
            }
        }
        for &s in &self.start_counts[..self.n_motors] {
            if !s.is_finite() || s.abs() >= f64::from(1u32 << 23) {
                return bad("start position", s, "finite and within ±2^23 counts");
            }
        }
        Ok(())
    }
}
