//! `[camera]` of `backend = "images"` (issue 46): where the frames come from (`source`), the
//! camera's geometry (`pose`, `intrinsics`, `image_px`), what a part looks like in a frame
//! (`polarity`, `threshold`, `area_px`), the calibration from pixels to the belt
//! (`calibration`), and how the simulated camera draws its frames (`sim_*`).

use super::RawCamera;
use crate::ConfigLoadError;
use crate::source::{Source, num, one_of, within};
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Where an `images` camera's frames come from.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum FrameSource {
    /// Drawn from the simulated belt and its parts.
    Sim,
    /// PNG files `<exposure_ns>.png` in a folder, in order.
    Dir(PathBuf),
    /// A Video4Linux2 device.
    V4l2(PathBuf),
}

impl FrameSource {
    /// `sim`, `dir:PATH` or `v4l2:/dev/videoN`.
    pub fn parse(s: &str) -> Result<FrameSource, String> {
        let bad = || format!("`sim`, `dir:PATH` or `v4l2:/dev/videoN`, found `{s}`");
        match s.split_once(':') {
            None if s == "sim" => Ok(FrameSource::Sim),
            Some(("dir", p)) if !p.is_empty() => Ok(FrameSource::Dir(p.into())),
            Some(("v4l2", p)) if !p.is_empty() => Ok(FrameSource::V4l2(p.into())),
            _ => Err(bad()),
        }
    }
}

/// An `images` camera.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ImageSettings {
    /// `sim`, `dir:PATH` or `v4l2:/dev/videoN` ([`FrameSource::parse`]).
    pub source: String,
    /// `[along, across, height]` mm of the camera's centre in belt coordinates, then
    /// `[yaw, pitch, roll]` degrees (yaw 90: the image's x across the belt, its y along the
    /// travel).
    pub pose: [f64; 6],
    /// `[fx, fy, cx, cy]`, px.
    pub intrinsics: [f64; 4],
    /// A frame's columns and rows.
    pub image_px: [u32; 2],
    /// Parts `bright` or `dark` against the belt.
    pub polarity: String,
    /// A part's pixels differ from the belt's level by more than this, gray levels.
    pub threshold: u8,
    /// A part's area in a frame, px: `[min, max]`.
    pub area_px: [u32; 2],
    /// The calibration file (`qmarc-camera calibrate --out`); none: the simulated camera
    /// calibrates itself from a target it draws (another source needs one).
    pub calibration: Option<PathBuf>,
    /// The simulated parts' length and width, mm.
    pub sim_part_mm: [f64; 2],
    /// The simulated belt's and parts' gray levels.
    pub sim_gray: [f64; 2],
    /// The simulated sensor's noise, gray levels (standard deviation).
    pub sim_noise_gray: f64,
    /// The simulated lens' radial distortion k1 (negative: barrel).
    pub sim_k1: f64,
}

impl Default for ImageSettings {
    /// A 640×480 camera 800 mm above the default field's centre, 0.5 mm a pixel on the
    /// belt, looking straight down with the belt running down the image; bright parts of
    /// 40 × 16 mm (about 2600 px) on a dark belt.
    fn default() -> ImageSettings {
        ImageSettings {
            source: "sim".into(),
            pose: [150.0, 0.0, 800.0, 90.0, 0.0, 0.0],
            intrinsics: [1600.0, 1600.0, 319.5, 239.5],
            image_px: [640, 480],
            polarity: "bright".into(),
            threshold: 70,
            area_px: [1200, 4000],
            calibration: None,
            sim_part_mm: [40.0, 16.0],
            sim_gray: [60.0, 200.0],
            sim_noise_gray: 4.0,
            sim_k1: 0.0,
        }
    }
}

impl ImageSettings {
    /// Where the frames come from.
    pub fn frame_source(&self) -> FrameSource {
        FrameSource::parse(&self.source).unwrap_or(FrameSource::Sim)
    }
}

/// Polarities.
pub const POLARITIES: &[&str] = &["bright", "dark"];

/// `N` finite numbers.
fn finite<const N: usize>(v: &[f64]) -> Result<[f64; N], String> {
    if v.len() != N {
        return Err(format!("{N} numbers, found {}", v.len()));
    }
    match v.iter().find(|x| !x.is_finite()) {
        Some(bad) => Err(format!("must be finite numbers, found {}", num(*bad))),
        None => Ok(std::array::from_fn(|i| v[i])),
    }
}

/// `[min, max]` px, 1 ≤ min ≤ max ≤ `hi`.
fn px_range(v: &[i64], hi: i64) -> Result<[u32; 2], String> {
    match v {
        [lo, top] if 1 <= *lo && lo <= top && *top <= hi => Ok([*lo as u32, *top as u32]),
        _ => Err(format!("[min, max] with 1 ≤ min ≤ max ≤ {hi}, found {v:?}")),
    }
}

impl RawCamera {
    /// `[camera]`'s `images` settings, checked.
    pub(crate) fn images(&self, src: &Source<'_>) -> Result<ImageSettings, ConfigLoadError> {
        let d = ImageSettings::default();
        let image_px =
            src.read(&self.image_px, "camera.image_px", d.image_px, |v| match v.as_slice() {
                [w, h] if (16..=16_384).contains(w) && (16..=16_384).contains(h) => {
                    Ok([*w as u32, *h as u32])
                }
                _ => Err(format!("[columns, rows], each 16‥16384, found {v:?}")),
            })?;
        let pixels = i64::from(image_px[0]) * i64::from(image_px[1]);
        Ok(ImageSettings {
            source: src.take(&self.source, "camera.source", d.source, |v| {
                FrameSource::parse(v).map(|_| ())
            })?,
            pose: src.read(&self.pose, "camera.pose", d.pose, |v| {
                let p = finite::<6>(v)?;
                if p[2] <= 0.0 {
                    return Err(format!(
                        "the camera is above the belt: its height (the third \
                                        number) must be > 0 mm, found {}",
                        num(p[2])
                    ));
                }
                Ok(p)
            })?,
            intrinsics: src.read(&self.intrinsics, "camera.intrinsics", d.intrinsics, |v| {
                let k = finite::<4>(v)?;
                let [w, h] = image_px.map(|n| f64::from(n) - 1.0);
                if k[0] <= 0.0
                    || k[1] <= 0.0
                    || !(0.0..=w).contains(&k[2])
                    || !(0.0..=h).contains(&k[3])
                {
                    return Err(format!(
                        "[fx, fy, cx, cy] with fx, fy > 0 px and (cx, cy) in the frame \
                         (camera.image_px {}×{}), found {v:?}",
                        image_px[0], image_px[1]
                    ));
                }
                Ok(k)
            })?,
            image_px,
            polarity: src.take(&self.polarity, "camera.polarity", d.polarity, |v| {
                one_of(POLARITIES, "polarity")(v)
            })?,
            threshold: src.int(&self.threshold, "camera.threshold", d.threshold.into(), 1, 254)?
                as u8,
            area_px: src
                .read(&self.area_px, "camera.area_px", d.area_px, |v| px_range(v, pixels))?,
            calibration: src.read(&self.calibration, "camera.calibration", None, |v| {
                if v.is_empty() {
                    Err("a file's path, found none".into())
                } else {
                    Ok(Some(v.into()))
                }
            })?,
            sim_part_mm: src.read(&self.sim_part_mm, "camera.sim_part_mm", d.sim_part_mm, |v| {
                let s = finite::<2>(v)?;
                if s.iter().all(|x| (0.1..=2_000.0).contains(x)) {
                    Ok(s)
                } else {
                    Err(format!("[length, width], each 0.1‥2000 mm, found {v:?}"))
                }
            })?,
            sim_gray: src.read(&self.sim_gray, "camera.sim_gray", d.sim_gray, |v| {
                let g = finite::<2>(v)?;
                if g.iter().all(|x| (0.0..=255.0).contains(x)) {
                    Ok(g)
                } else {
                    Err(format!("[belt, part] gray levels, each 0‥255, found {v:?}"))
                }
            })?,
            sim_noise_gray: src.take(
                &self.sim_noise_gray,
                "camera.sim_noise_gray",
                d.sim_noise_gray,
                within(0.0, 100.0, "gray levels"),
            )?,
            sim_k1: src.take(&self.sim_k1, "camera.sim_k1", d.sim_k1, within(-0.5, 0.5, ""))?,
        })
    }
}
