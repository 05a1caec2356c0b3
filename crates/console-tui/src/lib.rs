//! The QMARC console, `qmarc`: the thesis' controller console (3.4) as a terminal program.
//!
//! It edits the five sections of the settings file the starter reads ([`form`]), runs moves
//! by spawning `qmarc-starter` and streaming its output ([`starter_process`]), and shows each move's
//! error figures, timing, fault and charts right after it, with a history of the session's
//! moves ([`results`]); Ctrl-T tunes the gains on the path and Ctrl-A takes the tuned ones
//! ([`tuning`]). While a move runs, a line of its own says what it does (homing's motor and
//! stage, where the effector is, the gripper: [`live`]); at rest, the setup page says where the
//! robot is, which motors are homed and the gripper, and where each comes from ([`rest`]).
//! [`app`] holds the state and the keys, [`ui`] draws it; both work on ratatui's test backend,
//! which is how the screens are tested.
//!
//! ```
//! use qmarc_console::{app::App, form::Form, ui};
//! use ratatui::{Terminal, backend::TestBackend};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let config = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
//! let dir = std::env::temp_dir().join(format!("qmarc-doc-{}", std::process::id()));
//! std::fs::create_dir_all(&dir)?;
//! let copy = dir.join("qmarc.toml");
//! std::fs::copy(&config, &copy)?;
//! let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
//! let app = App::new(Form::load_in(&copy, &repo)?, "qmarc-starter".into(), dir.clone());
//! let mut terminal = Terminal::new(TestBackend::new(80, 24))?;
//! terminal.draw(|f| ui::draw(f, &app))?;
//! let screen = format!("{:?}", terminal.backend().buffer());
//! assert!(screen.contains("Gains (one column per motor)"));
//! std::fs::remove_dir_all(&dir)?;
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod app;
pub mod cmd;
pub mod form;
pub mod live;
pub mod rest;
pub mod results;
pub mod starter_process;
pub mod tuning;
pub mod ui;
