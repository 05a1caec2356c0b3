//! Issue 13, the Deltabot evaluation of thesis chapter 5: Cartesian paths made with
//! `qmarc-starter path`, and the report of the X-Z pick-and-place path on the simulated robot.

use qmarc_tests::{TestRun, knots, read_summary, workspace};
use std::time::Duration;

/// The shipped thesis paths: (waypoints, knot file prefix, --every-ms).
const THESIS_PATHS: [(&str, &str, &str); 2] = [
    ("xz-pick-place-waypoints.txt", "xz-pick-place", "11.07"),
    ("rotated-arc-waypoints.txt", "rotated-arc", "10"),
];

/// The shipped knot files are what `path` makes of the shipped waypoints, byte for byte:
/// 37 knots 11.07 ms apart and 57 knots 10 ms apart, as the thesis resampled them.
#[test]
fn path_makes_the_shipped_thesis_knot_files_issue_13() {
    let run = TestRun::new("pathknots");
    for (waypoints, name, every) in THESIS_PATHS {
        for method in ["spline", "pvt"] {
            let out = run.out(&format!("{name}-{method}.txt"));
            let r = run.starter_ok(&[
                "--config=config/qmarc.toml",
                "path",
                &format!("--waypoints=knots/{waypoints}"),
                &format!("--method={method}"),
                &format!("--every-ms={every}"),
                &format!("--out={}", out.display()),
            ]);
            let shipped = knots(&format!("{name}-{method}.txt"));
            let made = std::fs::read_to_string(&out).unwrap();
            assert_eq!(made, std::fs::read_to_string(&shipped).unwrap(), "{}", shipped.display());
            let n = if name == "xz-pick-place" { 37 } else { 57 };
            assert_eq!(r.stdout.trim(), format!("wrote {n} {method} knots to {}", out.display()));
        }
    }
    run.assert_clean();
}

#[test]
fn path_refuses_bad_waypoints_before_writing_anything_issue_13() {
    let run = TestRun::new("pathbad");
    let w = run.out("w.txt");
    std::fs::write(&w, "# t x y z\n0.0 0 0 -0.6\n0.1 0 0 -1.2\n").unwrap();
    let out = run.out("k.txt");
    let args = |extra: &[&str]| {
        let mut a = vec![
            "--config=config/qmarc.toml".to_string(),
            "path".into(),
            format!("--waypoints={}", w.display()),
            "--method=spline".into(),
        ];
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let call = |a: Vec<String>| {
        let refs: Vec<&str> = a.iter().map(String::as_str).collect();
        run.starter(&refs, Duration::from_secs(30))
    };
    let r = call(args(&[&format!("--out={}", out.display())]));
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(
        r.stderr.contains(&format!(
            "{}:3: at t = 0.1 s: arm 1 cannot reach (0.0, 0.0, -1200.0) mm",
            w.display()
        )),
        "{}",
        r.stderr
    );
    assert!(!out.exists(), "nothing written");
    let r = call(args(&[&format!("--out={}", w.display())]));
    assert_eq!(r.code, Some(3));
    assert!(r.stderr.contains("that is the waypoint file"), "{}", r.stderr);
    let r = call(args(&[]));
    assert!(r.stderr.contains("--out FILE"), "{}", r.stderr);
    // Without a [robot] table there is no geometry to go by.
    let no_robot = run.out("norobot.toml");
    let text = std::fs::read_to_string(workspace().join("config/qmarc.toml")).unwrap();
    let cut = text.find("[robot]").unwrap();
    let end = cut + text[cut..].find("# Per motor").unwrap();
    std::fs::write(&no_robot, format!("{}{}", &text[..cut], &text[end..])).unwrap();
    let mut a = args(&[&format!("--out={}", out.display())]);
    a[0] = format!("--config={}", no_robot.display());
    let r = call(a);
    assert_eq!(r.code, Some(3));
    assert!(r.stderr.contains("no [robot] table"), "{}", r.stderr);
    run.assert_clean();
}

/// Settings whose simulated robot starts at the first knot of the spline file `name`.
fn starting_at_the_path(run: &TestRun, name: &str) -> std::path::PathBuf {
    let text = std::fs::read_to_string(knots(name)).unwrap();
    let first = text.lines().find(|l| l.starts_with("0.000000")).unwrap();
    let start: Vec<&str> = first.split_whitespace().skip(1).collect();
    run.config_with(&[("start_counts", &format!("[{}]", start.join(", ")))])
}

/// Every shipped thesis path runs to its end on the simulated robot with the thesis' gains.
#[test]
fn every_thesis_path_runs_without_a_fault_issue_13() {
    let run = TestRun::new("thesispaths");
    for (_, name, _) in THESIS_PATHS {
        let config = starting_at_the_path(&run, &format!("{name}-spline.txt"));
        for method in ["spline", "pvt"] {
            let out = run.out(&format!("{name}-{method}"));
            run.starter_ok(&[
                &format!("--config={}", config.display()),
                &format!("--out={}", out.display()),
                "--deterministic",
                "run",
                &format!("--method={method}"),
                &format!("--knots={}", knots(&format!("{name}-{method}.txt")).display()),
            ]);
            let s = read_summary(&out);
            assert!(s.ok && s.fault.is_none() && s.effector.is_some(), "{name} {method}: {s:?}");
        }
    }
    run.assert_clean();
}

/// The X-Z spline path with the thesis' gains, gathered every 4th cycle as the thesis did:
/// the arm figures over the gathered rows and the end-effector error are in the summary.
/// The figures of this deterministic run are reproducible to the last bit; the band is the
/// one docs/deltabot.md justifies for the present plant.
#[test]
fn the_xz_path_reports_arm_and_effector_errors_issue_13() {
    let run = TestRun::new("xzreport");
    let out = run.out("out");
    let config = starting_at_the_path(&run, "xz-pick-place-spline.txt");
    run.starter_ok(&[
        &format!("--config={}", config.display()),
        &format!("--out={}", out.display()),
        "--deterministic",
        "--gather-every=4",
        "run",
        "--method=spline",
        &format!("--knots={}", knots("xz-pick-place-spline.txt").display()),
    ]);
    let s = read_summary(&out);
    assert!(s.ok, "{s:?}");
    let g = s.gathered.as_ref().expect("figures over the gathered rows");
    assert_eq!((g.every, g.rows), (4, s.cycles.div_ceil(4)));
    for (all, gathered) in s.motors.iter().zip(&g.motors) {
        // Every 4th cycle sums about a quarter of every cycle's error.
        let ratio = gathered.accumulated_abs_error_rad / all.accumulated_abs_error_rad;
        assert!((0.24..0.26).contains(&ratio), "{ratio}");
        assert!((4.0..7.0).contains(&gathered.accumulated_abs_error_rad), "{gathered:?}");
    }
    let e = s.effector.expect("the [robot] gives the end-effector error");
    assert_eq!((e.rows, e.no_pose_rows), (g.rows, 0));
    // The path is in the X-Z plane and arms 2 and 3 mirror each other: the error is in x
    // and z, hardly in y.
    assert!((10.0..30.0).contains(&e.x.max_abs_mm), "{e:?}");
    assert!((3.0..15.0).contains(&e.z.max_abs_mm), "{e:?}");
    assert!(e.y.max_abs_mm < 0.1 * e.x.max_abs_mm, "{e:?}");
    assert!(e.distance.max_mm >= e.x.max_abs_mm && e.distance.rms_mm > 0.0);
    let json = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(json.contains("\"effector\""), "the contract's key");
    run.assert_clean();
}
