//! The camera server (thesis 6.2.1: a Camera Server process beside the Hardware Server): it
//! sees the belt upstream of the robot and tells the controller, for every frame, where each
//! part lay on the belt when the frame was exposed ([`qmarc_proto::camera::PartDetection`]).
//!
//! The camera is behind a backend ([`CameraBackend`]), as the hardware is behind the
//! hwserver's: [`sim::SimCamera`] sees the simulated world of the run (the belt of
//! `[conveyor]`, the parts a feeder drops on it, `[camera]`'s rate, latency and noise) and
//! reports its parts directly; [`images::ImagesCamera`] finds them in frames — drawn from
//! that world, replayed from files, or from a device ([`frames`]) — with `qmarc-vision`. A
//! camera on a network is one more backend and one more name in `camera.backend`.
#![deny(missing_docs)]

use qmarc_proto::camera::PartDetection;
use std::sync::atomic::AtomicBool;

pub mod frames;
pub mod images;
pub mod sim;
pub mod tools;
#[cfg(feature = "v4l2")]
pub mod v4l2;

/// A frame whose results are in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Frame {
    /// Its number: 0, 1, 2…
    pub number: u64,
    /// When it was exposed, ns of `CLOCK_MONOTONIC`.
    pub exposure_ns: u64,
}

/// A camera failed (a lost connection, a device error): the server ends, saying why.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("camera `{backend}`: {reason}")]
pub struct CameraError {
    /// The backend.
    pub backend: &'static str,
    /// Why, in words.
    pub reason: String,
}

/// A camera: frames, and the parts found in each.
pub trait CameraBackend: Send {
    /// Its name in `camera.backend`.
    fn name(&self) -> &'static str;

    /// Waits for the next frame's results and writes its parts into `out` (cleared first).
    /// `None` when `stop` was set while it waited.
    fn next_frame(
        &mut self,
        out: &mut Vec<PartDetection>,
        stop: &AtomicBool,
    ) -> Result<Option<Frame>, CameraError>;
}

/// The camera of the run `spec` (`camera.backend`).
pub fn open(spec: &qmarc_config::RunSpec) -> Result<Box<dyn CameraBackend>, CameraError> {
    match spec.settings.camera.backend.as_str() {
        "sim" => Ok(Box::new(sim::SimCamera::of(spec))),
        "images" => Ok(Box::new(images::ImagesCamera::of(spec)?)),
        other => Err(CameraError {
            backend: "none",
            reason: format!(
                "no camera backend `{other}`; available: {}",
                qmarc_config::CAMERA_BACKENDS.join(", ")
            ),
        }),
    }
}
