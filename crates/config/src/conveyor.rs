//! `[conveyor]` and `[camera]`: the belt the robot picks from and the camera upstream of it
//! (issue 44). Belt coordinates are mm along the belt's travel from its coordinate 0
//! (`origin_mm`), across it along `direction` turned +90° about z.

use crate::ConfigLoadError;
use crate::source::{S, Source, non_negative, num, one_of, positive_at_most, span_of, within};
use serde::{Deserialize, Serialize};

mod images;
pub use images::{FrameSource, ImageSettings, POLARITIES};

/// Fastest belt, mm/s.
pub const MAX_BELT_MM_S: f64 = 5_000.0;
/// Most speed changes of a simulated belt.
pub const MAX_SPEED_STEPS: usize = 1_000;
/// Farthest a belt coordinate, a point or a window may be from the robot, mm.
pub const MAX_BELT_MM: f64 = 100_000.0;
/// How far from 1 the length of `direction` may be (a rounding, not a typo).
const UNIT_SLACK: f64 = 1e-6;

/// The belt.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ConveyorSettings {
    /// The belt's travel in the robot frame: a horizontal unit vector.
    pub direction: [f64; 3],
    /// The robot-frame point of belt coordinate 0 on the belt's centre line, on its surface,
    /// mm.
    pub origin_mm: [f64; 3],
    /// The belt encoder, mm per count.
    pub mm_per_count: f64,
    /// The 626 counter that reads the belt encoder (0‥5).
    pub counter_channel: u32,
    /// The simulated belt's speed, mm/s.
    pub speed_mm_s: f64,
    /// The simulated belt's speed changes: at `t_s` (s from the session's start) to `mm_s`,
    /// times rising.
    pub speed_steps: Vec<[f64; 2]>,
    /// How fast the simulated belt changes speed, mm/s².
    pub acceleration_mm_s2: f64,
    /// The belt coordinates between which a part may be picked, mm: a part past the end
    /// unpicked is missed.
    pub window_mm: [f64; 2],
    /// Where a picked part is put down, robot frame, mm.
    pub place_mm: [f64; 3],
    /// How long `qmarc-starter conveyor` runs the belt and picks, s (`--seconds`).
    #[serde(default = "default_run_s")]
    pub run_s: f64,
}

/// `conveyor.run_s`'s default: a minute, the benchmark.
fn default_run_s() -> f64 {
    60.0
}

impl Default for ConveyorSettings {
    fn default() -> ConveyorSettings {
        ConveyorSettings {
            direction: [1.0, 0.0, 0.0],
            origin_mm: [-400.0, 0.0, -680.0],
            mm_per_count: 0.05,
            counter_channel: 3,
            speed_mm_s: 500.0,
            speed_steps: Vec::new(),
            acceleration_mm_s2: 2_000.0,
            window_mm: [300.0, 500.0],
            place_mm: [0.0, 150.0, -600.0],
            run_s: default_run_s(),
        }
    }
}

impl ConveyorSettings {
    /// The across-belt unit vector: `direction` turned +90° about z, `(−dy, dx, 0)`.
    pub fn across(&self) -> [f64; 3] {
        [-self.direction[1], self.direction[0], 0.0]
    }

    /// The robot-frame point, mm, of belt coordinate `belt_mm`, `across_mm` across, `up_mm`
    /// above the belt's surface.
    pub fn point_mm(&self, belt_mm: f64, across_mm: f64, up_mm: f64) -> [f64; 3] {
        let (d, a, o) = (self.direction, self.across(), self.origin_mm);
        std::array::from_fn(|i| {
            o[i] + belt_mm * d[i] + across_mm * a[i] + if i == 2 { up_mm } else { 0.0 }
        })
    }
}

/// The camera upstream of the robot, and the parts its simulation sees.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraSettings {
    /// Where detections come from: `sim` (the simulated belt's parts).
    pub backend: String,
    /// The belt coordinates it sees, mm: upstream of the conveyor's window.
    pub field_mm: [f64; 2],
    /// Frames a second.
    pub rate_hz: f64,
    /// From the exposure to the detection published, s.
    pub latency_s: f64,
    /// The standard deviation of a detection's position, mm.
    pub noise_mm: f64,
    /// A part's height: its grip point is its top centre, mm above the belt.
    pub part_height_mm: f64,
    /// Simulated parts a minute.
    pub parts_per_min: f64,
    /// Simulated parts lie uniformly within ±spread/2 across the belt, mm.
    pub spread_mm: f64,
    /// The simulation's random seed.
    pub seed: u64,
    /// An `images` camera: its frames, geometry, detection and calibration.
    pub images: ImageSettings,
}

impl Default for CameraSettings {
    fn default() -> CameraSettings {
        CameraSettings {
            backend: "sim".into(),
            field_mm: [50.0, 250.0],
            rate_hz: 30.0,
            latency_s: 0.02,
            noise_mm: 0.1,
            part_height_mm: 10.0,
            parts_per_min: 120.0,
            spread_mm: 100.0,
            seed: 1,
            images: ImageSettings::default(),
        }
    }
}

/// The camera backends there are.
pub const CAMERA_BACKENDS: &[&str] = &["sim", "images"];

/// A list of `N` finite numbers within ±[`MAX_BELT_MM`].
fn numbers<const N: usize>(v: &[f64]) -> Result<[f64; N], String> {
    if v.len() != N {
        return Err(format!("{N} numbers, found {}", v.len()));
    }
    match v.iter().find(|x| !(x.is_finite() && x.abs() <= MAX_BELT_MM)) {
        Some(bad) => {
            Err(format!("must be finite numbers within ±{MAX_BELT_MM}, found {}", num(*bad)))
        }
        None => Ok(std::array::from_fn(|i| v[i])),
    }
}

/// A `[start, end]` range, start < end.
fn range(v: &[f64]) -> Result<[f64; 2], String> {
    let r = numbers::<2>(v)?;
    if r[0] < r[1] {
        Ok(r)
    } else {
        Err(format!("[start, end] with start < end, found [{}, {}]", num(r[0]), num(r[1])))
    }
}

/// A horizontal unit vector.
fn direction(v: &[f64]) -> Result<[f64; 3], String> {
    let d = numbers::<3>(v)?;
    let length = d.iter().map(|x| x * x).sum::<f64>().sqrt();
    if (length - 1.0).abs() > UNIT_SLACK {
        return Err(format!("must be a unit vector (length 1), found length {}", num(length)));
    }
    if d[2] != 0.0 {
        return Err(format!("the belt is horizontal: its z must be 0, found {}", num(d[2])));
    }
    Ok(d)
}

/// Speed steps: `[t_s, mm_s]` pairs, times ≥ 0 and rising, speeds within the belt's.
fn steps(v: &[Vec<f64>]) -> Result<Vec<[f64; 2]>, String> {
    if v.len() > MAX_SPEED_STEPS {
        return Err(format!("at most {MAX_SPEED_STEPS} steps, found {}", v.len()));
    }
    let mut out: Vec<[f64; 2]> = Vec::with_capacity(v.len());
    for (k, pair) in v.iter().enumerate() {
        let [t, s] = numbers::<2>(pair).map_err(|e| format!("step {}: [t_s, mm_s]: {e}", k + 1))?;
        if t < 0.0 || out.last().is_some_and(|l| t <= l[0]) {
            return Err(format!("step {}: times are ≥ 0 and rising, found {}", k + 1, num(t)));
        }
        speed()(&s).map_err(|e| format!("step {}: mm_s {e}", k + 1))?;
        out.push([t, s]);
    }
    Ok(out)
}

/// A belt speed: 0‥[`MAX_BELT_MM_S`].
fn speed() -> impl FnOnce(&f64) -> Result<(), String> {
    within(0.0, MAX_BELT_MM_S, "mm/s")
}

/// A conveyor session's length: 0.1 s‥a day.
fn run_length() -> impl FnOnce(&f64) -> Result<(), String> {
    within(0.1, 86_400.0, "s")
}

/// The camera's parts a minute: 0‥6000.
fn part_rate() -> impl FnOnce(&f64) -> Result<(), String> {
    within(0.0, 6_000.0, "a minute")
}

impl crate::Settings {
    /// Overrides the simulated belt's speed (`--belt-mm-s`).
    pub fn set_belt_speed(&mut self, mm_s: f64) -> Result<(), ConfigLoadError> {
        speed()(&mm_s)
            .map_err(|message| ConfigLoadError::Override { flag: "--belt-mm-s", message })?;
        self.conveyor.speed_mm_s = mm_s;
        Ok(())
    }

    /// Overrides the simulated camera's parts a minute (`--parts-per-min`).
    pub fn set_parts_per_min(&mut self, n: f64) -> Result<(), ConfigLoadError> {
        part_rate()(&n)
            .map_err(|message| ConfigLoadError::Override { flag: "--parts-per-min", message })?;
        self.camera.parts_per_min = n;
        Ok(())
    }

    /// Overrides the camera's backend (`--camera`): `sim`, or `images` (whose frames from a
    /// device or a folder need `camera.calibration`).
    pub fn set_camera_backend(&mut self, backend: &str) -> Result<(), ConfigLoadError> {
        let refused = |message| ConfigLoadError::Override { flag: "--camera", message };
        one_of(CAMERA_BACKENDS, "camera backend")(&backend.to_string()).map_err(refused)?;
        let i = &self.camera.images;
        if backend == "images" && i.calibration.is_none() && i.frame_source() != FrameSource::Sim {
            return Err(refused(format!(
                "frames from `{}` need a calibration: set camera.calibration (docs/vision.md)",
                i.source
            )));
        }
        self.camera.backend = backend.to_string();
        Ok(())
    }

    /// Overrides the conveyor session's length (`--seconds`).
    pub fn set_conveyor_seconds(&mut self, s: f64) -> Result<(), ConfigLoadError> {
        run_length()(&s)
            .map_err(|message| ConfigLoadError::Override { flag: "--seconds", message })?;
        self.conveyor.run_s = s;
        Ok(())
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawConveyor {
    direction: S<Vec<f64>>,
    origin_mm: S<Vec<f64>>,
    mm_per_count: S<f64>,
    counter_channel: S<i64>,
    speed_mm_s: S<f64>,
    speed_steps: S<Vec<Vec<f64>>>,
    acceleration_mm_s2: S<f64>,
    window_mm: S<Vec<f64>>,
    place_mm: S<Vec<f64>>,
    run_s: S<f64>,
}

impl RawConveyor {
    /// Checked, its counter none of the motors' (`motor_counters`, `s626.counter_channels`).
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        motor_counters: &[u32],
    ) -> Result<ConveyorSettings, ConfigLoadError> {
        let d = ConveyorSettings::default();
        let conveyor = ConveyorSettings {
            direction: src
                .read(&self.direction, "conveyor.direction", d.direction, |v| direction(v))?,
            origin_mm: src
                .read(&self.origin_mm, "conveyor.origin_mm", d.origin_mm, |v| numbers::<3>(v))?,
            mm_per_count: src.take(
                &self.mm_per_count,
                "conveyor.mm_per_count",
                d.mm_per_count,
                positive_at_most(1_000.0, "mm"),
            )?,
            counter_channel: src.int(
                &self.counter_channel,
                "conveyor.counter_channel",
                i64::from(d.counter_channel),
                0,
                5,
            )? as u32,
            speed_mm_s: src.take(&self.speed_mm_s, "conveyor.speed_mm_s", d.speed_mm_s, speed())?,
            speed_steps: src.read(
                &self.speed_steps,
                "conveyor.speed_steps",
                d.speed_steps,
                |v| steps(v),
            )?,
            acceleration_mm_s2: src.take(
                &self.acceleration_mm_s2,
                "conveyor.acceleration_mm_s2",
                d.acceleration_mm_s2,
                positive_at_most(100_000.0, "mm/s²"),
            )?,
            window_mm: src
                .read(&self.window_mm, "conveyor.window_mm", d.window_mm, |v| range(v))?,
            place_mm: src
                .read(&self.place_mm, "conveyor.place_mm", d.place_mm, |v| numbers::<3>(v))?,
            run_s: src.take(&self.run_s, "conveyor.run_s", d.run_s, run_length())?,
        };
        if motor_counters.contains(&conveyor.counter_channel) {
            return Err(src.invalid(
                span_of(&self.counter_channel),
                "conveyor.counter_channel",
                format!(
                    "counter {} reads a motor (s626.counter_channels = {motor_counters:?}): the \
                     belt's encoder needs a counter of its own",
                    conveyor.counter_channel
                ),
            ));
        }
        Ok(conveyor)
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawCamera {
    backend: S<String>,
    field_mm: S<Vec<f64>>,
    rate_hz: S<f64>,
    latency_s: S<f64>,
    noise_mm: S<f64>,
    part_height_mm: S<f64>,
    parts_per_min: S<f64>,
    spread_mm: S<f64>,
    seed: S<i64>,
    source: S<String>,
    pose: S<Vec<f64>>,
    intrinsics: S<Vec<f64>>,
    image_px: S<Vec<i64>>,
    polarity: S<String>,
    threshold: S<i64>,
    area_px: S<Vec<i64>>,
    calibration: S<String>,
    sim_part_mm: S<Vec<f64>>,
    sim_gray: S<Vec<f64>>,
    sim_noise_gray: S<f64>,
    sim_k1: S<f64>,
}

impl RawCamera {
    /// Checked, its field upstream of `conveyor`'s window.
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        conveyor: &ConveyorSettings,
    ) -> Result<CameraSettings, ConfigLoadError> {
        let d = CameraSettings::default();
        let at_most = |hi: f64, unit: &'static str| {
            move |v: &f64| {
                non_negative(v)?;
                if *v <= hi {
                    Ok(())
                } else {
                    Err(format!("must be ≤ {hi} {unit}, found {}", num(*v)))
                }
            }
        };
        let camera = CameraSettings {
            backend: src.take(&self.backend, "camera.backend", d.backend, |v| {
                one_of(CAMERA_BACKENDS, "camera backend")(v)
            })?,
            field_mm: src.read(&self.field_mm, "camera.field_mm", d.field_mm, |v| range(v))?,
            rate_hz: src.take(
                &self.rate_hz,
                "camera.rate_hz",
                d.rate_hz,
                positive_at_most(1_000.0, "Hz"),
            )?,
            latency_s: src.take(
                &self.latency_s,
                "camera.latency_s",
                d.latency_s,
                at_most(1.0, "s"),
            )?,
            noise_mm: src.take(
                &self.noise_mm,
                "camera.noise_mm",
                d.noise_mm,
                at_most(10.0, "mm"),
            )?,
            part_height_mm: src.take(
                &self.part_height_mm,
                "camera.part_height_mm",
                d.part_height_mm,
                at_most(500.0, "mm"),
            )?,
            parts_per_min: src.take(
                &self.parts_per_min,
                "camera.parts_per_min",
                d.parts_per_min,
                part_rate(),
            )?,
            spread_mm: src.take(
                &self.spread_mm,
                "camera.spread_mm",
                d.spread_mm,
                at_most(2_000.0, "mm"),
            )?,
            seed: src.take(&self.seed, "camera.seed", d.seed as i64, |v| {
                if *v >= 0 { Ok(()) } else { Err(format!("must be ≥ 0, found {v}")) }
            })? as u64,
            images: self.images(src)?,
        };
        if camera.backend == "images"
            && camera.images.calibration.is_none()
            && camera.images.frame_source() != FrameSource::Sim
        {
            return Err(src.invalid(
                span_of(&self.source),
                "camera.source",
                format!(
                    "frames from `{}` need a calibration: set camera.calibration to the file \
                     `qmarc-camera calibrate --out` wrote (docs/vision.md)",
                    camera.images.source
                ),
            ));
        }
        if camera.field_mm[1] > conveyor.window_mm[0] {
            return Err(src.invalid(
                span_of(&self.field_mm),
                "camera.field_mm",
                format!(
                    "the camera sees the belt upstream of the robot: its field must end by the \
                     window's start (conveyor.window_mm starts at {} mm), found {} mm",
                    num(conveyor.window_mm[0]),
                    num(camera.field_mm[1])
                ),
            ));
        }
        Ok(camera)
    }
}

#[cfg(test)]
mod tests;
