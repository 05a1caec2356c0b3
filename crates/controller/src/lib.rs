//! The QMARC controller's servo loop (thesis 3.8, 4.1): one cycle reads every encoder,
//! samples the trajectory, runs the servo law, writes every DAC and gathers — allocating,
//! locking and formatting nothing — and the state machine and faults around it.
//!
//! The loop is [`servo::Servo`]. Its plug-ins are the [`traj::TrajectoryGenerator`] and
//! [`law::ServoLaw`] traits (the thesis' generators and law, and their registry, are in
//! `qmarc-plugins`); it talks to the hardware server through a [`link::HwLink`]
//! ([`link::IoxLink`] over iceoryx2). `qmarc-controller-process` builds a move from the settings and runs
//! it on a SCHED_FIFO thread; `qmarc-report` writes what it leaves behind.
//!
//! A move against a hardware that stands still, on simulated time:
//!
//! ```
//! use qmarc_config::Mode;
//! use qmarc_controller::law::{ServoInput, ServoLaw};
//! use qmarc_controller::link::{HwLink, LinkError};
//! use qmarc_controller::plan::MovePlan;
//! use qmarc_controller::servo::Servo;
//! use qmarc_controller::traj::{Sample, TrajStartError, TrajectoryGenerator};
//! use qmarc_proto::{HwMsg, MAX_MOTORS};
//! use qmarc_timer::{ManualTicker, MockClock};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! /// 100 counts, held for 10 samples.
//! struct Hold;
//! impl TrajectoryGenerator for Hold {
//!     fn name(&self) -> &'static str { "hold" }
//!     fn start(&mut self, _: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> { Ok(()) }
//!     fn samples(&self) -> Option<u64> { Some(11) }
//!     fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
//!         if n > 10 { return Sample::Done }
//!         cmd[0] = 100.0;
//!         Sample::Ready
//!     }
//! }
//! /// No output at all.
//! struct Off;
//! impl ServoLaw for Off {
//!     fn name(&self) -> &'static str { "off" }
//!     fn reset(&mut self, _: &[f64; MAX_MOTORS], _: &[f64; MAX_MOTORS]) {}
//!     fn step(&mut self, _: &ServoInput<'_>, dac: &mut [i32; MAX_MOTORS]) { *dac = [0; MAX_MOTORS] }
//! }
//! /// A hardware that answers every read with position 0.
//! struct Still;
//! impl HwLink for Still {
//!     fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, LinkError> { Ok(req.response()) }
//! }
//! let plan = MovePlan { deterministic: true, ..MovePlan::new(Mode::Step, 1, 400_000) };
//! let mut servo = Servo::new(plan, Box::new(Hold), Box::new(Off), Box::new(MockClock::new(0)));
//! let stop = std::sync::atomic::AtomicBool::new(false);
//! servo.run(&mut Still, &mut ManualTicker::new(400_000), &stop)?;
//! assert_eq!(servo.cycles(), 11);
//! assert_eq!(servo.errors().axes[0].max, 100.0);
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod fault;
pub mod gather;
pub mod law;
pub mod link;
pub mod plan;
pub mod record;
pub mod servo;
pub mod stats;
pub mod status;
pub mod telemetry;
pub mod traj;
