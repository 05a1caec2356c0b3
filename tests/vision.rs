//! The vision system (issue 46) as its user meets it: `qmarc-camera draw` → `calibrate` →
//! `detect` on the simulated camera's frames; a conveyor session whose camera finds the parts
//! in frames it draws (`backend = "images"`, `source = "sim"`) picking them all, each
//! detection checked against where the simulated world put the part, each grip against the
//! part itself; sources that are not there refused before anything starts.

use qmarc_tests::{Finished, TestRun, bin_dir, read_gather, read_summary, run_with_timeout};
use std::collections::HashMap;
use std::path::Path;
use std::process::Command;
use std::time::Duration;

fn camera(args: &[&str]) -> Finished {
    run_with_timeout(
        Command::new(bin_dir().join("qmarc-camera")).args(args),
        Duration::from_secs(60),
    )
}

/// The settings file of `run` with an `images` camera and `edits`.
fn images_config(run: &TestRun, edits: &[(&str, &str)]) -> std::path::PathBuf {
    let mut all = vec![("camera.backend", "\"images\"")];
    all.extend_from_slice(edits);
    run.config_from(&qmarc_tests::tuned_config(), &all)
}

/// The commands a user calibrates and tries a camera with, on the simulated camera: its
/// target drawn, the calibration fitted (under 0.3 px), parts drawn and found where they
/// were put; a wrong grid refused saying what the frame holds.
#[test]
fn a_camera_is_calibrated_and_finds_parts_from_its_commands() {
    let run = TestRun::new("vision-cli");
    let config = images_config(&run, &[]);
    let target = run.out("target.png");
    let drawn = camera(&[
        "draw",
        &format!("--config={}", config.display()),
        &format!("--out={}", target.display()),
    ]);
    assert_eq!(drawn.code, Some(0), "{}", drawn.stderr);
    // It prints the calibrate command for its target: run it as printed.
    let printed = drawn.stdout.split("qmarc-camera ").nth(1).expect("the command").trim();
    let cal = run.out("cal.toml");
    let mut args: Vec<String> = printed.split_whitespace().map(String::from).collect();
    let last = args.len() - 1;
    args[last] = cal.display().to_string();
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let fitted = camera(&args);
    assert_eq!(fitted.code, Some(0), "{}", fitted.stderr);
    let mean_px: f64 = fitted
        .stdout
        .split("mean ")
        .nth(1)
        .and_then(|s| s.split(" px").next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{}", fitted.stdout));
    assert!(mean_px <= 0.3, "{}", fitted.stdout);
    // The file reads back; detection through it.
    let with_cal =
        images_config(&run, &[("camera.calibration", &format!("{:?}", cal.display().to_string()))]);
    let frame = run.out("parts.png");
    let parts = [[120.0, 30.0, 25.0], [200.0, -50.0, -70.0], [60.0, -10.0, 90.0]];
    let part_args: Vec<String> =
        parts.iter().map(|p| format!("--part={},{},{}", p[0], p[1], p[2])).collect();
    let mut draw = vec![
        "draw".to_string(),
        format!("--config={}", with_cal.display()),
        format!("--out={}", frame.display()),
    ];
    draw.extend(part_args);
    let draw: Vec<&str> = draw.iter().map(String::as_str).collect();
    assert_eq!(camera(&draw).code, Some(0));
    let found = camera(&[
        "detect",
        &format!("--config={}", with_cal.display()),
        &format!("--image={}", frame.display()),
    ]);
    assert_eq!(found.code, Some(0), "{}", found.stderr);
    let lines: Vec<Vec<f64>> =
        found.stdout.lines().map(|l| l.split(',').map(|v| v.parse().unwrap()).collect()).collect();
    assert_eq!(lines.len(), 3, "one line per part: {}", found.stdout);
    for p in parts {
        let d = lines
            .iter()
            .find(|d| f64::hypot(d[0] - p[0], d[1] - p[1]) < 0.5)
            .unwrap_or_else(|| panic!("{p:?} not found within 0.5 mm: {}", found.stdout));
        let mut e = d[2] - p[2];
        e -= 180.0 * (e / 180.0).round();
        assert!(e.abs() < 2.0 && d[2] > -90.0 && d[2] <= 90.0, "{p:?}: {d:?}");
        assert!(d[3] > 1000.0, "{d:?}");
    }
    assert!(found.stderr.contains("3 parts"), "{}", found.stderr);
    // A grid that is not the target's: refused, saying what the frame holds.
    let wrong = camera(&[
        "calibrate",
        &format!("--image={}", target.display()),
        "--grid=5x5",
        "--pitch-mm=17",
        &format!("--out={}", run.out("x.toml").display()),
    ]);
    assert_eq!(wrong.code, Some(i32::from(qmarc_proto::exit::REFUSED)));
    assert!(wrong.stderr.contains("no 5x5 grid of dots: 108 dots"), "{}", wrong.stderr);
    assert!(!run.out("x.toml").exists());
    // A frame that is not there, named.
    let missing = camera(&[
        "detect",
        &format!("--config={}", with_cal.display()),
        "--image=/nonexistent/f.png",
    ]);
    assert_eq!(missing.code, Some(i32::from(qmarc_proto::exit::REFUSED)));
    assert!(missing.stderr.contains("/nonexistent/f.png"), "{}", missing.stderr);
}

fn read_parts(out: &Path) -> Vec<HashMap<String, f64>> {
    let text = std::fs::read_to_string(out.join("parts.csv")).expect("parts.csv");
    let mut lines = text.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    lines
        .map(|l| {
            header
                .iter()
                .zip(l.split(','))
                .map(|(h, v)| {
                    let v = match v {
                        "picked" => 1.0,
                        "missed" => -1.0,
                        _ => v.parse().unwrap_or(0.0),
                    };
                    (h.to_string(), v)
                })
                .collect()
        })
        .collect()
}

/// A conveyor session at 120 parts a minute whose camera finds the parts in the frames it
/// draws of the simulated belt: none missed; each detection where the world put the part
/// (≤ 0.5 mm); each grip within 1 mm of the part itself — the effector's forward kinematics
/// at the grip cycle against the part where the belt had carried it, from the world, not
/// from the detection.
#[test]
fn a_conveyor_session_picks_the_parts_its_camera_sees_in_frames() {
    let run = TestRun::new("vision-conveyor");
    let config = images_config(&run, &[]);
    let s = qmarc_config::Settings::load(&config, &qmarc_config::Names::any()).unwrap();
    let out = run.out("out");
    let (c, cam) = (&s.conveyor, &s.camera);
    run.starter_ok(&[
        &format!("--config={}", config.display()),
        &format!("--out={}", out.display()),
        "--deterministic",
        "conveyor",
        "--seconds=8",
        "--parts-per-min=120",
    ]);
    let summary = read_summary(&out);
    assert!(summary.fault.is_none(), "{:?}", summary.fault);
    let section = summary.conveyor.expect("the conveyor section");
    assert_eq!(section.missed, 0);
    assert!(section.picked >= 10, "{section:?}");
    // The world's parts: dropped every 0.5 s, upstream of the field, riding at the belt's
    // constant speed.
    let feed = qmarc_conveyor::world::PartFeed {
        parts_per_min: 120.0,
        drop_mm: cam.field_mm[0] - qmarc_camera::sim::DROP_BEFORE_FIELD_MM,
        spread_mm: cam.spread_mm,
        seed: cam.seed,
    };
    let (header, rows) = read_gather(&out);
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let robot = s.robot().unwrap();
    let mut matched = 0;
    for p in read_parts(&out) {
        // The belt had run counts·mm_per_count at the exposure: the part dropped at t_k is
        // drop + that − speed·t_k along.
        let run_mm = (p["latched_counts"] + 0.5) * c.mm_per_count;
        let k = ((feed.drop_mm + run_mm - p["belt_mm"]) / c.speed_mm_s / feed.interval_s()).round();
        let (t_k, truth) = feed.dropped(k as u64);
        let along = feed.drop_mm + run_mm - c.speed_mm_s * t_k;
        let off = f64::hypot(p["belt_mm"] - along, p["across_mm"] - truth.across_mm);
        assert!(off <= 0.5, "part {}: seen {off} mm from where it was", p["id"]);
        matched += 1;
        if p["state"] == 1.0 {
            let r = rows.iter().find(|r| r[col("cycle")] == p["grip_cycle"]).unwrap();
            let effector = robot.mm_of(&[r[col("act1")], r[col("act2")], r[col("act3")]]).unwrap();
            let now = along + (r[col("conv")] - p["latched_counts"]) * c.mm_per_count;
            let part = c.point_mm(now, truth.across_mm, cam.part_height_mm);
            let e = (0..3).map(|i| (effector[i] - part[i]).powi(2)).sum::<f64>().sqrt();
            assert!(e <= 1.0, "part {}: gripped {e} mm from the part", p["id"]);
        }
    }
    assert!(matched >= 10);
    run.assert_clean();
}

/// Frames from a device or a folder that is not there, and a camera over the robot's
/// window rather than upstream: refused before anything starts, naming them.
#[test]
fn a_source_that_is_not_there_is_refused_naming_it() {
    let run = TestRun::new("vision-refused");
    let cal = run.out("cal.toml");
    // Any calibration will do: it is the source that is refused.
    std::fs::write(&cal, "").unwrap();
    for (source, says) in [
        ("v4l2:/dev/video97", "v4l2:/dev/video97: no such device"),
        ("dir:/nonexistent/frames", "dir:/nonexistent/frames: No such file or directory"),
    ] {
        let config = images_config(
            &run,
            &[
                ("camera.source", &format!("{source:?}")),
                ("camera.calibration", &format!("{:?}", cal.display().to_string())),
            ],
        );
        let r = run.starter(
            &[&format!("--config={}", config.display()), "conveyor", "--seconds=2"],
            Duration::from_secs(60),
        );
        assert_eq!(r.code, Some(i32::from(qmarc_proto::exit::REFUSED)), "{}", r.stderr);
        assert!(r.stderr.contains(says), "{}", r.stderr);
    }
    // A camera that sees the robot's window, not upstream of it.
    let over = images_config(&run, &[("camera.pose", "[400.0, 0.0, 800.0, 90.0, 0.0, 0.0]")]);
    let r = run.starter(
        &[&format!("--config={}", over.display()), "conveyor", "--seconds=2"],
        Duration::from_secs(60),
    );
    assert_eq!(r.code, Some(i32::from(qmarc_proto::exit::REFUSED)), "{}", r.stderr);
    assert!(
        r.stderr.contains("the camera sees the belt up to 520 mm along it")
            && r.stderr.contains("(conveyor.window_mm starts at 300 mm)"),
        "{}",
        r.stderr
    );
    run.assert_clean();
}
