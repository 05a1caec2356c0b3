//! [`ImagesCamera`]: the camera that sees (issue 46). Frames come from a
//! [`FrameSource`] — drawn from the simulated belt through the camera model, replayed from a
//! folder of PNG files, or a Video4Linux2 device — and the parts are found in each by
//! [`qmarc_vision::detect::Detector`], through the calibration `[camera] calibration` names
//! (the simulated camera, without one, calibrates itself from a target it draws, as a user
//! does with a real one).

use crate::sim::SimCamera;
use crate::{CameraBackend, CameraError, Frame};
use image::GrayImage;
use qmarc_config::{CameraSettings, FrameSource, ImageSettings, RunSpec};
use qmarc_conveyor::world::TruePart;
use qmarc_proto::camera::PartDetection;
use qmarc_vision::blobs::Polarity;
use qmarc_vision::calib::Calibration;
use qmarc_vision::camera::CameraModel;
use qmarc_vision::detect::{DetectSettings, Detection, Detector};
use qmarc_vision::render::{self, Look, PartShape, Target};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

/// The camera of `[camera]`'s image settings.
pub fn camera_model(i: &ImageSettings) -> CameraModel {
    CameraModel { pose: i.pose, intrinsics: i.intrinsics, size_px: i.image_px, k1: i.sim_k1 }
}

/// What the detector looks for, from `[camera]`.
pub fn detect_settings(c: &CameraSettings) -> DetectSettings {
    DetectSettings {
        polarity: if c.images.polarity == "dark" { Polarity::Dark } else { Polarity::Bright },
        threshold: c.images.threshold,
        area_px: c.images.area_px,
        part_height_mm: c.part_height_mm,
    }
}

/// How the simulated camera's frames look.
pub fn sim_look(i: &ImageSettings, seed: u64) -> Look {
    Look {
        belt: i.sim_gray[0],
        part: i.sim_gray[1],
        noise: i.sim_noise_gray,
        seed,
        ..Look::default()
    }
}

/// Whether the `images` camera of `[camera]` can be used before anything starts (the
/// starter asks): its frames' source is there (a folder's first frame of `image_px`), its
/// calibration reads and agrees with `intrinsics`, and what it sees of the belt ends before
/// the robot's window (`window_mm`).
pub fn check(c: &CameraSettings, window_mm: [f64; 2]) -> Result<(), CameraError> {
    let fail = |reason: String| CameraError { backend: "images", reason };
    match c.images.frame_source() {
        FrameSource::Sim => {}
        FrameSource::Dir(dir) => {
            let files = crate::frames::in_folder(&dir).map_err(fail)?;
            let first = crate::frames::read_png(&files[0].1).map_err(fail)?;
            sized(&first, c.images.image_px, &files[0].1.display().to_string())?;
        }
        FrameSource::V4l2(dev) => {
            if let Some(why) = crate::frames::v4l2_refused(&dev) {
                return Err(fail(why));
            }
        }
    }
    let cal = calibration(c)?;
    let [w, h] = c.images.image_px.map(|v| f64::from(v) - 1.0);
    let seen = [[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]].map(|p| cal.belt_of(p)[0]);
    let last = seen.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if last > window_mm[0] {
        return Err(fail(format!(
            "the camera sees the belt up to {last:.0} mm along it (its calibration's frame \
             corners): upstream of the robot, it must end by the window's start \
             (conveyor.window_mm starts at {} mm)",
            window_mm[0]
        )));
    }
    detector(c).map(|_| ())
}

/// `img` if it is `size`, else why not (`what` names it).
fn sized(img: &GrayImage, size: [u32; 2], what: &str) -> Result<(), CameraError> {
    if img.dimensions() == (size[0], size[1]) {
        return Ok(());
    }
    Err(CameraError {
        backend: "images",
        reason: format!(
            "{what}: a {}×{} frame, camera.image_px is {}×{}",
            img.width(),
            img.height(),
            size[0],
            size[1]
        ),
    })
}

/// The detector of `[camera]`: its settings, its calibration, the camera's centre from the
/// calibration and `intrinsics` (for the parallax of the parts' tops; refused when the two
/// disagree and the parts have a height).
pub fn detector(c: &CameraSettings) -> Result<Detector, CameraError> {
    let d = Detector::new(detect_settings(c), calibration(c)?, Some(c.images.intrinsics));
    if d.camera_mm().is_none() && c.part_height_mm > 0.0 {
        return Err(CameraError {
            backend: "images",
            reason: "the calibration is not a view a pinhole camera of camera.intrinsics \
                     gives: set camera.intrinsics to the camera's [fx, fy, cx, cy] (the \
                     parallax of the parts' tops needs its centre), or recalibrate"
                .into(),
        });
    }
    Ok(d)
}

/// The calibration of `[camera]`: its file, or (no file, frames drawn by the simulation)
/// one fitted to a target the simulated camera draws.
pub fn calibration(c: &CameraSettings) -> Result<Calibration, CameraError> {
    let fail = |reason: String| CameraError { backend: "images", reason };
    if let Some(file) = &c.images.calibration {
        let cal = Calibration::load(file).map_err(|e| fail(e.to_string()))?;
        if cal.image_px != c.images.image_px {
            return Err(fail(format!(
                "{}: calibrated for {}×{} frames, camera.image_px is {}×{}",
                file.display(),
                cal.image_px[0],
                cal.image_px[1],
                c.images.image_px[0],
                c.images.image_px[1]
            )));
        }
        return Ok(cal);
    }
    let model = camera_model(&c.images);
    let target = target_in_view(&model);
    let frame = render::target_frame(&model, &target, &sim_look(&c.images, 0));
    let dots = qmarc_vision::grid::find(&frame, target.grid, target.pitch_mm, target.origin_mm)
        .map_err(|e| fail(format!("the simulated camera's own target: {e}")))?;
    Calibration::fit(&dots.pixels, &dots.belt, model.size_px).map_err(|e| fail(e.to_string()))
}

/// What `model` sees of the belt's surface: its along and across spans, mm.
pub fn view_mm(model: &CameraModel) -> [[f64; 2]; 2] {
    let [w, h] = model.size_px.map(|v| f64::from(v) - 1.0);
    let corners: Vec<[f64; 2]> = [[0.0, 0.0], [w, 0.0], [0.0, h], [w, h]]
        .iter()
        .filter_map(|&p| model.belt_of(p, 0.0))
        .collect();
    [0, 1].map(|k| {
        corners
            .iter()
            .fold([f64::INFINITY, f64::NEG_INFINITY], |[lo, hi], c| [lo.min(c[k]), hi.max(c[k])])
    })
}

/// A dot target filling about 60 % of what `model` sees of the belt, 8 pitches (whole mm)
/// across its narrower side.
pub fn target_in_view(model: &CameraModel) -> Target {
    let [[a0, a1], [c0, c1]] = view_mm(model);
    let (along, across) = (0.6 * (a1 - a0), 0.6 * (c1 - c0));
    // Whole millimetres: numbers a user types.
    let pitch = (along.min(across) / 8.0).floor().max(1.0);
    let grid = [(along / pitch).floor() as u32 + 1, (across / pitch).floor() as u32 + 1];
    let centre = [(a0 + a1) / 2.0, (c0 + c1) / 2.0];
    let origin_mm = [
        (centre[0] - f64::from(grid[0] - 1) * pitch / 2.0).round(),
        (centre[1] - f64::from(grid[1] - 1) * pitch / 2.0).round(),
    ];
    Target {
        grid,
        pitch_mm: pitch,
        origin_mm,
        dot_mm: 0.3 * pitch,
        origin_scale: render::ORIGIN_DOT_SCALE,
    }
}

/// Frames from their source.
enum Frames {
    /// Drawn from the simulated world (whose timing, belt and parts it is).
    Sim { world: Box<SimCamera>, model: CameraModel, view_mm: [f64; 2], truth: Vec<TruePart> },
    /// PNG files, in the order of their exposures.
    Dir { files: Vec<(u64, PathBuf)>, next: usize, start_ns: u64 },
    /// A Video4Linux2 camera, and its frames so far.
    #[cfg(feature = "v4l2")]
    Device { camera: crate::v4l2::V4l2Frames, number: u64 },
}

/// The frames of the V4L2 camera at `dev`, streaming `size` frames.
#[cfg(feature = "v4l2")]
fn device(dev: &std::path::Path, size: [u32; 2], rate_hz: f64) -> Result<Frames, String> {
    if let Some(why) = crate::frames::v4l2_refused(dev) {
        return Err(why);
    }
    Ok(Frames::Device { camera: crate::v4l2::V4l2Frames::open(dev, size, rate_hz)?, number: 0 })
}

/// A build without V4L2 capture: the device refused, saying why.
#[cfg(not(feature = "v4l2"))]
fn device(dev: &std::path::Path, _size: [u32; 2], _rate_hz: f64) -> Result<Frames, String> {
    Err(crate::frames::v4l2_refused(dev).unwrap_or_default())
}

/// The camera that finds parts in frames.
pub struct ImagesCamera {
    frames: Frames,
    detector: Detector,
    settings: CameraSettings,
    found: Vec<Detection>,
}

impl ImagesCamera {
    /// The camera of the run `spec`.
    pub fn of(spec: &RunSpec) -> Result<ImagesCamera, CameraError> {
        let c = &spec.settings.camera;
        let fail = |reason: String| CameraError { backend: "images", reason };
        let frames = match c.images.frame_source() {
            FrameSource::Sim => {
                let model = camera_model(&c.images);
                // What the camera sees along the belt, and a part's length either side.
                let [[lo, hi], _] = view_mm(&model);
                let reach = c.images.sim_part_mm[0];
                Frames::Sim {
                    world: Box::new(SimCamera::of(spec)),
                    model,
                    view_mm: [lo - reach, hi + reach],
                    truth: Vec::new(),
                }
            }
            FrameSource::Dir(dir) => Frames::Dir {
                files: crate::frames::in_folder(&dir).map_err(fail)?,
                next: 0,
                start_ns: 0,
            },
            FrameSource::V4l2(dev) => device(&dev, c.images.image_px, c.rate_hz).map_err(fail)?,
        };
        let detector = detector(c)?;
        Ok(ImagesCamera { frames, detector, settings: c.clone(), found: Vec::new() })
    }

    /// The next frame, its exposure, and the belt count latched then (if the source has one).
    fn next_image(
        &mut self,
        stop: &AtomicBool,
    ) -> Result<Option<(GrayImage, Frame, Option<i64>)>, CameraError> {
        let i = &self.settings.images;
        match &mut self.frames {
            Frames::Sim { world, model, view_mm, truth } => {
                let Some(number) = world.wait_next(stop) else { return Ok(None) };
                let (frame, counts) = world.truth(number, *view_mm, truth);
                let h = self.settings.part_height_mm;
                let parts: Vec<PartShape> = truth
                    .iter()
                    .map(|p| PartShape {
                        at_mm: [p.belt_mm, p.across_mm],
                        angle_rad: p.angle_rad,
                        size_mm: i.sim_part_mm,
                        height_mm: h,
                    })
                    .collect();
                let look = sim_look(i, self.settings.seed ^ (frame.number << 20));
                Ok(Some((render::belt_frame(model, &parts, &look), frame, Some(counts))))
            }
            #[cfg(feature = "v4l2")]
            Frames::Device { camera, number } => loop {
                if stop.load(std::sync::atomic::Ordering::Acquire) {
                    return Ok(None);
                }
                let next = camera
                    .next_frame(stop)
                    .map_err(|reason| CameraError { backend: "images", reason })?;
                if let Some((img, exposure_ns)) = next {
                    *number += 1;
                    return Ok(Some((img, Frame { number: *number - 1, exposure_ns }, None)));
                }
            },
            Frames::Dir { files, next, start_ns } => {
                let Some((exposure, path)) = files.get(*next).cloned() else {
                    // Every frame replayed: the camera waits for its stop.
                    crate::sim::wait_until(stop, u64::MAX);
                    return Ok(None);
                };
                if *next == 0 {
                    *start_ns = qmarc_timer::clock::monotonic_now_ns();
                }
                // Replayed at their pace, from now.
                let at = *start_ns + (exposure - files[0].0);
                if !crate::sim::wait_until(stop, at) {
                    return Ok(None);
                }
                *next += 1;
                let img = crate::frames::read_png(&path)
                    .map_err(|reason| CameraError { backend: "images", reason })?;
                sized(&img, i.image_px, &path.display().to_string())?;
                Ok(Some((img, Frame { number: *next as u64 - 1, exposure_ns: at }, None)))
            }
        }
    }
}

impl CameraBackend for ImagesCamera {
    fn name(&self) -> &'static str {
        "images"
    }

    fn next_frame(
        &mut self,
        out: &mut Vec<PartDetection>,
        stop: &AtomicBool,
    ) -> Result<Option<Frame>, CameraError> {
        let Some((img, frame, counts)) = self.next_image(stop)? else { return Ok(None) };
        self.detector.detect(&img, &mut self.found);
        out.clear();
        let in_frame = self.found.len() as u32;
        out.extend(self.found.iter().map(|d| PartDetection {
            frame: frame.number,
            exposure_ns: frame.exposure_ns,
            latched_counts: counts.unwrap_or(0),
            belt_mm: d.belt_mm,
            across_mm: d.across_mm,
            angle_rad: d.angle_deg.to_radians(),
            flags: if counts.is_some() { PartDetection::LATCHED } else { 0 },
            in_frame,
        }));
        Ok(Some(frame))
    }
}
