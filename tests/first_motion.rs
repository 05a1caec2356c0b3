//! The first motions of a real robot (issue 27, items 3 and 4): jog, and the move to a path's
//! start before the path, on the simulated robot through the real processes.

use qmarc_tests::{TestRun, knots, read_gather, read_summary};
use std::path::Path;
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_secs(120);

/// Runs `qmarc-starter --config=CONFIG --out=OUT ARGS…` of `run`.
fn starter(run: &TestRun, config: &Path, out: &Path, args: &[&str]) -> qmarc_tests::Finished {
    let (config, out) =
        (format!("--config={}", config.display()), format!("--out={}", out.display()));
    let mut all = vec![config.as_str(), out.as_str()];
    all.extend_from_slice(args);
    run.starter(&all, TIMEOUT)
}

/// The column of `name` in gather.csv's `header`.
fn col(header: &[String], name: &str) -> usize {
    header.iter().position(|h| h == name).unwrap_or_else(|| panic!("no {name} in {header:?}"))
}

/// `run --approach`: from the work centre, where the simulated robot starts, a jerk-limited
/// move to the X-Z path's first knot, then the path, at rest at both ends; the approach is
/// reported apart from the path's figures. Without it the path is refused, saying so.
#[test]
fn run_with_the_approach_moves_to_the_paths_start_first() {
    let run = TestRun::new("approach");
    let config = run.config_with(&[]);
    let path = knots("xz-pick-place-spline.txt");
    let args = |out: &std::path::Path, approach: bool| {
        let mut a = vec![
            format!("--config={}", config.display()),
            format!("--out={}", out.display()),
            "--deterministic".to_string(),
            "run".to_string(),
            format!("--knots={}", path.display()),
        ];
        if approach {
            a.push("--approach".to_string());
        }
        a
    };
    let refused = run.out("refused");
    let a = args(&refused, false);
    let r = run.starter(&a.iter().map(String::as_str).collect::<Vec<_>>(), TIMEOUT);
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(r.stderr.contains("move it there first (`run --approach` does)"), "{}", r.stderr);

    let out = run.out("out");
    let a = args(&out, true);
    let r = run.starter(&a.iter().map(String::as_str).collect::<Vec<_>>(), TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("approach to the path's start from 0.0 0.0 0.0 cnt"), "{}", r.stdout);
    let s = read_summary(&out);
    let approach = s.approach.expect("the approach is reported");
    assert_eq!(approach.from_counts, [0.0; 3]);
    assert!(approach.samples > 100 && approach.cycles == approach.samples, "{approach:?}");
    // The path's figures are the path's: its 997 samples, not the approach's.
    assert_eq!(s.cycles, 997, "the X-Z path alone");
    let (header, rows) = read_gather(&out);
    let start = [3054.0, -952.0, -952.0];
    let lead = approach.samples as usize;
    for (m, want) in start.iter().enumerate() {
        let cmd = col(&header, &format!("cmd{}", m + 1));
        assert_eq!(rows[0][cmd], 0.0, "motor {}: the approach starts where it is", m + 1);
        assert_eq!(rows[lead][cmd], *want, "motor {}: the path starts at its first knot", m + 1);
        // The approach moves toward the start and never beyond it.
        let (lo, hi) = (want.min(0.0), want.max(0.0));
        assert!(rows[..lead].iter().all(|r| (lo..=hi).contains(&r[cmd])), "motor {}", m + 1);
    }
    // The PVT path likewise: its first knots read for the way there, then the path.
    let pvt = run.out("pvt");
    let knots = format!("--knots={}", knots("xz-pick-place-pvt.txt").display());
    let r = starter(
        &run,
        &config,
        &pvt,
        &["--deterministic", "run", "--method=pvt", &knots, "--approach"],
    );
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let s = read_summary(&pvt);
    assert_eq!(s.approach.map(|a| a.samples), Some(approach.samples), "the same way there");
    assert_eq!((s.trajectory.as_str(), s.cycles), ("pvt", 997));
    run.assert_clean();
}

/// `jog`: one motor moves its counts from where it is, the others hold; where the frame is
/// homed the software limits hold; where it is not, jog still moves (that is what it is for),
/// more slowly.
#[test]
fn jog_moves_one_motor_within_the_soft_limits_and_slower_unhomed() {
    let run = TestRun::new("jog");
    let config = run.config_with(&[]);
    let jog = |config: &Path, out: &Path, counts: &str| {
        let counts = format!("--counts={counts}");
        starter(&run, config, out, &["--deterministic", "jog", "--motor=2", &counts])
    };
    let homed = run.out("homed");
    let r = jog(&config, &homed, "-500");
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let (header, rows) = read_gather(&homed);
    let last = rows.last().unwrap();
    for (m, want) in [0.0, -500.0, 0.0].iter().enumerate() {
        assert_eq!(last[col(&header, &format!("cmd{}", m + 1))], *want, "motor {}", m + 1);
        let act = last[col(&header, &format!("act{}", m + 1))];
        assert!((act - want).abs() <= 2.0, "motor {} at {act}", m + 1);
    }
    assert_eq!(read_summary(&homed).mode.to_string(), "jog");
    // Beyond the software limits (−9000 counts): refused before anything moves.
    let r = jog(&config, &run.out("far"), "-12000");
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(
        r.stderr.contains("motor 2: the path reaches -12000.0 counts, outside its software limits"),
        "{}",
        r.stderr
    );
    // Unhomed: it jogs, at jog.unhomed_speed, so the same jog takes longer.
    let unhomed = run.config_as(
        "unhomed.toml",
        &qmarc_tests::default_config(),
        &[("homed", "false"), ("state_file", "\"\"")],
    );
    let slow = run.out("slow");
    let r = jog(&unhomed, &slow, "-500");
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let (s_homed, s_slow) = (read_summary(&homed), read_summary(&slow));
    assert!(s_slow.cycles > 2 * s_homed.cycles, "{} vs {}", s_slow.cycles, s_homed.cycles);
    // A motor resting on its bottom switch (10 500 counts) jogs away from it, not further.
    let on_switch = run.config_as(
        "onswitch.toml",
        &qmarc_tests::default_config(),
        &[("homed", "false"), ("state_file", "\"\""), ("start_counts", "[0, 10600, 0]")],
    );
    let r = jog(&on_switch, &run.out("further"), "500");
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("motor 2 rests on its bottom limit switch: jog it away"),
        "{}",
        r.stderr
    );
    let r = jog(&on_switch, &run.out("away"), "-500");
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    run.assert_clean();
}

/// `jog --axis z --mm 5` (issue 30, the console's Cartesian keys): the effector goes 5 mm up
/// on a straight line from where it is, x and y held; a wrong axis or distance is refused by
/// its flag, and an unhomed robot by the generator, before anything moves.
#[test]
fn a_cartesian_jog_moves_the_effector_along_its_axis() {
    let run = TestRun::new("jogxyz");
    let config = run.config_with(&[]);
    let robot = qmarc_config::Settings::load(&config, &qmarc_config::Names::any())
        .unwrap()
        .robot()
        .unwrap();
    let out = run.out("z");
    let r = starter(&run, &config, &out, &["--deterministic", "jog", "--axis=z", "--mm=5"]);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert_eq!(read_summary(&out).mode.to_string(), "jog");
    let (header, rows) = read_gather(&out);
    let cmd = |r: &Vec<f64>| [1, 2, 3].map(|m| r[col(&header, &format!("cmd{m}"))]);
    let at = |r: &Vec<f64>| robot.point_of(&cmd(r)).unwrap() * 1e3;
    let (first, last) = (at(&rows[0]), at(rows.last().unwrap()));
    assert!(((last - first).z - 5.0).abs() < 1e-6, "{first} → {last}");
    for r in &rows {
        let p = at(r);
        assert!((p.x - first.x).abs() < 0.1 && (p.y - first.y).abs() < 0.1, "off the line: {p}");
    }
    let refused = |args: &[&str], says: &str| {
        let mut all = vec!["--deterministic", "jog"];
        all.extend_from_slice(args);
        let r = starter(&run, &config, &run.out("refused"), &all);
        assert_eq!(r.code.map(|c| c == 3 || c == 64), Some(true), "{args:?}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
    };
    refused(&["--axis=w"], "--axis: `w` is not an axis: x, y or z");
    refused(&["--axis=x", "--mm=0"], "--mm: a Cartesian jog must be");
    refused(&["--axis=x", "--motor=1"], "cannot be used with");
    let unhomed = run.config_as(
        "unhomed.toml",
        &qmarc_tests::default_config(),
        &[("homed", "false"), ("state_file", "\"\"")],
    );
    let r = starter(&run, &unhomed, &run.out("unhomed"), &["--deterministic", "jog", "--axis=y"]);
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("a Cartesian jog moves in the homed frame"), "{}", r.stderr);
    run.assert_clean();
}

/// `check`: with the loop open, each motor in turn gets `[check] volts`; a robot whose motors
/// count up as they should passes, on the simulator and through the 626 backend on the fake
/// card; a motor whose amplifier is wired backwards (`sim.reversed_motor`) fails the check
/// (exit 2) with what to change, and nothing else moved.
#[test]
fn check_finds_a_motor_wired_backwards_and_says_what_to_change() {
    let run = TestRun::new("check");
    let good = run.config_with(&[]);
    let out = run.out("good");
    let r = starter(&run, &good, &out, &["--deterministic", "check"]);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let s = read_summary(&out);
    let check = s.check.expect("the check's report");
    for m in &check {
        assert!(m.ok, "{m:?}");
        // The simulated amplifier is 23 650 counts/s per V; the whole move of a pulse counts.
        assert!((m.counts_per_volt_second / 23_650.0 - 1.0).abs() < 0.01, "{m:?}");
        assert_eq!(m.other_moved_counts, 0.0, "{m:?}");
    }
    let reversed =
        run.config_as("rev.toml", &qmarc_tests::default_config(), &[("sim.reversed_motor", "2")]);
    let out = run.out("reversed");
    let r = starter(&run, &reversed, &out, &["--deterministic", "check"]);
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("QMARC check: CHECK FAILED"), "{}", r.stdout);
    assert!(
        r.stdout.contains("motor 2: counted DOWN")
            && r.stdout.contains("set motor 2's entry of s626.dac_sign to -1"),
        "{}",
        r.stdout
    );
    let check = read_summary(&out).check.expect("the check's report");
    assert_eq!(check.iter().map(|m| m.ok).collect::<Vec<_>>(), [true, false, true]);
    // Through the 626 backend against the fake card, in its 1× counts: every motor counts up
    // and nothing else moves with it. (The fake's plant advances a period per read, not per
    // period of the clock: under a loaded host's missed periods it moves less than the time
    // says, so its speed against the feed-forward's is not judged here; on the simulator
    // above it is.)
    let card = qmarc_tests::s626_config();
    let out = run.out("card");
    let r =
        starter(&run, &card, &out, &["--device=fake", &qmarc_tests::rehearsal_bounds(), "check"]);
    assert!(matches!(r.code, Some(0 | 2)), "{}\n{}", r.stdout, r.stderr);
    let check = read_summary(&out).check.expect("the check's report");
    assert!(check.iter().all(|m| m.moved_counts > 0.0 && m.other_moved_counts == 0.0), "{check:?}");
    assert!(!r.stdout.contains("counted DOWN"), "{}", r.stdout);
    run.assert_clean();
}

/// Issue 42, item 9: the first-motion sequence of docs/hardware.md — check, home, a small
/// step — rehearsed on the fake card with the card's own settings and the explicit
/// rehearsal bounds of `config/rehearse-without-rt.toml` (never a widened shipped bound),
/// which the starter says it uses; a real device refuses them.
#[test]
fn the_first_motion_is_rehearsed_on_the_fake_card_with_the_rehearsal_bounds() {
    let run = TestRun::new("rehearse");
    let card = qmarc_tests::s626_config();
    let bounds = qmarc_tests::workspace().join("config/rehearse-without-rt.toml");
    let o = qmarc_tests::rehearsal_bounds();
    // The card's settings as shipped but for where the homed frame is kept (the test's own
    // folder) and nearer switches (a shorter homing: the loop is the same).
    let state_dir = format!("{:?}", run.dir.display().to_string());
    let config = run.config_from(
        &card,
        &[
            ("s626.state_dir", state_dir.as_str()),
            ("top_switch_counts", "-400"),
            ("home_offset_counts", "400.0"),
        ],
    );
    for (step, args) in
        [("check", &["check"][..]), ("home", &["home"]), ("step", &["step", "--size", "50"])]
    {
        let out = run.out(step);
        let mut all = vec!["--device=fake", o.as_str()];
        all.extend_from_slice(args);
        let r = starter(&run, &config, &out, &all);
        assert_eq!(r.code, Some(0), "{step}: {}\n{}", r.stdout, r.stderr);
        assert!(
            r.stderr.contains(&format!(
                "timing bounds from {}: hwserver.watchdog_periods = 2500, \
                 hwserver.response_timeout_periods = 2500, safety.max_missed_in_row = 2500 (a \
                 rehearsal's, not the robot's)",
                bounds.display()
            )),
            "{step}: {}",
            r.stderr
        );
        let s = read_summary(&out);
        assert!(s.ok && s.fault.is_none(), "{step}: {:?}", s.fault);
    }
    // The shipped card settings are untouched, and a device that drives a robot refuses them.
    let shipped = std::fs::read_to_string(&card).unwrap();
    assert!(!shipped.contains("watchdog_periods = 2500"), "the card's bounds are its own");
    let r = starter(&run, &card, &run.out("real"), &["--device=/dev/null", &o, "step"]);
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("is for a rehearsal on the fake card"), "{}", r.stderr);
    run.assert_clean();
}
