//! Live telemetry of a move. The servo loop puts a [`TelemetrySample`] into a wait-free ring
//! every `telemetry.every` cycles (the controller's `telemetry` module); [`relay`] is the
//! controller's thread that empties it and publishes each sample on the run's
//! `qmarc/telemetry` publish–subscribe service; [`reader`] opens that service from another
//! process (the console's live charts, [`scope`]); [`scope`] is `qmarc scope`; [`session`]
//! says which runs are alive, whose, and where their data go.
//!
//! [`TelemetrySample`]: qmarc_proto::telemetry::TelemetrySample
#![deny(missing_docs)]

/// Reading a run's telemetry from another process; which serving session a client means.
pub mod reader;
/// The controller's thread that publishes the loop's samples.
pub mod relay;
/// `qmarc scope`.
pub mod scope;
/// Which runs are alive (their processes), for refusing a live prefix and naming sessions.
pub mod session;
