//! The QMARC controller (thesis 3.8): trajectory generation, the servo law, the servo loop
//! and data gathering, talking to the hardware server through one link.
//!
//! The loop is [`servo::Servo`]; its plug-ins are the [`traj::TrajectoryGenerator`] and
//! [`law::ServoLaw`] traits, chosen by name from the [`registry`]. [`link::IoxLink`] is the
//! iceoryx2 link to `qmarc-hwserver`; [`run::run_move`] puts it all together on a
//! SCHED_FIFO thread and writes `gather.csv`, `gather.m` and `summary.json`.
//!
//! A move against an in-process hardware core, with simulated time:
//!
//! ```
//! use qmarc_controller::law::PidFf;
//! use qmarc_controller::servo::{MovePlan, Servo};
//! use qmarc_controller::traj::Step;
//! use qmarc_controller::config::MotorGains;
//! use qmarc_controller::link::{HwLink, LinkError};
//! use qmarc_proto::HwMsg;
//! use qmarc_timer::{ManualTicker, MockClock};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! /// A hardware that answers every read with position 0.
//! struct Still;
//! impl HwLink for Still {
//!     fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, LinkError> { Ok(req.response()) }
//! }
//! let plan = MovePlan { deterministic: true, ..MovePlan::new("step", 1, 400_000) };
//! let gains = MotorGains { kp: 182_000.0, ..MotorGains::default() };
//! let mut servo = Servo::new(plan, Box::new(Step::new(100, 0.004, 0.0004, 1)),
//!                            Box::new(PidFf::new(&[gains])), Box::new(MockClock::new(0)));
//! let stop = std::sync::atomic::AtomicBool::new(false);
//! servo.run(&mut Still, &mut ManualTicker::new(400_000), &stop)?;
//! assert_eq!(servo.cycles(), 11);
//! assert_eq!(servo.errors().axes[0].max, 100.0);
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod cli;
pub mod config;
#[doc = include_str!("../../../docs/extending.md")]
pub mod extending {}
pub mod gather;
pub mod homing;
pub mod knots;
pub mod law;
pub mod link;
pub mod output;
pub mod progress;
pub mod pvt;
pub mod registry;
pub mod run;
pub mod servo;
pub mod spline;
pub mod summary;
pub mod traj;
