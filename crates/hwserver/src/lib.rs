//! The QMARC hardware server (thesis 3.6): the only process that touches hardware.
//!
//! It waits for requests from the controller, performs them on a [`Backend`] and answers each
//! with the status word. The [`HwCore`] holds what is backend-independent: the 64-bit
//! software position extended from each 24-bit counter (thesis 3.10.2), enable state, latched
//! limit-switch bits and the watchdog. [`server::answer_requests`] is the iceoryx2 loop around it.
//! Backends are chosen by name from [`backends::BACKENDS`] (one file and one registry line
//! each); the default is [`SimDeltabot`], a simulated Deltabot with velocity-mode amplifiers,
//! quadrature counters and limit switches (`../shared/notes/deltabot.md`). Every backend
//! passes the [`conformance`] suite.
//!
//! ```
//! use qmarc_hwserver::{HwCore, SimDeltabot, SimParams};
//! use qmarc_proto::{HwMsg, MsgType};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let sim = SimDeltabot::new(SimParams { n_motors: 3, lockstep: true, ..SimParams::default() })?;
//! let mut core = HwCore::new(Box::new(sim));
//! let resp = core.handle(&HwMsg::for_motor(MsgType::EnableMotor, 0));
//! assert!(resp.status().is_ok());
//! let resp = core.handle(&HwMsg::read_all_encoders());
//! assert_eq!(resp.data[0], 0.0);
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod backend;
pub mod backends;
pub mod conformance;
pub mod core;
pub mod gripper;
pub mod selftest;
pub mod server;

pub use crate::core::HwCore;
pub use backend::{Backend, BackendOpenError, HwFault, Inputs, Outputs};
pub use backends::sim::{SimDeltabot, SimParams, SimParamsError};
