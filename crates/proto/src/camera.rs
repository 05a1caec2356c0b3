//! What the camera server (`qmarc-camera`, thesis 6.2.1) tells the controller: one
//! [`PartDetection`] per part per frame, published on the publish–subscribe service
//! [`CAMERA_SERVICE`] of the run's prefix.
//!
//! The QoS is the same on both sides ([`open_camera_service`]): one camera; safe overflow, so
//! a reader that falls behind loses its oldest detections and never holds the camera up; no
//! history (a reader that comes late starts from the next frame); [`CAMERA_BUFFER`]
//! detections queued per reader.

use crate::service::ServiceError;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe;

/// Name of the publish–subscribe service.
pub const CAMERA_SERVICE: &str = "qmarc/camera";
/// Detections queued per reader before the oldest is dropped: seconds of parts at any rate
/// a robot picks.
pub const CAMERA_BUFFER: usize = 512;
/// Readers at most (the controller, the console, a bridge).
pub const CAMERA_MAX_READERS: usize = 4;

/// One part seen in one frame: where it lay on the belt when the frame was exposed.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("qmarc.PartDetection.v1")]
#[repr(C)]
pub struct PartDetection {
    /// The camera's frame number, 0, 1, 2… (the parts of one frame share it).
    pub frame: u64,
    /// When the frame was exposed, ns of `CLOCK_MONOTONIC`.
    pub exposure_ns: u64,
    /// The belt encoder at the exposure, counts, when the camera latched it
    /// ([`PartDetection::LATCHED`]); else 0, and the controller interpolates its own samples
    /// of the encoder at `exposure_ns`.
    pub latched_counts: i64,
    /// Along the belt, mm (belt coordinates, `conveyor.origin_mm` and `direction`).
    pub belt_mm: f64,
    /// Across the belt, mm (`direction` turned +90° about z).
    pub across_mm: f64,
    /// The part's orientation about the vertical, rad.
    pub angle_rad: f64,
    /// [`PartDetection::LATCHED`] and later flags.
    pub flags: u32,
    /// How many parts the frame holds (this one among them).
    pub in_frame: u32,
}

const _: () = assert!(core::mem::size_of::<PartDetection>() == 56);

impl PartDetection {
    /// `latched_counts` holds the belt encoder latched at the exposure.
    pub const LATCHED: u32 = 1;

    /// The camera latched the belt's count at the exposure.
    pub fn latched(&self) -> bool {
        self.flags & Self::LATCHED != 0
    }
}

/// The camera service.
pub type CameraService = publish_subscribe::PortFactory<ipc::Service, PartDetection, ()>;

/// Opens the camera service on `node`, creating it if it is not there yet: the camera or
/// its reader, whichever comes first (a reader that comes first waits for a camera that
/// starts later; the QoS is the same either way).
pub fn open_camera_service(node: &Node<ipc::Service>) -> Result<CameraService, ServiceError> {
    let failed = |e: &dyn std::fmt::Debug| ServiceError::new("service", CAMERA_SERVICE, e);
    let name = ServiceName::new(CAMERA_SERVICE).map_err(|e| failed(&e))?;
    node.service_builder(&name)
        .publish_subscribe::<PartDetection>()
        .max_publishers(1)
        .max_subscribers(CAMERA_MAX_READERS)
        .subscriber_max_buffer_size(CAMERA_BUFFER)
        .history_size(0)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| failed(&e))
}
