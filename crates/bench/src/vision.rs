//! `qmarc-bench vision` (issue 46): the vision system as its user measures it.
//!
//! - Detection: frames of 1280×1024 at 0.5 mm a pixel with 20 parts each (40 × 16 mm, 10 mm
//!   tall, at random places and angles), drawn through a tilted camera with a little barrel
//!   distortion and sensor noise; the time `Detector::detect` takes on each, on one core —
//!   beside imageproc's connected components of the same thresholded frame, the labelling
//!   we did not use; the parts found against where they were drawn (position, orientation);
//!   the calibration's reprojection error on the camera's rendered target.
//! - The chain: a real `qmarc-starter conveyor` session whose camera finds the parts in the
//!   frames it draws (`backend = "images"`, `source = "sim"`): picks a minute, missed parts,
//!   the grip error, and a part's exposure to the part in the session's queue (p50, p99).

use crate::conveyor::{ConveyorArgs, say, session};
use crate::stats::nearest_rank;
use anyhow::Context as _;
use qmarc_vision::blobs::Polarity;
use qmarc_vision::calib::Calibration;
use qmarc_vision::camera::CameraModel;
use qmarc_vision::detect::{DetectSettings, Detector};
use qmarc_vision::render::{self, Look, PartShape, Target};
use std::path::PathBuf;
use std::time::Instant;

/// Options of `vision`.
#[derive(Debug, clap::Args)]
pub struct VisionArgs {
    /// Frames timed.
    #[arg(long, default_value_t = 100)]
    pub frames: u32,
    /// Parts in each frame (at most 20: a 5×4 lattice).
    #[arg(long, default_value_t = 20, value_parser = clap::value_parser!(u32).range(1..=20))]
    pub parts: u32,
    /// Settings file of the conveyor session (default: the gains tuned for online moves, as
    /// the conveyor's figures in BENCHMARKS.md).
    #[arg(long, default_value = "config/tuned.toml")]
    pub config: PathBuf,
    /// Length of the conveyor session, s (0: none).
    #[arg(long, default_value_t = 30.0)]
    pub seconds: f64,
    /// Parts a minute of the conveyor session.
    #[arg(long, default_value_t = 120.0)]
    pub parts_per_min: f64,
    /// Directory holding qmarc-starter and its children (default: next to this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
}

/// The camera: 1280×1024, 0.5 mm a pixel at the belt from 800 mm, turned 2°,
/// tilted 2° and 1.5°, barrel distortion k1 = −0.02.
fn camera() -> CameraModel {
    let mut c = CameraModel::overhead([150.0, 0.0], 800.0, 0.5, [1280, 1024]);
    c.pose[3..].copy_from_slice(&[88.0, 2.0, -1.5]);
    c.k1 = -0.02;
    c
}

/// A number in [0, 1): draw `k` of the simulated world's own stream.
fn uniform(k: u64) -> f64 {
    qmarc_conveyor::world::uniform(0, 0, k)
}

/// Frame `f`'s parts: `n` of a 5×4 lattice of 85 × 100 mm cells, jittered and turned.
fn parts(f: u64, n: u32) -> Vec<PartShape> {
    (0..n)
        .map(|p| {
            let k = 3 * (u64::from(p) + 20 * f);
            let (i, j) = (f64::from(p / 4), f64::from(p % 4));
            PartShape {
                at_mm: [
                    -20.0 + 85.0 * i + 30.0 * (uniform(k) - 0.5),
                    -170.0 + 100.0 * j + 30.0 * (uniform(k + 1) - 0.5),
                ],
                angle_rad: (180.0 * uniform(k + 2) - 90.0).to_radians(),
                size_mm: [40.0, 16.0],
                height_mm: 10.0,
            }
        })
        .collect()
}

/// `v` sorted, for [`nearest_rank`].
fn sorted(mut v: Vec<f64>) -> Vec<f64> {
    v.sort_by(f64::total_cmp);
    v
}

/// Detection's time and accuracy; the calibration's fit.
fn detection(a: &VisionArgs) -> anyhow::Result<()> {
    let cam = camera();
    let target = Target {
        grid: [11, 9],
        pitch_mm: 40.0,
        origin_mm: [-50.0, -160.0],
        dot_mm: 12.0,
        origin_scale: render::ORIGIN_DOT_SCALE,
    };
    let board = render::target_frame(&cam, &target, &Look::default());
    let dots = qmarc_vision::grid::find(&board, target.grid, target.pitch_mm, target.origin_mm)?;
    let cal = Calibration::fit(&dots.pixels, &dots.belt, cam.size_px)?;
    let r = cal.reprojection;
    println!(
        "calibration on the rendered {}x{} target: reprojection mean {:.3} px, max {:.3} px \
         (goal ≤ 0.3 px mean); mean {:.3} mm, max {:.3} mm",
        target.grid[0], target.grid[1], r.mean_px, r.max_px, r.mean_mm, r.max_mm
    );
    let settings = DetectSettings {
        polarity: Polarity::Bright,
        threshold: 70,
        area_px: [800, 4000],
        part_height_mm: 10.0,
    };
    let mut detector = Detector::new(settings, cal, Some(cam.intrinsics));
    let (mut ours, mut labels, mut pos, mut ang) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let mut found = Vec::new();
    for f in 0..u64::from(a.frames) {
        let drawn = parts(f, a.parts);
        let img = render::belt_frame(&cam, &drawn, &Look { seed: f + 1, ..Look::default() });
        let t = Instant::now();
        detector.detect(&img, &mut found);
        ours.push(t.elapsed().as_secs_f64() * 1e3);
        // imageproc's labelling of the same frame, thresholded at the same level.
        let level = qmarc_vision::detect::belt_level(&img).saturating_add(70);
        let t = Instant::now();
        let binary = imageproc::contrast::threshold(&img, level);
        let labelled = imageproc::region_labelling::connected_components(
            &binary,
            imageproc::region_labelling::Connectivity::Eight,
            image::Luma([0u8]),
        );
        labels.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(labelled);
        anyhow::ensure!(
            found.len() == drawn.len(),
            "frame {f}: {} of {} parts",
            found.len(),
            drawn.len()
        );
        for p in &drawn {
            let d = found
                .iter()
                .min_by(|x, y| {
                    let at = |q: &&qmarc_vision::detect::Detection| {
                        f64::hypot(q.belt_mm - p.at_mm[0], q.across_mm - p.at_mm[1])
                    };
                    at(x).total_cmp(&at(y))
                })
                .context("a part")?;
            pos.push(f64::hypot(d.belt_mm - p.at_mm[0], d.across_mm - p.at_mm[1]));
            let mut e = d.angle_deg - p.angle_rad.to_degrees();
            e -= 180.0 * (e / 180.0).round();
            ang.push(e.abs());
        }
    }
    let (ours, labels, pos, ang) = (sorted(ours), sorted(labels), sorted(pos), sorted(ang));
    println!(
        "detection, {} frames of 1280×1024 with {} parts, one core: p50 {:.2} ms, p99 {:.2} ms, \
         max {:.2} ms (goal ≤ 5 ms)",
        a.frames,
        a.parts,
        nearest_rank(&ours, 0.5),
        nearest_rank(&ours, 0.99),
        nearest_rank(&ours, 1.0)
    );
    println!(
        "  imageproc's threshold + connected components of the same frames (labelling only): \
         p50 {:.2} ms, p99 {:.2} ms",
        nearest_rank(&labels, 0.5),
        nearest_rank(&labels, 0.99)
    );
    println!(
        "accuracy, {} parts: position error p50 {:.3} mm, p99 {:.3} mm (goal ≤ 0.5 mm at 0.5 \
         mm/px); orientation p50 {:.3}°, p99 {:.3}° (goal ≤ 2°, 40 × 16 mm parts)",
        pos.len(),
        nearest_rank(&pos, 0.5),
        nearest_rank(&pos, 0.99),
        nearest_rank(&ang, 0.5),
        nearest_rank(&ang, 0.99)
    );
    Ok(())
}

/// A conveyor session whose camera finds its parts in frames.
fn chain(a: &VisionArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&a.config)
        .with_context(|| format!("cannot read {}", a.config.display()))?;
    let mut doc: toml_edit::DocumentMut =
        text.parse().with_context(|| format!("{}", a.config.display()))?;
    doc["camera"]["backend"] = toml_edit::value("images");
    let config =
        std::env::temp_dir().join(format!("qmarc-bench-vision-{}.toml", std::process::id()));
    std::fs::write(&config, doc.to_string())?;
    let args = ConveyorArgs {
        config: config.clone(),
        seconds: a.seconds,
        belt_mm_s: 500.0,
        parts_per_min: a.parts_per_min,
        sweep_seconds: 0.0,
        sweep_step: 0.0,
        bin_dir: a.bin_dir.clone(),
    };
    let run = session(&args, a.seconds, 500.0, a.parts_per_min, "vision");
    let _ = std::fs::remove_file(&config);
    println!(
        "a conveyor session of {} s, its camera finding the parts in 640×480 frames it draws \
         (backend images, source sim), belt 500 mm/s:",
        a.seconds
    );
    say("images camera", &run?, a.parts_per_min);
    Ok(())
}

/// `qmarc-bench vision`.
pub fn run(a: &VisionArgs) -> anyhow::Result<()> {
    detection(a)?;
    if a.seconds > 0.0 {
        chain(a)?;
    }
    Ok(())
}
