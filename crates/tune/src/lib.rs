//! QMARC's automatic tuning (`qmarc-starter tune`): better gains for the user's own path.
//!
//! The thesis tuned by hand "with the objective of minimizing the sum of absolute position
//! error" (5.2). Here every candidate gain set is a move of that path: on the simulated robot
//! a lock-step move inside this process ([`local::run_local`], byte for byte the move of the
//! process set, in milliseconds), on hardware a real move through the process set (an
//! [`eval::Evaluator`] the starter provides). [`optimise::tune`] searches each motor's gains
//! with argmin's Nelder–Mead under the constraints of `[tune]`; [`report`] says what it
//! found and writes the gains as TOML.

pub mod eval;
pub mod local;
pub mod optimise;
pub mod real;
pub mod report;
