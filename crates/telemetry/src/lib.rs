//! Live telemetry of a move. The servo loop puts a [`TelemetrySample`] into a wait-free ring
//! every `telemetry.every` cycles (the controller's `telemetry` module); [`relay`] is the
//! controller's thread that empties it and publishes each sample on the run's
//! `qmarc/telemetry` publish–subscribe service; [`reader`] opens that service from another
//! process (the console's live charts, [`scope`]) and finds the runs there are; [`scope`] is
//! `qmarc scope`.
//!
//! [`TelemetrySample`]: qmarc_proto::telemetry::TelemetrySample
#![deny(missing_docs)]

/// Reading a run's telemetry from another process; which runs there are.
pub mod reader;
/// The controller's thread that publishes the loop's samples.
pub mod relay;
/// `qmarc scope`.
pub mod scope;
