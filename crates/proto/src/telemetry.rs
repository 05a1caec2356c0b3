//! The live telemetry of a move: [`TelemetrySample`], published by the controller on the
//! publish–subscribe service [`TELEMETRY_SERVICE`] of the run's prefix, read by the console's
//! live charts and `qmarc scope`.
//!
//! The QoS is the same on both sides ([`open_telemetry_service`]): safe overflow, so a reader
//! that falls behind loses its oldest samples and never holds the publisher up; no history;
//! [`TELEMETRY_BUFFER`] samples queued per reader; at most [`TELEMETRY_MAX_READERS`] readers.

use crate::MAX_MOTORS;
use crate::service::ServiceError;
use iceoryx2::prelude::*;
use iceoryx2::service::builder::publish_subscribe::PublishSubscribeOpenError;
use iceoryx2::service::port_factory::publish_subscribe;

/// Name of the publish–subscribe service.
pub const TELEMETRY_SERVICE: &str = "qmarc/telemetry";
/// Samples queued per reader before the oldest is dropped.
pub const TELEMETRY_BUFFER: usize = 1024;
/// Readers at most (the console, scopes).
pub const TELEMETRY_MAX_READERS: usize = 8;

/// One sample of the servo loop, taken after the cycle's DAC write.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("qmarc.TelemetrySample.v2")]
#[repr(C)]
pub struct TelemetrySample {
    /// 0, 1, 2… over the move's samples: a gap is samples lost (a full queue, a slow reader).
    pub seq: u64,
    /// The servo sample index, gather.csv's `cycle`.
    pub cycle: u64,
    /// Since tick 0, ns (gather.csv's `time`: simulated time in lock-step runs).
    pub time_ns: u64,
    /// Commanded position per motor, counts.
    pub cmd: [f64; MAX_MOTORS],
    /// Actual position per motor, counts.
    pub act: [f64; MAX_MOTORS],
    /// Following error (command − actual) per motor, counts.
    pub following_error: [f64; MAX_MOTORS],
    /// DAC value written per motor.
    pub dac: [i32; MAX_MOTORS],
    /// How late the servo thread woke for this cycle's tick, ns (saturated at u32::MAX).
    pub wake_latency_ns: u32,
    /// Tick → DAC write acknowledged, ns (saturated).
    pub output_latency_ns: u32,
    /// Wake to wake since the previous cycle, ns (0 for the first; saturated).
    pub period_ns: u32,
    /// The move's phase ([`crate::state::Phase::wire`]).
    pub phase: u32,
    /// The hwserver's status bits of the cycle ([`crate::Status`]).
    pub status: u32,
    /// The fault that ended the move ([`crate::state::FaultKind::wire`]: its code + 1, 0 for none).
    pub fault: u32,
    /// Motors driven.
    pub n_motors: u32,
    /// Samples the loop could not hand over so far (its queue to the publisher was full).
    pub dropped: u32,
    /// The gripper ([`crate::Gripper`] bits; [`crate::Gripper::ABSENT`] when none is wired).
    pub gripper: u32,
    /// The free digital outputs that are on (bit c: DIO channel c).
    pub outputs: u32,
}

const _: () = assert!(core::mem::size_of::<TelemetrySample>() == 176);

/// The telemetry service.
pub type TelemetryService = publish_subscribe::PortFactory<ipc::Service, TelemetrySample, ()>;

/// The telemetry service could not be opened.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TelemetryOpenError {
    /// No move publishes under this prefix now.
    NoMove,
    /// It exists but could not be opened (another version, other QoS, resources).
    Failed(ServiceError),
}

/// Opens the telemetry service on `node`, creating it when `create` (the publisher's side;
/// a reader only opens it, so that no reader ever makes a move's service).
pub fn open_telemetry_service(
    node: &Node<ipc::Service>,
    create: bool,
) -> Result<TelemetryService, TelemetryOpenError> {
    let failed = |e: &dyn std::fmt::Debug| {
        TelemetryOpenError::Failed(ServiceError::new("service", TELEMETRY_SERVICE, e))
    };
    let name = ServiceName::new(TELEMETRY_SERVICE).map_err(|e| failed(&e))?;
    let builder = node
        .service_builder(&name)
        .publish_subscribe::<TelemetrySample>()
        .max_publishers(1)
        .max_subscribers(TELEMETRY_MAX_READERS)
        .subscriber_max_buffer_size(TELEMETRY_BUFFER)
        .history_size(0)
        .enable_safe_overflow(true);
    if create {
        builder.open_or_create().map_err(|e| failed(&e))
    } else {
        builder.open().map_err(|e| match e {
            PublishSubscribeOpenError::DoesNotExist => TelemetryOpenError::NoMove,
            e => failed(&e),
        })
    }
}
