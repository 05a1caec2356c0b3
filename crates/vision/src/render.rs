//! Frames drawn through a [`CameraModel`]: the belt with its parts (the simulated camera's
//! frames, and the tests' frames with known parts), and a calibration target lying on it.
//! Grayscale, 8 bits, with what a real frame has: the lens' distortion, light falling off
//! toward the corners, the sensor's noise, and edges that are partly covered pixels.
//!
//! A part is a box; its top face is what the camera sees of it (lit from above; its sides,
//! in shadow, look like the belt).

use crate::camera::CameraModel;
use image::GrayImage;

/// A part on the belt: a box of `size_mm` (length along its axis, width), `height_mm`
/// tall, its centre at `[along, across]` mm, its axis at `angle_rad` from the belt's travel
/// toward the across direction.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartShape {
    /// Its centre, belt coordinates, mm.
    pub at_mm: [f64; 2],
    /// Its axis from the belt's travel toward across, rad.
    pub angle_rad: f64,
    /// Length and width, mm.
    pub size_mm: [f64; 2],
    /// Its top above the belt, mm.
    pub height_mm: f64,
}

/// How the scene looks.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Look {
    /// The belt's gray level at the image's centre.
    pub belt: f64,
    /// A part's top face (brighter or darker than the belt).
    pub part: f64,
    /// The light in the image's corners, as a fraction of the centre's.
    pub corner_light: f64,
    /// The sensor's noise, gray levels (standard deviation).
    pub noise: f64,
    /// The noise's seed (each frame its own).
    pub seed: u64,
}

impl Default for Look {
    fn default() -> Look {
        Look { belt: 60.0, part: 200.0, corner_light: 0.8, noise: 4.0, seed: 1 }
    }
}

/// A calibration target: a white board with black dots `pitch_mm` apart in `grid` columns
/// (along the belt) and rows (across it), dot (0, 0) — the origin, `origin_scale` times as
/// wide as the others ([`ORIGIN_DOT_SCALE`] marks it) — at `origin_mm`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Target {
    /// Columns and rows.
    pub grid: [u32; 2],
    /// Between dots, mm.
    pub pitch_mm: f64,
    /// The origin dot's centre, belt coordinates, mm.
    pub origin_mm: [f64; 2],
    /// A dot's diameter, mm.
    pub dot_mm: f64,
    /// The origin dot's diameter over the others'.
    pub origin_scale: f64,
}

/// A target's dots' gray level (printed black).
const DOT_LEVEL: f64 = 20.0;

/// The origin dot's diameter over the others'.
pub const ORIGIN_DOT_SCALE: f64 = 1.5;

/// The belt seen by `camera` with `parts` on it.
pub fn belt_frame(camera: &CameraModel, parts: &[PartShape], look: &Look) -> GrayImage {
    let mut level = vec![look.belt; pixels(camera)];
    for p in parts {
        let (c, s) = (p.angle_rad.cos(), p.angle_rad.sin());
        let half = [p.size_mm[0] / 2.0, p.size_mm[1] / 2.0];
        let corners = [[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]].map(|[a, b]| {
            let (x, y) = (a * half[0], b * half[1]);
            [p.at_mm[0] + c * x - s * y, p.at_mm[1] + s * x + c * y, p.height_mm]
        });
        let Some(px) = corners.iter().map(|&q| camera.pixel_of(q)).collect::<Option<Vec<_>>>()
        else {
            continue;
        };
        let Some(centre) = camera.pixel_of([p.at_mm[0], p.at_mm[1], p.height_mm]) else {
            continue;
        };
        let soft = camera.mm_per_px(centre, p.height_mm);
        paint(camera, &mut level, &px, |q| {
            let Some(b) = camera.belt_of(q, p.height_mm) else { return 0.0 };
            let (dx, dy) = (b[0] - p.at_mm[0], b[1] - p.at_mm[1]);
            let d = box_distance([c * dx + s * dy, -s * dx + c * dy], half);
            coverage(d, soft) * (look.part - look.belt)
        });
    }
    finish(camera, &level, look)
}

/// Calibration target `t` lying on the belt seen by `camera`.
pub fn target_frame(camera: &CameraModel, t: &Target, look: &Look) -> GrayImage {
    let board = look.part.max(look.belt);
    let mut level = vec![look.belt; pixels(camera)];
    let span = [f64::from(t.grid[0] - 1) * t.pitch_mm, f64::from(t.grid[1] - 1) * t.pitch_mm];
    let margin = t.pitch_mm;
    let centre = [t.origin_mm[0] + span[0] / 2.0, t.origin_mm[1] + span[1] / 2.0];
    let half = [span[0] / 2.0 + margin, span[1] / 2.0 + margin];
    let corners = [[1.0, 1.0], [1.0, -1.0], [-1.0, 1.0], [-1.0, -1.0]]
        .map(|[a, b]| camera.pixel_of([centre[0] + a * half[0], centre[1] + b * half[1], 0.0]));
    let px: Vec<[f64; 2]> = corners.into_iter().flatten().collect();
    let soft = camera.mm_per_px([camera.intrinsics[2], camera.intrinsics[3]], 0.0);
    paint(camera, &mut level, &px, |q| {
        let Some(b) = camera.belt_of(q, 0.0) else { return 0.0 };
        let on_board = coverage(box_distance([b[0] - centre[0], b[1] - centre[1]], half), soft);
        let (u, v) = ((b[0] - t.origin_mm[0]) / t.pitch_mm, (b[1] - t.origin_mm[1]) / t.pitch_mm);
        let (i, j) = (
            u.round().clamp(0.0, span[0] / t.pitch_mm),
            v.round().clamp(0.0, span[1] / t.pitch_mm),
        );
        let scale = if i == 0.0 && j == 0.0 { t.origin_scale } else { 1.0 };
        let r = t.dot_mm / 2.0 * scale;
        let d = f64::hypot((u - i) * t.pitch_mm, (v - j) * t.pitch_mm) - r;
        let dot = coverage(d, soft);
        // The board over the belt, the dot's black over the board.
        on_board * ((board - look.belt) - dot * (board - DOT_LEVEL))
    });
    finish(camera, &level, look)
}

fn pixels(camera: &CameraModel) -> usize {
    camera.size_px[0] as usize * camera.size_px[1] as usize
}

/// Adds `delta(pixel)` to every pixel of the box around `corners` (px), two pixels wider.
fn paint(
    camera: &CameraModel,
    level: &mut [f64],
    corners: &[[f64; 2]],
    delta: impl Fn([f64; 2]) -> f64,
) {
    let [w, h] = camera.size_px.map(f64::from);
    let lo = |k: usize| corners.iter().map(|c| c[k]).fold(f64::INFINITY, f64::min) - 2.0;
    let hi = |k: usize| corners.iter().map(|c| c[k]).fold(f64::NEG_INFINITY, f64::max) + 2.0;
    let (x0, x1) = (lo(0).floor().max(0.0), hi(0).ceil().min(w - 1.0));
    let (y0, y1) = (lo(1).floor().max(0.0), hi(1).ceil().min(h - 1.0));
    if x0 > x1 || y0 > y1 {
        return;
    }
    for y in y0 as usize..=y1 as usize {
        for x in x0 as usize..=x1 as usize {
            level[y * w as usize + x] += delta([x as f64, y as f64]);
        }
    }
}

/// The light's fall-off and the sensor's noise over `level`, quantised to 8 bits.
fn finish(camera: &CameraModel, level: &[f64], look: &Look) -> GrayImage {
    let [w, h] = camera.size_px;
    let (cx, cy) = ((f64::from(w) - 1.0) / 2.0, (f64::from(h) - 1.0) / 2.0);
    let r_max = cx * cx + cy * cy;
    let mut rng = look.seed ^ 0x9E37_79B9_7F4A_7C15;
    GrayImage::from_fn(w, h, |x, y| {
        let r = ((f64::from(x) - cx).powi(2) + (f64::from(y) - cy).powi(2)) / r_max;
        let light = 1.0 - (1.0 - look.corner_light) * r;
        let v = level[y as usize * w as usize + x as usize] * light + look.noise * normal(&mut rng);
        image::Luma([v.round().clamp(0.0, 255.0) as u8])
    })
}

/// The signed distance from `p` to a box of half sides `half` about the origin (negative
/// inside).
fn box_distance(p: [f64; 2], half: [f64; 2]) -> f64 {
    let q = [p[0].abs() - half[0], p[1].abs() - half[1]];
    let outside = f64::hypot(q[0].max(0.0), q[1].max(0.0));
    outside + q[0].max(q[1]).min(0.0)
}

/// How much of a pixel `soft` mm wide an edge at signed distance `d` mm covers.
fn coverage(d: f64, soft: f64) -> f64 {
    (0.5 - d / soft).clamp(0.0, 1.0)
}

/// A standard normal number (approximately: the sum of four uniform ones, scaled; a sensor's
/// noise needs no tails), from the SplitMix64 stream `state`.
fn normal(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    let sum: f64 = (0..4).map(|k| ((z >> (16 * k)) & 0xFFFF) as f64).sum();
    // Four uniforms on [0, 65535]: mean 2·65535, variance 4·65536²/12.
    (sum - 2.0 * 65535.0) / (65536.0 * (4.0_f64 / 12.0).sqrt())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A part's top face shows as its area at the camera's scale, brighter than the belt.
    #[test]
    fn a_part_covers_its_area_at_the_cameras_scale() {
        let cam = CameraModel::overhead([0.0, 0.0], 800.0, 0.5, [400, 300]);
        let look = Look { noise: 0.0, corner_light: 1.0, ..Look::default() };
        let part =
            PartShape { at_mm: [0.0, 0.0], angle_rad: 0.3, size_mm: [40.0, 20.0], height_mm: 0.0 };
        let img = belt_frame(&cam, &[part], &look);
        let covered: f64 = img.pixels().map(|p| (f64::from(p[0]) - 60.0) / 140.0).sum();
        // 800 mm² at 0.25 mm² a pixel.
        assert!((covered - 3200.0).abs() < 10.0, "{covered}");
        let empty = belt_frame(&cam, &[], &look);
        assert!(empty.pixels().all(|p| p[0] == 60));
    }

    /// The noise has the standard deviation asked, about the level.
    #[test]
    fn the_noise_is_what_was_asked() {
        let cam = CameraModel::overhead([0.0, 0.0], 800.0, 0.5, [200, 200]);
        let look = Look { noise: 5.0, corner_light: 1.0, ..Look::default() };
        let img = belt_frame(&cam, &[], &look);
        let v: Vec<f64> = img.pixels().map(|p| f64::from(p[0])).collect();
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
        assert!((mean - 60.0).abs() < 0.1 && (sd - 5.0).abs() < 0.15, "{mean} {sd}");
    }
}
