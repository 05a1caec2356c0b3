//! What every QMARC program does at its edges, whatever it is: reads its command line and
//! ends with docs/usage.md's exit codes ([`cli`]), spawns its children so that none outlives
//! it ([`process`]), and picks loopback ports for its own servers ([`net`]). The starter, the
//! console, the bench, the bridge and the two robot processes share it; it knows no settings
//! and no robot.
//!
//! ```
//! assert_eq!(qmarc_program::cli::parse_on_off("on"), Ok(true));
//! ```
#![deny(missing_docs)]

pub mod cli;
pub mod net;
pub mod process;
