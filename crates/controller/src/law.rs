//! [`ServoLaw`]: the control law plug-in the loop runs every cycle (the thesis' law, PidFf,
//! and the registry are in `qmarc-plugins`).

use qmarc_proto::{DAC_MAX, MAX_MOTORS};

/// What a law sees each cycle. Positions are in counts in the software-counter frame.
#[derive(Debug, Clone, Copy)]
pub struct ServoInput<'a> {
    /// Servo sample index n (the command is the path at n·T).
    pub n: u64,
    /// Servo periods since the law's previous cycle (its reset counts as sample 0): 1 when
    /// the loop is punctual, k + 1 after k missed periods. A law that differences or sums
    /// over cycles divides or multiplies by it, so that a late cycle outputs what a punctual
    /// one would (a velocity over k + 1 periods is not k + 1 times the velocity).
    pub elapsed: u64,
    /// Command position per motor.
    pub cmd: &'a [f64; MAX_MOTORS],
    /// Actual (measured) position per motor.
    pub act: &'a [f64; MAX_MOTORS],
}

/// A servo law: commanded and actual positions in, DAC codes out.
///
/// Real-time contract: construction (from already-validated settings) may allocate and fail;
/// [`ServoLaw::reset`] runs before the move; [`ServoLaw::step`] runs every cycle, writes
/// codes clamped to ±[`DAC_MAX`] into the caller's array (an output that is not a finite
/// number as [`NOT_A_CODE`]: the loop then disables every motor, `bad_output`) and never
/// allocates, locks, does I/O or panics.
pub trait ServoLaw: Send {
    /// Registered name.
    fn name(&self) -> &'static str;

    /// Clears the state at the start of a move, given sample 0's command and actual
    /// positions (so the first cycle sees no velocity).
    fn reset(&mut self, cmd: &[f64; MAX_MOTORS], act: &[f64; MAX_MOTORS]);

    /// Computes the DAC code of every motor for this cycle.
    fn step(&mut self, input: &ServoInput<'_>, dac: &mut [i32; MAX_MOTORS]);
}

/// What [`to_dac_code`] makes of an output that is not a finite number: no DAC code, so the
/// loop refuses it (`bad_output`) instead of writing a silent 0 V.
pub const NOT_A_CODE: i32 = i32::MIN;

/// Rounds and clamps a law output to a DAC code; an output that is not finite (NaN, ±∞)
/// gives [`NOT_A_CODE`].
#[inline]
pub fn to_dac_code(u: f64) -> i32 {
    let limit = f64::from(DAC_MAX);
    if u.is_finite() { u.clamp(-limit, limit).round() as i32 } else { NOT_A_CODE }
}

/// True for a code a DAC can take: within ±[`DAC_MAX`].
#[inline]
pub fn is_dac_code(code: i32) -> bool {
    (-DAC_MAX..=DAC_MAX).contains(&code)
}
