//! The camera's commands for its user (issue 46): `calibrate` a camera from a frame of a
//! dot target on the belt, `detect` the parts in one frame, `draw` what the simulated camera
//! sees (its target, or the belt with parts) to try both without a camera.

use crate::images::{camera_model, sim_look, target_in_view};
use qmarc_config::{Names, Settings};
use qmarc_vision::calib::Calibration;
use qmarc_vision::render::{self, PartShape};
use std::fmt::Write as _;
use std::path::Path;

/// `COLSxROWS`, each ≥ 2.
pub fn parse_grid(s: &str) -> Result<[u32; 2], String> {
    let bad =
        || format!("COLSxROWS (two whole numbers ≥ 2, 6 to 10000 dots, e.g. 9x7), found `{s}`");
    let (c, r) = s.split_once(['x', 'X']).ok_or_else(bad)?;
    match (c.trim().parse::<u32>(), r.trim().parse::<u32>()) {
        // Six dots at least (the calibration's fit), ten thousand at most.
        (Ok(c), Ok(r))
            if c >= 2 && r >= 2 && (6..=10_000).contains(&(u64::from(c) * u64::from(r))) =>
        {
            Ok([c, r])
        }
        _ => Err(bad()),
    }
}

/// `X,Y` mm.
pub fn parse_point(s: &str) -> Result<[f64; 2], String> {
    let bad = || format!("X,Y mm (two numbers), found `{s}`");
    let (x, y) = s.split_once(',').ok_or_else(bad)?;
    match (x.trim().parse::<f64>(), y.trim().parse::<f64>()) {
        (Ok(x), Ok(y)) if x.is_finite() && y.is_finite() => Ok([x, y]),
        _ => Err(bad()),
    }
}

/// The calibration of the target in `image` (`grid` dots `pitch_mm` apart, its origin dot
/// at `origin_mm`) written to `out`; what it says of the fit.
pub fn calibrate(
    image: &Path,
    grid: [u32; 2],
    pitch_mm: f64,
    origin_mm: [f64; 2],
    out: &Path,
) -> Result<String, String> {
    let frame = crate::frames::read_png(image)?;
    let dots = qmarc_vision::grid::find(&frame, grid, pitch_mm, origin_mm)
        .map_err(|e| format!("{}: {e}", image.display()))?;
    let cal = Calibration::fit(&dots.pixels, &dots.belt, [frame.width(), frame.height()])
        .map_err(|e| format!("{}: {e}", image.display()))?;
    let r = cal.reprojection;
    let comment = format!(
        "qmarc-camera calibrate --image {} --grid {}x{} --pitch-mm {pitch_mm} --origin-mm {},{}\n\
         reprojection: mean {:.3} px, max {:.3} px; mean {:.3} mm, max {:.3} mm",
        image.display(),
        grid[0],
        grid[1],
        origin_mm[0],
        origin_mm[1],
        r.mean_px,
        r.max_px,
        r.mean_mm,
        r.max_mm
    );
    create_parent(out)?;
    std::fs::write(out, cal.to_toml(&comment)).map_err(|e| format!("{}: {e}", out.display()))?;
    Ok(format!(
        "{} dots found; reprojection error: mean {:.3} px, max {:.3} px; mean {:.3} mm, max \
         {:.3} mm; written to {}",
        dots.pixels.len(),
        r.mean_px,
        r.max_px,
        r.mean_mm,
        r.max_mm,
        out.display()
    ))
}

/// The folder `file` goes in, made if it is not there.
fn create_parent(file: &Path) -> Result<(), String> {
    match file.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => {
            std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))
        }
        _ => Ok(()),
    }
}

/// The settings of `config`.
pub fn settings(config: &Path) -> Result<Settings, String> {
    Settings::load(config, &Names::any()).map_err(|e| e.to_string())
}

/// The parts in `image` as `[camera]` of `s` finds them: one CSV line each,
/// `belt_mm,across_mm,angle_deg,area_px`; and a line for standard error saying what else
/// the frame held.
pub fn detect(s: &Settings, image: &Path) -> Result<(String, String), String> {
    let frame = crate::frames::read_png(image)?;
    let c = &s.camera;
    let mut detector = crate::images::detector(c).map_err(|e| e.reason)?;
    let size = c.images.image_px;
    if [frame.width(), frame.height()] != size {
        return Err(format!(
            "{}: the frame is {}×{}, camera.image_px (and its calibration) {}×{}",
            image.display(),
            frame.width(),
            frame.height(),
            size[0],
            size[1]
        ));
    }
    let mut parts = Vec::new();
    let t = detector.detect(&frame, &mut parts);
    let mut csv = String::new();
    for p in &parts {
        // Rounded as printed, then into (−90, 90]: −90.00 is +90.00.
        let mut angle = (p.angle_deg * 100.0).round() / 100.0;
        if angle <= -90.0 {
            angle += 180.0;
        }
        let _ = writeln!(csv, "{:.3},{:.3},{angle:.2},{}", p.belt_mm, p.across_mm, p.area_px);
    }
    let through = match (&c.images.calibration, detector.camera_mm()) {
        (Some(f), Some(m)) => format!(
            "through {} (the camera's centre at {:.0}, {:.0}, {:.0} mm)",
            f.display(),
            m[0],
            m[1],
            m[2]
        ),
        (Some(f), None) => format!("through {}", f.display()),
        (None, _) => {
            "through the simulated camera's own calibration (no camera.calibration)".into()
        }
    };
    let saturated = if t.saturated {
        "; the threshold is beyond the gray scale: nothing can be found"
    } else {
        ""
    };
    let said = format!(
        "{}: {} parts; skipped {} regions too small, {} too big, {} at the border (belt level \
         {}){saturated}; {through}",
        image.display(),
        parts.len(),
        t.too_small,
        t.too_big,
        t.at_border,
        t.belt_level
    );
    Ok((csv, said))
}

/// What the simulated camera of `s` sees, to `out` (PNG): the target it calibrates itself
/// with (and the `calibrate` arguments that go with it), or the belt with `parts`
/// (`[along, across, angle_deg]`).
pub fn draw(s: &Settings, out: &Path, parts: &[[f64; 3]]) -> Result<String, String> {
    let model = camera_model(&s.camera.images);
    let look = sim_look(&s.camera.images, s.camera.seed);
    let (img, said) = if parts.is_empty() {
        let t = target_in_view(&model);
        let img = render::target_frame(&model, &t, &look);
        let said = format!(
            "a {}x{} target, {} mm apart, its origin dot at {},{}: qmarc-camera \
             calibrate --image {} --grid {}x{} --pitch-mm {} --origin-mm {},{} --out FILE",
            t.grid[0],
            t.grid[1],
            t.pitch_mm,
            t.origin_mm[0],
            t.origin_mm[1],
            out.display(),
            t.grid[0],
            t.grid[1],
            t.pitch_mm,
            t.origin_mm[0],
            t.origin_mm[1]
        );
        (img, said)
    } else {
        let shapes: Vec<PartShape> = parts
            .iter()
            .map(|p| PartShape {
                at_mm: [p[0], p[1]],
                angle_rad: p[2].to_radians(),
                size_mm: s.camera.images.sim_part_mm,
                height_mm: s.camera.part_height_mm,
            })
            .collect();
        let n = shapes.len();
        (render::belt_frame(&model, &shapes, &look), format!("{n} parts drawn"))
    };
    create_parent(out)?;
    img.save(out).map_err(|e| format!("{}: {e}", out.display()))?;
    Ok(said)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grids_and_points_are_read_or_refused_saying_what_is_expected() {
        assert_eq!(parse_grid("9x7"), Ok([9, 7]));
        assert_eq!(parse_grid("12X3"), Ok([12, 3]));
        for bad in ["9", "1x7", "9x", "x7", "9x7x2", "-3x4", "2x2", "65536x65536"] {
            assert!(parse_grid(bad).unwrap_err().contains("COLSxROWS"), "{bad}");
        }
        assert_eq!(parse_point("10.5,-3"), Ok([10.5, -3.0]));
        assert!(parse_point("10").is_err() && parse_point("a,b").is_err());
    }
}
