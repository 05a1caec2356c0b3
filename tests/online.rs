//! Online moves to a target (issue 30): `qmarc-starter move --to | --xyz [--linear]
//! [--speed]` through the real processes on the simulated robot — where the move ends, that
//! its sampled commands keep every joint's limits, the straight line, the refusals.

use qmarc_plugins::motion::MotionLimits;
use qmarc_plugins::motion::sampled_ratio;
use qmarc_proto::MAX_MOTORS;
use qmarc_tests::{TestRun, read_gather, read_summary};
use std::path::Path;
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_secs(120);

/// `qmarc-starter --config=CONFIG --out=OUT --deterministic move ARGS…`.
fn move_to(run: &TestRun, config: &Path, out: &Path, args: &[&str]) -> qmarc_tests::Finished {
    let (config, out) =
        (format!("--config={}", config.display()), format!("--out={}", out.display()));
    let mut all = vec![config.as_str(), out.as_str(), "--deterministic", "move"];
    all.extend_from_slice(args);
    run.starter(&all, TIMEOUT)
}

/// The settings of `config`, as the starter reads them.
fn settings(config: &Path) -> qmarc_config::Settings {
    qmarc_config::Settings::load(config, &qmarc_config::Names::any()).expect("settings")
}

/// The commands of gather.csv's rows, one array per row.
fn commands(out: &Path) -> Vec<[f64; MAX_MOTORS]> {
    let (header, rows) = read_gather(out);
    let col = |m: usize| header.iter().position(|h| *h == format!("cmd{}", m + 1)).unwrap();
    rows.iter()
        .map(|r| {
            let mut c = [0.0; MAX_MOTORS];
            for (m, cm) in c.iter_mut().enumerate().take(3) {
                *cm = r[col(m)];
            }
            c
        })
        .collect()
}

/// [`sampled_ratio`]'s rounding: a third difference of positions of 10⁴ counts over T³.
const ROUNDING: f64 = 1e-6;

/// `move --to` ends exactly on the target, every motor arriving together, the sampled
/// commands within every limit; at half speed the same move takes twice as long.
#[test]
fn a_move_to_joint_counts_ends_there_within_the_limits() {
    let run = TestRun::new("moveto");
    let config = run.config_with(&[]);
    let s = settings(&config);
    let limits = MotionLimits::of(&s);
    let out = run.out("full");
    let r = move_to(&run, &config, &out, &["--to=3000,-2500,800"]);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("QMARC move: ok"), "{}", r.stdout);
    let summary = read_summary(&out);
    assert_eq!((summary.mode.to_string().as_str(), summary.trajectory.as_str()), ("move", "move"));
    let cmd = commands(&out);
    assert_eq!(cmd[0][..3], [0.0, 0.0, 0.0]);
    assert_eq!(cmd.last().unwrap()[..3], [3000.0, -2500.0, 800.0]);
    assert!(sampled_ratio(&cmd, 3, s.period_s(), &limits) <= 1.0 + ROUNDING);
    // Time-synchronised: the motors stop moving at the same sample.
    let stops: Vec<usize> = (0..3)
        .map(|m| (1..cmd.len()).rev().find(|&i| cmd[i][m] != cmd[i - 1][m]).unwrap())
        .collect();
    assert!(stops.iter().max().unwrap() - stops.iter().min().unwrap() <= 1, "{stops:?}");
    let half = run.out("half");
    let r = move_to(&run, &config, &half, &["--to=3000,-2500,800", "--speed=0.5"]);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let (c_full, c_half) = (summary.cycles as f64, read_summary(&half).cycles as f64);
    assert!((c_half / c_full - 2.0).abs() < 0.05, "{c_full} and {c_half} cycles");
    // Every global option holds: gather every 4th cycle.
    let every = run.out("every");
    let r = move_to(&run, &config, &every, &["--to=3000,-2500,800", "--gather-every=4"]);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert_eq!(commands(&every).len(), commands(&out).len().div_ceil(4));
    run.assert_clean();
}

/// `move --xyz` (joint space) ends with the effector on the point; `--linear` goes there on
/// the straight line, every command within 0.1 mm of it, every joint within its limits.
#[test]
fn a_move_to_a_point_ends_on_it_and_the_linear_one_keeps_to_the_line() {
    let run = TestRun::new("movexyz");
    let config = run.config_with(&[]);
    let s = settings(&config);
    let robot = s.robot().expect("[robot]");
    let limits = MotionLimits::of(&s);
    let effector = |c: &[f64; MAX_MOTORS]| robot.point_of(&[c[0], c[1], c[2]]).unwrap() * 1e3;
    let target = qmarc_kinematics::Point::new(60.0, -40.0, -680.0);
    for (name, linear) in [("joint", false), ("line", true)] {
        let out = run.out(name);
        let mut args = vec!["--xyz=60,-40,-680"];
        if linear {
            args.push("--linear");
        }
        let r = move_to(&run, &config, &out, &args);
        assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
        let cmd = commands(&out);
        let end = effector(cmd.last().unwrap());
        assert!((end - target).norm() < 1e-6, "{name}: ends at {end:?}");
        assert!(sampled_ratio(&cmd, 3, s.period_s(), &limits) <= 1.0 + ROUNDING, "{name}");
        let start = effector(&cmd[0]);
        let axis = (target - start).normalize();
        let off_line = cmd
            .iter()
            .map(|c| {
                let d = effector(c) - start;
                (d - axis * d.dot(&axis)).norm()
            })
            .fold(0.0, f64::max);
        if linear {
            assert_eq!(read_summary(&out).trajectory, "linear");
            assert!(off_line < 0.1, "the line is left by {off_line} mm");
        } else {
            assert!(off_line > 1.0, "a joint-space move is not a line ({off_line} mm)");
        }
    }
    run.assert_clean();
}

/// What a move refuses before anything is enabled: a point out of reach, a target beyond the
/// soft limits, a line without a point, a speed out of (0, 1], an unhomed robot.
#[test]
fn a_move_is_refused_before_anything_moves() {
    let run = TestRun::new("moverefused");
    let config = run.config_with(&[]);
    let refused = |args: &[&str], says: &str| {
        let r = move_to(&run, &config, &run.out("refused"), args);
        assert_eq!(r.code, Some(3), "{args:?}: {}\n{}", r.stdout, r.stderr);
        assert!(r.stderr.contains(says), "{args:?}: {}", r.stderr);
    };
    refused(&["--xyz=0,0,-200"], "--xyz: 0.0, 0.0, -200.0 mm is unreachable");
    refused(
        &["--to=0,0,12000"],
        "--to: motor 3 would go to 12000.0 counts, outside its soft limits [-9000, 10000]",
    );
    refused(&["--to=1,2"], "--to: one position per motor in use: 3 numbers, found 2");
    refused(&["--speed=1.5", "--to=1,2,3"], "--speed: must be > 0 and ≤ 1");
    refused(&["--to=1,2,3", "--linear"], "--xyz");
    let unhomed = run.config_as(
        "unhomed.toml",
        &qmarc_tests::default_config(),
        &[("homed", "false"), ("state_file", "\"\"")],
    );
    let r = move_to(&run, &unhomed, &run.out("unhomed"), &["--to=100,100,100"]);
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("not homed"), "{}", r.stderr);
    run.assert_clean();
}
