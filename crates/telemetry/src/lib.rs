//! Live telemetry of a move. The servo loop puts a [`TelemetrySample`] into a wait-free ring
//! every `telemetry.every` cycles (the controller's `telemetry` module); [`relay`] is the
//! controller's thread that empties it and publishes each sample on the run's
//! `qmarc/telemetry` publish–subscribe service; [`reader`] opens that service from another
//! process (the console's live charts, [`scope`]); [`scope`] is `qmarc scope`.
//!
//! [`TelemetrySample`]: qmarc_proto::telemetry::TelemetrySample
#![deny(missing_docs)]

pub mod reader;
pub mod relay;
pub mod scope;
