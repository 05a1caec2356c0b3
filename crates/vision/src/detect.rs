//! [`Detector`]: the parts in a frame of the belt, in belt coordinates. The belt's level is
//! the frame's most common gray (a belt is mostly belt); parts are the connected regions
//! brighter (or darker, `polarity`) than it by more than `threshold`; a region is a part when
//! its area is within `area_px` and it does not touch the frame's border (then it may go on
//! beyond it: the next frame sees it whole). Two parts that touch make one region too big:
//! skipped, never reported as one wrong part. A part's position is its region's centroid,
//! its orientation the principal axis of the region's second moments, both taken to the
//! belt by the [`Calibration`] — at the part's top face, above the belt, where the camera's
//! centre is known (the parallax of a part `h` tall seen from `H` above: the belt point
//! moves toward the camera's foot by h/H of its distance).

use crate::blobs::{Labeller, Polarity, Region};
use crate::calib::Calibration;
use image::GrayImage;

/// What a detector looks for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DetectSettings {
    /// Parts brighter or darker than the belt.
    pub polarity: Polarity,
    /// How far from the belt's level a part's pixel is, gray levels.
    pub threshold: u8,
    /// A part's area in the frame, px: the smallest and the largest.
    pub area_px: [u32; 2],
    /// A part's top above the belt, mm.
    pub part_height_mm: f64,
}

/// A part found.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// Along the belt, mm.
    pub belt_mm: f64,
    /// Across it, mm.
    pub across_mm: f64,
    /// Its axis from the belt's travel toward the across direction, degrees in (−90, 90].
    pub angle_deg: f64,
    /// Its region's area, px.
    pub area_px: u32,
}

/// What a frame held besides its parts.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Tally {
    /// The belt's gray level.
    pub belt_level: u8,
    /// Regions smaller than `area_px` (noise, specks).
    pub too_small: u32,
    /// Regions larger (parts touching each other, a hand, a shadow).
    pub too_big: u32,
    /// Regions at the frame's border.
    pub at_border: u32,
    /// Whether the threshold lay beyond the gray scale (the belt's level within `threshold`
    /// of 0 or 255 the wrong way): no pixel could be a part's.
    pub saturated: bool,
}

/// Finds parts, frame after frame (its buffers are kept).
#[derive(Debug)]
pub struct Detector {
    settings: DetectSettings,
    calibration: Calibration,
    /// The camera's centre on the belt, mm (its height the third), for the parallax.
    camera_mm: Option<[f64; 3]>,
    labeller: Labeller,
    regions: Vec<Region>,
}

impl Detector {
    /// A detector of `settings` through `calibration`, for a camera of `intrinsics`
    /// (`[fx, fy, cx, cy]` px; `None`: parts taken as lying flat on the belt).
    pub fn new(
        settings: DetectSettings,
        calibration: Calibration,
        intrinsics: Option<[f64; 4]>,
    ) -> Detector {
        let camera_mm = intrinsics.and_then(|k| calibration.camera_centre(k));
        Detector {
            settings,
            calibration,
            camera_mm,
            labeller: Labeller::default(),
            regions: Vec::new(),
        }
    }

    /// The camera's centre the calibration gives, belt coordinates, mm.
    pub fn camera_mm(&self) -> Option<[f64; 3]> {
        self.camera_mm
    }

    /// The parts in `img`, into `out` (cleared first), in the order of their first pixel.
    pub fn detect(&mut self, img: &GrayImage, out: &mut Vec<Detection>) -> Tally {
        let s = self.settings;
        let level = belt_level(img);
        let (threshold, saturated) = match s.polarity {
            Polarity::Bright => level.overflowing_add(s.threshold),
            Polarity::Dark => level.overflowing_sub(s.threshold),
        };
        let threshold = if saturated {
            match s.polarity {
                Polarity::Bright => u8::MAX,
                Polarity::Dark => 0,
            }
        } else {
            threshold
        };
        self.labeller.regions(img, s.polarity, threshold, &mut self.regions);
        out.clear();
        let mut tally = Tally { belt_level: level, saturated, ..Tally::default() };
        for r in &self.regions {
            if r.at_border {
                tally.at_border += 1;
            } else if r.area < s.area_px[0] {
                tally.too_small += 1;
            } else if r.area > s.area_px[1] {
                tally.too_big += 1;
            } else {
                out.push(self.on_belt(r));
            }
        }
        tally
    }

    /// Region `r` as a part on the belt: its centroid there, and its axis — the region's
    /// second moments carried to the belt by the map's local Jacobian (a tilted or
    /// anisotropic view turns a frame's axes), their principal axis.
    fn on_belt(&self, r: &Region) -> Detection {
        let c = r.centroid;
        let at = self.top(c);
        let (dx, dy) = (self.top([c[0] + 1.0, c[1]]), self.top([c[0], c[1] + 1.0]));
        let j = [[dx[0] - at[0], dy[0] - at[0]], [dx[1] - at[1], dy[1] - at[1]]];
        let [xx, yy, xy] = r.covariance;
        let cov = [[xx, xy], [xy, yy]];
        // (J C Jᵀ)[a][b].
        let m = |a: usize, b: usize| {
            (0..2).map(|k| (0..2).map(|l| j[a][k] * cov[k][l] * j[b][l]).sum::<f64>()).sum::<f64>()
        };
        let mut angle = 0.5 * f64::atan2(2.0 * m(0, 1), m(0, 0) - m(1, 1)).to_degrees();
        if angle <= -90.0 {
            angle += 180.0;
        }
        Detection { belt_mm: at[0], across_mm: at[1], angle_deg: angle, area_px: r.area }
    }

    /// The point of a part's top face pixel `p` sees.
    fn top(&self, p: [f64; 2]) -> [f64; 2] {
        let b = self.calibration.belt_of(p);
        match self.camera_mm {
            Some(c) => {
                let f = 1.0 - self.settings.part_height_mm / c[2];
                [c[0] + (b[0] - c[0]) * f, c[1] + (b[1] - c[1]) * f]
            }
            None => b,
        }
    }
}

/// The belt's gray level in `img`: the most common (over every other pixel of every other
/// row, the histogram smoothed over five levels).
pub fn belt_level(img: &GrayImage) -> u8 {
    let mut hist = [0u32; 256];
    let w = img.width() as usize;
    for row in img.as_raw().chunks_exact(w).step_by(2) {
        for v in row.iter().step_by(2) {
            hist[*v as usize] += 1;
        }
    }
    let smooth = |v: usize| (v.saturating_sub(2)..=(v + 2).min(255)).map(|k| hist[k]).sum::<u32>();
    (0..256).max_by_key(|&v| (smooth(v), std::cmp::Reverse(v))).unwrap_or(0) as u8
}
