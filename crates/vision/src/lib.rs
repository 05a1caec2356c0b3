//! The camera's eyes (issue 46): parts found in real frames, and the calibration that takes
//! a frame's pixels to the belt.
//!
//! - [`camera::CameraModel`]: a pinhole camera with radial distortion above the belt.
//! - [`render`]: frames of the belt and its parts, or of a calibration target, drawn through
//!   a camera model (the simulated camera's frames; the tests' frames with known parts).
//! - [`blobs`]: the connected regions of a thresholded frame, as runs, with their moments.
//! - [`detect::Detector`]: the parts of a frame in belt coordinates.
//! - [`grid`]: a calibration target's dots found and named; [`calib::Calibration`]: the fit,
//!   its file.
//!
//! Nothing here is on the servo loop's path: the camera server runs it, in its own process.
//!
//! ```
//! use qmarc_vision::{blobs::Polarity, calib::Calibration, camera::CameraModel, grid, render};
//! use qmarc_vision::detect::{DetectSettings, Detector};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! // A camera 800 mm above the belt, 0.5 mm a pixel; a 9×7 target of 20 mm under it.
//! let cam = CameraModel::overhead([150.0, 0.0], 800.0, 0.5, [640, 480]);
//! let target = render::Target { grid: [9, 7], pitch_mm: 20.0, origin_mm: [70.0, -60.0], dot_mm: 8.0, origin_scale: render::ORIGIN_DOT_SCALE };
//! let frame = render::target_frame(&cam, &target, &render::Look::default());
//! let dots = grid::find(&frame, target.grid, target.pitch_mm, target.origin_mm)?;
//! let calibration = Calibration::fit(&dots.pixels, &dots.belt, cam.size_px)?;
//! assert!(calibration.reprojection.mean_px < 0.3);
//! // A part 10 mm tall at (160, 20) mm, turned 30°: found there.
//! let part = render::PartShape { at_mm: [160.0, 20.0], angle_rad: 30f64.to_radians(), size_mm: [40.0, 16.0], height_mm: 10.0 };
//! let frame = render::belt_frame(&cam, &[part], &render::Look::default());
//! let settings = DetectSettings { polarity: Polarity::Bright, threshold: 70, area_px: [500, 6000], part_height_mm: 10.0 };
//! let mut detector = Detector::new(settings, calibration, Some(cam.intrinsics));
//! let mut parts = Vec::new();
//! detector.detect(&frame, &mut parts);
//! assert_eq!(parts.len(), 1);
//! assert!((parts[0].belt_mm - 160.0).abs() < 0.5 && (parts[0].angle_deg - 30.0).abs() < 2.0);
//! # Ok(())
//! # }
//! ```
#![deny(missing_docs)]

pub mod blobs;
pub mod calib;
pub mod camera;
pub mod detect;
pub mod grid;
pub mod render;
