//! Detection and calibration against rendered frames whose parts and target are known
//! (issue 46): positions and orientations within the accuracy, parts at the border
//! and touching ones skipped, an empty belt and a frame of noise giving nothing, the
//! calibration from a rendered target, refused (saying what was found) where there is no
//! grid; our region labelling against imageproc's.

use image::GrayImage;
use qmarc_vision::blobs::{Labeller, Polarity};
use qmarc_vision::calib::Calibration;
use qmarc_vision::camera::CameraModel;
use qmarc_vision::detect::{DetectSettings, Detection, Detector};
use qmarc_vision::grid;
use qmarc_vision::render::{self, Look, PartShape, Target};

/// The camera: 1280×1024 at 0.5 mm a pixel on the belt, 800 mm above it, slightly
/// turned and tilted, with a little barrel distortion.
fn camera() -> CameraModel {
    let mut c = CameraModel::overhead([150.0, 0.0], 800.0, 0.5, [1280, 1024]);
    c.pose[3] = 88.0;
    c.pose[4] = 2.0;
    c.pose[5] = -1.5;
    c.k1 = -0.02;
    c
}

const TARGET: Target = Target {
    grid: [11, 9],
    pitch_mm: 40.0,
    origin_mm: [-50.0, -160.0],
    dot_mm: 12.0,
    origin_scale: render::ORIGIN_DOT_SCALE,
};

fn calibrated(cam: &CameraModel) -> Calibration {
    let frame = render::target_frame(cam, &TARGET, &Look::default());
    let dots = grid::find(&frame, TARGET.grid, TARGET.pitch_mm, TARGET.origin_mm).unwrap();
    Calibration::fit(&dots.pixels, &dots.belt, cam.size_px).unwrap()
}

fn settings() -> DetectSettings {
    DetectSettings {
        polarity: Polarity::Bright,
        threshold: 70,
        area_px: [800, 4000],
        part_height_mm: 10.0,
    }
}

fn part(at: [f64; 2], angle_deg: f64) -> PartShape {
    PartShape {
        at_mm: at,
        angle_rad: angle_deg.to_radians(),
        size_mm: [40.0, 16.0],
        height_mm: 10.0,
    }
}

fn p99(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() as f64 * 0.99).ceil() as usize).saturating_sub(1)]
}

/// A pseudo-random number in [0, 1): draw `k` of the simulated world's own stream.
fn uniform(k: u64) -> f64 {
    qmarc_conveyor::world::uniform(0, 0, k)
}

/// The calibration from a rendered target: reprojection ≤ 0.3 px mean, and the camera's
/// centre (for the parallax) where it is.
#[test]
fn a_rendered_target_calibrates_the_camera() {
    let cam = camera();
    let c = calibrated(&cam);
    assert!(c.reprojection.mean_px <= 0.3, "{:?}", c.reprojection);
    let centre = c.camera_centre(cam.intrinsics).unwrap();
    for k in 0..3 {
        assert!((centre[k] - cam.pose[k]).abs() < 5.0, "{centre:?} against {:?}", cam.pose);
    }
    // Any belt point comes back where the camera sees it.
    for (a, x) in [(0.0, 0.0), (150.0, 100.0), (300.0, -150.0)] {
        let b = c.belt_of(cam.pixel_of([a, x, 0.0]).unwrap());
        assert!((b[0] - a).abs() < 0.3 && (b[1] - x).abs() < 0.3, "{b:?} for {a} {x}");
    }
}

/// Many frames of up to 20 parts at known poses: position ≤ 0.5 mm p99, orientation
/// ≤ 2° (elongated parts, 40×16 mm), each part found once.
#[test]
fn parts_are_found_where_they_are() {
    let cam = camera();
    let mut detector = Detector::new(settings(), calibrated(&cam), Some(cam.intrinsics));
    let (mut pos, mut ang, mut out) = (Vec::new(), Vec::new(), Vec::new());
    let mut k = 0;
    for frame in 0..12u64 {
        // Parts on a 5×4 lattice of 85 × 100 mm cells, each jittered and turned at random.
        let mut parts = Vec::new();
        for i in 0..5 {
            for j in 0..4 {
                k += 1;
                let at = [
                    -20.0 + 85.0 * f64::from(i) + 30.0 * (uniform(3 * k) - 0.5),
                    -170.0 + 100.0 * f64::from(j) + 30.0 * (uniform(3 * k + 1) - 0.5),
                ];
                parts.push(part(at, 180.0 * uniform(3 * k + 2) - 90.0));
            }
        }
        let look = Look { seed: frame + 1, ..Look::default() };
        let img = render::belt_frame(&cam, &parts, &look);
        let tally = detector.detect(&img, &mut out);
        assert_eq!(out.len(), parts.len(), "frame {frame}: {tally:?}");
        // One to one: each detection the nearest of one part only.
        let mut used = vec![false; out.len()];
        for p in &parts {
            let k = nearest(&out, p.at_mm);
            assert!(
                !std::mem::replace(&mut used[k], true),
                "frame {frame}: two parts, one detection"
            );
            let d = out[k];
            pos.push(f64::hypot(d.belt_mm - p.at_mm[0], d.across_mm - p.at_mm[1]));
            let mut e = d.angle_deg - p.angle_rad.to_degrees();
            e -= 180.0 * (e / 180.0).round();
            ang.push(e.abs());
        }
    }
    let worst = pos.iter().copied().fold(0.0, f64::max);
    assert!(worst < 1.0, "the worst part {worst} mm off");
    let (pos99, ang99) = (p99(pos.clone()), p99(ang.clone()));
    eprintln!("position error p99 {pos99:.3} mm, orientation p99 {ang99:.3}°");
    assert!(pos99 <= 0.5, "position error p99 {pos99} mm");
    assert!(ang99 <= 2.0, "orientation error p99 {ang99}°");
    // The parallax matters: taken as flat, the same parts would be off by more.
    let mut flat = Detector::new(settings(), calibrated(&cam), None);
    let img = render::belt_frame(&cam, &[part([-50.0, -180.0], 0.0)], &Look::default());
    flat.detect(&img, &mut out);
    let off = f64::hypot(out[0].belt_mm + 50.0, out[0].across_mm + 180.0);
    assert!(off > 2.0, "the parallax of a 10 mm part 280 mm off the camera's foot: {off}");
}

/// The index of the detection nearest `at`.
fn nearest(found: &[Detection], at: [f64; 2]) -> usize {
    let d = |x: &Detection| f64::hypot(x.belt_mm - at[0], x.across_mm - at[1]);
    (0..found.len()).min_by(|&a, &b| d(&found[a]).total_cmp(&d(&found[b]))).unwrap()
}

/// A part cut by the frame's border is not reported (its centroid would be wrong); two
/// parts touching each other make one region too big, skipped; an empty belt and a frame of
/// noise give nothing.
#[test]
fn what_is_not_a_whole_part_is_not_reported() {
    let cam = camera();
    let mut detector = Detector::new(settings(), calibrated(&cam), Some(cam.intrinsics));
    let mut out = Vec::new();
    // Half a part beyond the frame's upstream edge (its first row).
    let edge = cam.belt_of([640.0, 0.0], 10.0).unwrap();
    let cut = part(edge, 0.0);
    let touching = [part([150.0, 0.0], 0.0), part([150.0 + 39.0, 0.0], 0.0)];
    let whole = part([150.0, 120.0], 45.0);
    let img = render::belt_frame(&cam, &[cut, touching[0], touching[1], whole], &Look::default());
    let tally = detector.detect(&img, &mut out);
    assert_eq!(out.len(), 1, "{out:?} {tally:?}");
    assert!((out[0].across_mm - 120.0).abs() < 0.5);
    assert_eq!((tally.at_border, tally.too_big), (1, 1), "{tally:?}");
    let empty = render::belt_frame(&cam, &[], &Look { noise: 8.0, ..Look::default() });
    detector.detect(&empty, &mut out);
    assert!(out.is_empty(), "{out:?}");
    let noise = GrayImage::from_fn(1280, 1024, |x, y| {
        image::Luma([(uniform(u64::from(y) << 20 | u64::from(x)) * 256.0) as u8])
    });
    let tally = detector.detect(&noise, &mut out);
    assert!(out.is_empty(), "{out:?} {tally:?}");
}

/// Dark parts on a bright belt, with `polarity = dark`.
#[test]
fn dark_parts_are_found_on_a_bright_belt() {
    let cam = camera();
    let dark = DetectSettings { polarity: Polarity::Dark, ..settings() };
    let mut detector = Detector::new(dark, calibrated(&cam), Some(cam.intrinsics));
    let look = Look { belt: 190.0, part: 40.0, ..Look::default() };
    let img = render::belt_frame(&cam, &[part([100.0, -50.0], -30.0)], &look);
    let mut out = Vec::new();
    detector.detect(&img, &mut out);
    assert_eq!(out.len(), 1);
    assert!(f64::hypot(out[0].belt_mm - 100.0, out[0].across_mm + 50.0) < 0.5, "{out:?}");
    assert!((out[0].angle_deg + 30.0).abs() < 2.0, "{out:?}");
}

/// Where there is no grid, the calibration is refused saying what the frame holds: another
/// grid than the target's, a target without its origin dot, a target seen in a mirror (its
/// rows against the across direction), a frame of parts.
#[test]
fn no_grid_is_refused_saying_what_was_found() {
    let cam = camera();
    let frame = render::target_frame(&cam, &TARGET, &Look::default());
    let e = grid::find(&frame, [10, 9], TARGET.pitch_mm, TARGET.origin_mm).unwrap_err();
    assert!(e.to_string().contains("no 10x9 grid of dots: 99 dots of about "), "{e}");
    assert!(e.to_string().contains("px (the grid has 90); "), "{e}");
    let plain = Target { origin_scale: 1.0, ..TARGET };
    let frame = render::target_frame(&cam, &plain, &Look::default());
    let e = grid::find(&frame, TARGET.grid, TARGET.pitch_mm, TARGET.origin_mm).unwrap_err();
    assert_eq!(
        e.to_string(),
        "no 11x9 grid of dots: 99 dots, but none larger than the others: the origin dot is 1.5× \
         as wide"
    );
    let frame = render::target_frame(&cam, &TARGET, &Look::default());
    let mirrored = image::imageops::flip_horizontal(&frame);
    let e = grid::find(&mirrored, TARGET.grid, TARGET.pitch_mm, TARGET.origin_mm).unwrap_err();
    assert!(e.to_string().contains("the rows run from the origin dot against the across"), "{e}");
    let belt = render::belt_frame(&cam, &[part([150.0, 0.0], 0.0)], &Look::default());
    let e = grid::find(&belt, TARGET.grid, TARGET.pitch_mm, TARGET.origin_mm).unwrap_err();
    assert!(e.to_string().starts_with("no 11x9 grid of dots: "), "{e}");
}

/// Our runs-based labelling finds the regions imageproc's connected components find — each
/// with its area, centroid and whether it touches the border — on frames of random specks.
#[test]
fn the_labelling_agrees_with_imageproc() {
    use imageproc::region_labelling::{Connectivity, connected_components};
    for seed in 0..6u64 {
        let density = 0.05 + 0.07 * seed as f64;
        let img = GrayImage::from_fn(200, 150, |x, y| {
            let on = uniform(seed << 40 | u64::from(y) << 16 | u64::from(x)) < density;
            image::Luma([if on { 255 } else { 0 }])
        });
        let mut ours = Vec::new();
        Labeller::default().regions(&img, Polarity::Bright, 128, &mut ours);
        let labels = connected_components(&img, Connectivity::Eight, image::Luma([0u8]));
        let n = labels.pixels().map(|p| p[0]).max().unwrap_or(0) as usize;
        let mut areas = vec![0u32; n + 1];
        for p in labels.pixels() {
            areas[p[0] as usize] += 1;
        }
        // Each region's area, centroid (×1000, rounded) and whether it touches the border.
        let mut sums = vec![(0u32, 0u64, 0u64, false); n + 1];
        for (x, y, p) in labels.enumerate_pixels() {
            let s = &mut sums[p[0] as usize];
            let edge = x == 0 || y == 0 || x == 199 || y == 149;
            *s = (s.0 + 1, s.1 + u64::from(x), s.2 + u64::from(y), s.3 || edge);
        }
        let key = |area: u32, cx: f64, cy: f64, edge: bool| {
            (area, (cx * 1000.0).round() as i64, (cy * 1000.0).round() as i64, edge)
        };
        let mut theirs: Vec<_> = sums[1..]
            .iter()
            .map(|s| key(s.0, s.1 as f64 / f64::from(s.0), s.2 as f64 / f64::from(s.0), s.3))
            .collect();
        let mut mine: Vec<_> =
            ours.iter().map(|r| key(r.area, r.centroid[0], r.centroid[1], r.at_border)).collect();
        theirs.sort_unstable();
        mine.sort_unstable();
        assert_eq!(mine, theirs, "density {density}");
    }
}
