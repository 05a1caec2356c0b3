//! The `qmarc-controller` process: one move from the [`qmarc_config::RunSpec`] the starter
//! hands over (`--settings FILE`) — the generator and law from the plug-ins' registry, the
//! servo loop of `qmarc-controller` on a SCHED_FIFO thread over the iceoryx2 link, and the
//! report of `qmarc-report` written after it.
//!
//! ```
//! use qmarc_config::Mode;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let names = qmarc_config::Names { laws: vec!["pidff"], methods: vec!["spline"], any_plugin: false };
//! let table = "[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n";
//! let settings = qmarc_config::Settings::parse("q.toml".as_ref(), &table.repeat(3), &names)?;
//! let plan = qmarc_controller_process::run::plan_for(&settings, Mode::Home, false, false);
//! assert!(!plan.monitor_switches && !plan.require_homed, "homing watches its switches itself");
//! assert_eq!(qmarc_controller_process::run::generator_name(Mode::Run, &settings), "spline");
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod conveyor;
pub mod run;
