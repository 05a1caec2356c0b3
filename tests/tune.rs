//! Issue 15, automatic tuning: `--unpaced` lock-step moves, `qmarc-starter tune` on the
//! simulated robot (in-process lock-step) and by real moves (`--paced`), its constraints and
//! its files.

use qmarc_tests::{TestRun, knots, read_summary};
use std::path::{Path, PathBuf};

const XZ: &str = "xz-pick-place-spline.txt";

/// Settings with the simulated robot standing at the X-Z path's start and no kept frame;
/// `edits` on top.
fn at_the_xz_start(run: &TestRun, edits: &[(&str, &str)]) -> PathBuf {
    let mut all = vec![("state_file", "\"\"")];
    all.extend_from_slice(edits);
    crate::deltabot::starting_at_the_path_with(run, XZ, &all)
}

/// `qmarc-starter --config=C --out=O tune ARGS… run --knots=X-Z`.
fn tune(run: &TestRun, config: &Path, out: &Path, args: &[&str]) -> qmarc_tests::Finished {
    let (config, out) =
        (format!("--config={}", config.display()), format!("--out={}", out.display()));
    let knots = format!("--knots={}", knots(XZ).display());
    let mut all = vec![config.as_str(), out.as_str(), "tune"];
    all.extend_from_slice(args);
    all.extend(["run", knots.as_str()]);
    // A whole tuning in a debug build is minutes of one core; on a machine loaded with the
    // rest of the suite and two CPU hogs, 300 s were seen to run out (issue 48): the bound
    // only keeps a hung tuning from hanging the suite.
    run.starter(&all, std::time::Duration::from_secs(1200))
}

/// Σ|e| per motor of the move in `dir`, rad.
fn abs_errors(dir: &Path) -> Vec<f64> {
    read_summary(dir).motors.iter().map(|m| m.accumulated_abs_error_rad).collect()
}

/// The paced lock-step move, the `--unpaced` one (three processes, no timer) and the one
/// inside the tuning process (its `before/`) leave the same data files, byte for byte.
#[test]
fn unpaced_lock_step_equals_paced_lock_step_byte_for_byte() {
    let run = TestRun::new("unpaced");
    let config = at_the_xz_start(&run, &[]);
    let knots = format!("--knots={}", knots(XZ).display());
    let c = format!("--config={}", config.display());
    for (name, flag) in [("paced", "--deterministic"), ("unpaced", "--unpaced")] {
        let out = format!("--out={}", run.out(name).display());
        run.starter_ok(&[&c, &out, flag, "run", &knots]);
    }
    let r = tune(&run, &config, &run.out("tune"), &["--budget=1", "--params=kvff"]);
    assert_eq!(r.code, Some(0), "{}{}", r.stdout, r.stderr);
    let paced = run.out("paced");
    for other in [run.out("unpaced"), run.out("tune").join("before")] {
        for file in ["gather.csv", "gather.m"] {
            let (a, b) = (
                std::fs::read(paced.join(file)).unwrap(),
                std::fs::read(other.join(file)).unwrap(),
            );
            assert!(
                a.len() > 10_000 && a == b,
                "{} differs from {}",
                other.join(file).display(),
                file
            );
        }
    }
    assert!(read_summary(&run.out("unpaced")).deterministic);
    // Not on hardware: real moves are paced by the timer.
    let r = run.starter(
        &[&c, "--unpaced", "--backend=s626", "run", &knots],
        std::time::Duration::from_secs(30),
    );
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(r.stderr.contains("--unpaced runs only on the simulated robot"), "{}", r.stderr);
    run.assert_clean();
}

/// The goal: on the simulated robot, tuning the thesis' Table 5-1 gains on the X-Z path
/// at least halves every arm's accumulated absolute error, with no saturation and no fault;
/// the same command twice gives the same gains; `--write` writes a copy that loads, and
/// never touches the settings file.
#[test]
fn tuning_halves_the_xz_error_deterministically_and_writes_a_copy() {
    let run = TestRun::new("tunexz");
    let config = at_the_xz_start(&run, &[]);
    let source = std::fs::read(&config).unwrap();
    let copy = run.out("tuned.toml");
    let w = format!("--write={}", copy.display());
    let r = tune(&run, &config, &run.out("a"), &[&w]);
    assert_eq!(r.code, Some(0), "{}{}", r.stdout, r.stderr);
    let (before, after) =
        (abs_errors(&run.out("a").join("before")), abs_errors(&run.out("a").join("after")));
    for (m, (b, a)) in before.iter().zip(&after).enumerate() {
        assert!(*a <= 0.5 * b, "motor {}: {b} → {a}\n{}", m + 1, r.stdout);
    }
    assert!(read_summary(&run.out("a").join("after")).ok);
    assert!(r.stdout.contains("Σ|e| rad (before → after, ratio)"), "{}", r.stdout);
    for f in ["tune.csv", "tuned-gains.toml", "convergence.png"] {
        assert!(run.out("a").join(f).is_file(), "{f}");
    }
    // Every candidate is in tune.csv; the saturated share of the accepted ones is within bounds.
    let csv = std::fs::read_to_string(run.out("a").join("tune.csv")).unwrap();
    assert!(csv.lines().count() > 100 && csv.contains(",best,"));
    // The same command again: the same gains.
    let r = tune(&run, &config, &run.out("b"), &[]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let gains = |d: &str| std::fs::read_to_string(run.out(d).join("tuned-gains.toml")).unwrap();
    assert_eq!(gains("a"), gains("b"));
    // --write: the settings file untouched, the copy loads with the tuned gains.
    assert_eq!(std::fs::read(&config).unwrap(), source);
    let written = std::fs::read_to_string(&copy).unwrap();
    let fragment = gains("a");
    for line in fragment.lines().filter(|l| l.starts_with("kvff = ")) {
        assert!(written.contains(line), "{line} not in the copy");
    }
    let out = format!("--out={}", run.out("check").display());
    let c = format!("--config={}", copy.display());
    run.starter_ok(&[&c, &out, "--print-settings", "step"]);
    // Never over the settings file nor over any existing file.
    for target in [config.clone(), copy.clone()] {
        let before = std::fs::read(&target).unwrap();
        let w = format!("--write={}", target.display());
        let r = tune(&run, &config, &run.out("c"), &["--budget=1", &w]);
        assert_eq!(r.code, Some(3), "{}", r.stderr);
        assert!(r.stderr.contains("--write"), "{}", r.stderr);
        assert_eq!(std::fs::read(&target).unwrap(), before);
    }
    run.assert_clean();
}

/// A deliberately detuned motor (its velocity feed-forward halved) is brought back: its
/// error falls by more than half, with only Kvff tuned and a small budget.
#[test]
fn tuning_repairs_a_detuned_motor() {
    let run = TestRun::new("detuned");
    let config = at_the_xz_start(&run, &[]);
    let text = std::fs::read_to_string(&config).unwrap();
    let detuned = text.replacen("kvff = 103500.0", "kvff = 51750.0", 1);
    assert_ne!(text, detuned);
    std::fs::write(&config, detuned).unwrap();
    let r =
        tune(&run, &config, &run.out("t"), &["--params=kvff", "--budget=25", "--objective=sse"]);
    assert_eq!(r.code, Some(0), "{}{}", r.stdout, r.stderr);
    let (before, after) =
        (abs_errors(&run.out("t").join("before")), abs_errors(&run.out("t").join("after")));
    assert!(before[1] > 2.0 * before[0], "motor 2 is the detuned one: {before:?}");
    assert!(after[1] < 0.5 * before[1], "{before:?} → {after:?}");
    run.assert_clean();
}

/// On real moves (`--paced`: the hardware procedure, here on the simulated robot) every
/// candidate is a move of the three processes, and tuning stops at `tune.max_moves` with the
/// best gains so far; `--unpaced` and `--unhomed` are refused there.
#[test]
fn paced_tuning_makes_real_moves_within_the_move_budget() {
    let run = TestRun::new("tunepaced");
    let config = at_the_xz_start(&run, &[("max_moves", "8")]);
    let out = run.out("p");
    let r = tune(&run, &config, &out, &["--paced", "--params=kvff", "--budget=3"]);
    assert_eq!(r.code, Some(0), "{}{}", r.stdout, r.stderr);
    // A step is made only with its step back: the budget may end a move or two early.
    assert!(r.stdout.contains("moves made, the most tune.max_moves allows"), "{}", r.stdout);
    // One more path, beyond the budget, for the before/after table.
    assert!(r.stdout.contains("Σ|e| rad (before → after, ratio)"), "{}", r.stdout);
    assert!(r.stdout.contains("by real moves"), "{}", r.stdout);
    // The last move's data, each move's messages in tune.log, the safe gains written.
    assert!(out.join("moves").join("gather.csv").is_file());
    assert!(std::fs::read_to_string(out.join("tune.log")).unwrap().contains("qmarc-controller"));
    assert!(std::fs::read_to_string(out.join("tuned-gains.toml")).unwrap().contains("kvff = "));
    let csv = std::fs::read_to_string(out.join("tune.csv")).unwrap();
    let moves: Vec<u32> =
        csv.lines().skip(1).map(|l| l.rsplit(',').next().unwrap().parse().unwrap()).collect();
    assert!(moves.iter().all(|&m| m <= 8) && !moves.is_empty(), "{csv}");
    let r = tune(&run, &config, &out, &["--paced", "--budget=1"]);
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    let knots = format!("--knots={}", knots(XZ).display());
    let c = format!("--config={}", config.display());
    let r = run.starter(
        &[&c, "--unpaced", "tune", "--paced", "run", &knots],
        std::time::Duration::from_secs(30),
    );
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(r.stderr.contains("--unpaced is the simulated robot's lock-step"), "{}", r.stderr);
    let r = run.starter(
        &[&c, "--unhomed", "tune", "--paced", "run", &knots],
        std::time::Duration::from_secs(30),
    );
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(r.stderr.contains("--unhomed"), "{}", r.stderr);
    run.assert_clean();
}

/// The effector's distance from its command over the pick cycle (`run --method pick`, in
/// lock-step from where the simulated robot stands, `--approach`) with the settings `config`:
/// max and RMS, mm.
fn pick_cycle_error(run: &TestRun, config: &Path, name: &str) -> (f64, f64) {
    let config = run.config_from(config, &[]);
    let (c, out) = (format!("--config={}", config.display()), run.out(name));
    let o = format!("--out={}", out.display());
    run.starter_ok(&[&c, &o, "--deterministic", "run", "--method=pick", "--approach"]);
    let summary = read_summary(&out);
    assert!(summary.fault.is_none(), "{name}: {:?}", summary.fault);
    let d = summary.effector.expect("a Delta's effector figures").distance;
    (d.max_mm, d.rms_mm)
}

/// Issue 44, accuracy at speed: the pick cycle — online, time-optimal moves at the motors'
/// limits — with the thesis' gains leaves the effector more than 5 mm off its command
/// (7.7 mm: the 7.9); `config/tuned.toml`, its feed-forward (the jerk's included)
/// tuned on that cycle, keeps it within 2 mm and 0.5 mm RMS. And tuned.toml is
/// `config/qmarc.toml` but for the gains: the same robot, belt, camera and limits.
#[test]
fn the_tuned_settings_follow_the_pick_cycle_within_2_mm() {
    let run = TestRun::new("tunedpick");
    let (thesis_max, _) = pick_cycle_error(&run, &qmarc_tests::shipped_config(), "thesis");
    assert!(thesis_max > 5.0, "the thesis' gains: {thesis_max} mm");
    let (max, rms) = pick_cycle_error(&run, &qmarc_tests::tuned_config(), "tuned");
    assert!(max <= 2.0 && rms <= 0.5, "tuned: max {max} mm, RMS {rms} mm");
    let load = |p: PathBuf| {
        let s = qmarc_config::Settings::load(&p, &qmarc_config::Names::any()).expect("loads");
        let mut v = serde_json::to_value(&s).unwrap();
        v["source"] = serde_json::Value::Null;
        for m in v["motors"].as_array_mut().unwrap() {
            for gain in ["kvff", "kaff", "kjff"] {
                m[gain] = serde_json::Value::Null;
            }
        }
        (s, v)
    };
    let ((thesis, a), (tuned, b)) =
        (load(qmarc_tests::shipped_config()), load(qmarc_tests::tuned_config()));
    assert_eq!(a, b, "tuned.toml differs from qmarc.toml beyond the feed-forward gains");
    for m in 0..3 {
        assert_eq!(thesis.motors[m].kjff, 0.0, "qmarc.toml is eq. 3-1");
        assert!(
            tuned.motors[m].kjff > 0.0 && tuned.motors[m].kaff > 1_000.0 * thesis.motors[m].kaff
        );
    }
    run.assert_clean();
}

/// `tune … run --method pick` tunes on the pick cycle, a path with no knot file: its files
/// say so, and the gains it writes include the jerk feed-forward when it is tuned.
#[test]
fn tuning_runs_on_the_pick_cycle() {
    let run = TestRun::new("tunepick");
    let config = run.config_with(&[("state_file", "\"\"")]);
    let (c, o) = (format!("--config={}", config.display()), run.out("t"));
    let out = format!("--out={}", o.display());
    let r = run.starter(
        &[&c, &out, "tune", "--params=kjff", "--budget=3", "run", "--method=pick"],
        std::time::Duration::from_secs(1200),
    );
    assert_eq!(r.code, Some(0), "{}{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("on the pick path of [pick]"), "{}", r.stdout);
    let gains = std::fs::read_to_string(o.join("tuned-gains.toml")).unwrap();
    assert!(gains.contains("the pick path of [pick]") && gains.contains("kjff = "), "{gains}");
    let summary = std::fs::read_to_string(o.join("tune-summary.json")).unwrap();
    assert!(summary.contains("\"knots\": \"\""), "{summary}");
    run.assert_clean();
}
