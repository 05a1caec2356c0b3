//! `qmarc-starter serve` and `qmarc cmd` (issue 30): the robot holds and moves as commands
//! arrive over `qmarc/command`, a new target takes over mid-motion without a jump, refusals
//! say why, and the session ends as any move ends — on `quit`, on Ctrl-C, and with every
//! process killed in turn.

use qmarc_plugins::motion::MotionLimits;
use qmarc_plugins::motion::sampled_ratio;
use qmarc_proto::MAX_MOTORS;
use qmarc_tests::{Finished, TestRun, bin_dir, read_gather, read_summary, run_with_timeout};
use std::path::Path;
use std::process::{Child, Command};
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(60);

/// [`sampled_ratio`]'s rounding: a third difference of positions of 10⁴ counts over T³.
const ROUNDING: f64 = 1e-6;

/// A serving session of `run` on the settings `config`, lock-step.
fn serve(run: &TestRun, config: &Path, extra: &[&str]) -> Child {
    let (config, out) =
        (format!("--config={}", config.display()), format!("--out={}", run.out("out").display()));
    let mut args = vec![config.as_str(), out.as_str(), "--deterministic"];
    args.extend_from_slice(extra);
    args.push("serve");
    let child = run.spawn_starter(&args);
    let started = Instant::now();
    while !cmd(run, &["status"]).stdout.contains("loop serving") {
        assert!(started.elapsed() < TIMEOUT, "the session did not start serving");
        std::thread::sleep(Duration::from_millis(20));
    }
    child
}

/// `qmarc cmd --iox-prefix … ARGS`.
fn cmd(run: &TestRun, args: &[&str]) -> Finished {
    run.cmd(args)
}

/// `qmarc cmd ARGS`, which must be accepted.
fn accepted(run: &TestRun, args: &[&str]) -> String {
    let r = cmd(run, args);
    assert_eq!(r.code, Some(0), "{args:?}: {}\n{}", r.stdout, r.stderr);
    r.stdout
}

/// The commands of gather.csv, one array per row.
fn commands(out: &Path) -> Vec<[f64; MAX_MOTORS]> {
    let (header, rows) = read_gather(out);
    let col = |m: usize| header.iter().position(|h| *h == format!("cmd{}", m + 1)).unwrap();
    rows.iter().map(|r| std::array::from_fn(|m| if m < 3 { r[col(m)] } else { 0.0 })).collect()
}

fn settings(config: &Path) -> qmarc_config::Settings {
    qmarc_config::Settings::load(config, &qmarc_config::Names::any()).expect("settings")
}

/// The numbers after `label` in a status.
fn numbers_after(status: &str, label: &str) -> Vec<f64> {
    let line = status
        .lines()
        .find(|l| l.trim_start().starts_with(label))
        .unwrap_or_else(|| panic!("no {label} in {status}"));
    line.trim_start()[label.len()..].split_whitespace().filter_map(|w| w.parse().ok()).collect()
}

/// Moves, a target replaced mid-motion, a line, refusals, quit: the whole session's commands
/// keep every joint's limits, each move ends where it was sent, and the session's data files
/// are those of any move.
#[test]
fn serve_takes_moves_and_new_targets_mid_motion_within_the_limits() {
    let run = TestRun::new("serve");
    let config = run.config_with(&[]);
    let s = settings(&config);
    let child = serve(&run, &config, &[]);
    assert!(accepted(&run, &["status"]).starts_with("at rest"));
    // A slow move (over five seconds: a status command that starts late on a loaded machine
    // still finds it moving), replaced while it runs by one the other way at full speed.
    assert!(accepted(&run, &["move", "--to=3000,-2000,1000", "--speed=0.01"]).contains("move 1"));
    // Taken by the loop in its next cycle, whenever a loaded machine runs it.
    let started = Instant::now();
    while !accepted(&run, &["status"]).starts_with("moving") {
        assert!(started.elapsed() < TIMEOUT, "the move was not taken");
        std::thread::sleep(Duration::from_millis(10));
    }
    accepted(&run, &["move", "--to=-1500,2500,500"]);
    let done = accepted(&run, &["wait"]);
    assert_eq!(numbers_after(&done, "command"), [-1500.0, 2500.0, 500.0], "{done}");
    // A straight line to a point, from rest.
    accepted(&run, &["move", "--xyz=40,-30,-660", "--linear"]);
    let done = accepted(&run, &["wait"]);
    let at = numbers_after(&done, "effector");
    assert!((at[0] - 40.0).abs() < 0.01 && (at[1] + 30.0).abs() < 0.01, "{done}");
    // Refusals: said at once, with the reason; nothing moves.
    let r = cmd(&run, &["move", "--xyz=0,0,-200"]);
    assert_eq!(r.code, Some(3), "{}", r.stdout);
    assert!(r.stdout.starts_with("refused (unreachable): 0.0, 0.0, -200.0 mm is unreachable"));
    let r = cmd(&run, &["move", "--to=0,0,12000"]);
    assert_eq!(r.code, Some(3), "{}", r.stdout);
    assert!(r.stdout.contains("refused (soft_limits): motor 3 would go to 12000.0 counts"));
    let r = cmd(&run, &["move", "--to=1,2,3", "--speed=2"]);
    assert!(r.stdout.contains("refused (bad_request): speed must be > 0 and ≤ 1"), "{}", r.stdout);
    accepted(&run, &["quit"]);
    let r = qmarc_tests::wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("QMARC serve: ok"), "{}", r.stdout);
    let out = run.out("out");
    assert_eq!(read_summary(&out).mode.to_string(), "serve");
    let cmds = commands(&out);
    let ratio = sampled_ratio(&cmds, 3, s.period_s(), &MotionLimits::of(&s));
    assert!(ratio <= 1.0 + ROUNDING, "the session's commands exceed a limit: ratio {ratio}");
    // Once served, the session is gone: a command says so.
    let r = cmd(&run, &["status"]);
    assert_eq!(r.code, Some(1), "{}\n{}", r.stdout, r.stderr);
    run.assert_clean();
}

/// Ctrl-C ends a serving session as it ends any move; kill -9 of the hwserver, the
/// controller or the starter mid-move ends it with the motors disabled and says what
/// happened; nothing is left behind.
#[test]
fn serve_ends_as_any_move_does_under_ctrl_c_and_kill_9() {
    use nix::sys::signal::Signal;
    for victim in ["qmarc-starter", "qmarc-hwserver", "qmarc-controller", "ctrl-c"] {
        let run = TestRun::new(&format!("servekill{}", victim.len()));
        let config = run.config_with(&[]);
        let child = serve(&run, &config, &[]);
        accepted(&run, &["move", "--to=4000,4000,4000", "--speed=0.05"]);
        // Killed once the move is under way (its command has left 0), however late.
        let started = Instant::now();
        while numbers_after(&accepted(&run, &["status"]), "command")[0] <= 0.0 {
            assert!(started.elapsed() < TIMEOUT, "{victim}: the move did not begin");
            std::thread::sleep(Duration::from_millis(10));
        }
        let pid = match victim {
            "ctrl-c" | "qmarc-starter" => child.id(),
            name => run
                .processes()
                .into_iter()
                .find(|(_, c)| c.contains(name))
                .map(|(pid, _)| pid)
                .expect("the victim runs"),
        };
        let signal = if victim == "ctrl-c" { Signal::SIGINT } else { Signal::SIGKILL };
        qmarc_tests::send_signal(pid, signal);
        let r = qmarc_tests::wait_with_timeout(child, TIMEOUT);
        match victim {
            "ctrl-c" => {
                assert_eq!(r.code, Some(130), "{}\n{}", r.stdout, r.stderr);
                qmarc_tests::assert_aborted_with_motors_disabled(&run.out("out"));
            }
            "qmarc-starter" => assert_eq!(r.code, None, "killed"),
            name => {
                assert_eq!(r.code, Some(2), "{victim}: {}\n{}", r.stdout, r.stderr);
                assert!(
                    r.stderr.contains(&format!("{name} was killed by SIGKILL")),
                    "{}",
                    r.stderr
                );
                // Issue 42, item 10: the session's data outlive its killed controller, up to
                // its last cycle (its move to 4000 counts begun).
                let out = run.out("out");
                let (_, rows) = read_gather(&out);
                assert!(rows.iter().any(|r| r[2] > 0.0), "{victim}: the move is in gather.csv");
                let s = read_summary(&out);
                assert_eq!(s.gathered_rows, rows.len() as u64, "{victim}");
                if name == "qmarc-controller" {
                    let cut = qmarc_report::summary::WarningKind::CutShort;
                    assert!(s.warnings.iter().any(|w| w.kind == cut), "{:?}", s.warnings);
                }
            }
        }
        // Nothing serves any more, and nothing is left (the children of a killed starter stop
        // on their parent's death, motors disabled by the hwserver first).
        let deadline = Instant::now() + TIMEOUT;
        while !run.processes().is_empty() {
            assert!(Instant::now() < deadline, "{victim}: {:?} left", run.processes());
            std::thread::sleep(Duration::from_millis(20));
        }
        if victim == "qmarc-starter" {
            run.location().remove_files();
        }
        run.assert_clean();
    }
}

/// `qmarc cmd path FILE` (`qmarc/path`, what the bridge's joint trajectories use): the robot
/// follows a PVT knot file from rest, through every knot at its time; a path while it moves,
/// one that does not start where it rests and a malformed file are refused, saying why.
#[test]
fn serve_follows_a_path_through_its_knots_at_their_times() {
    let run = TestRun::new("servepath");
    let config = run.config_with(&[]);
    let s = settings(&config);
    let child = serve(&run, &config, &[]);
    // The step (0.4 s), then held where it ends for longer than any command can take to
    // start (issue 48: a second command that started after a 0.4 s path had ended was
    // refused for another reason): the path runs until the test stops it.
    let step = qmarc_tests::smooth_step_pvt(2000.0, 8);
    let (knots, last) = step.trim_end().rsplit_once('\n').unwrap();
    let held =
        format!("{knots}\n{}\nX 2000 0 50 Y 0 0 50 Z 0 0 50\n", last.replace(" 50", " 120000"));
    let file = run.out("step.pvt");
    std::fs::write(&file, held).unwrap();
    let file = file.display().to_string();
    assert!(accepted(&run, &["path", &file]).starts_with("accepted (path 1)"));
    let r = cmd(&run, &["path", &file]);
    assert_eq!(r.code, Some(3), "{}", r.stdout);
    assert!(r.stdout.starts_with("refused (moving): a path starts from rest"), "{}", r.stdout);
    // Stopped in its hold (once the step is done), it rests where the step ended.
    let started = Instant::now();
    while numbers_after(&accepted(&run, &["status"]), "command")[0] != 2000.0 {
        assert!(started.elapsed() < TIMEOUT, "the step did not end");
        std::thread::sleep(Duration::from_millis(20));
    }
    accepted(&run, &["stop"]);
    let done = accepted(&run, &["wait"]);
    assert_eq!(numbers_after(&done, "command"), [2000.0, 0.0, 0.0], "{done}");
    // From where it rests now, the same path's first knot is 2000 counts away.
    let r = cmd(&run, &["path", &file]);
    assert_eq!(r.code, Some(3), "{}", r.stdout);
    assert!(r.stdout.contains("point 1: at time 0 the robot is where it rests"), "{}", r.stdout);
    // Issue 42: with --approach, first a jerk-limited move to its first knot (back to 0),
    // then the path (README's example).
    let step = run.out("step2.pvt");
    std::fs::write(&step, qmarc_tests::smooth_step_pvt(2000.0, 8)).unwrap();
    let step = step.display().to_string();
    assert!(accepted(&run, &["path", "--approach", &step]).starts_with("accepted (path 3)"));
    let done = accepted(&run, &["wait"]);
    assert_eq!(numbers_after(&done, "command"), [2000.0, 0.0, 0.0], "{done}");
    std::fs::write(&file, "X 0 0 50 Y 0 0 50 Z 0 0 50\nX 10 0 50 Y 0 zero 50 Z 0 0 50\n").unwrap();
    let r = cmd(&run, &["path", &file]);
    // Refused as the starter refuses a bad knot file (exit 3), naming file and line.
    assert_eq!(r.code, Some(3), "{}", r.stdout);
    assert!(r.stdout.starts_with("refused (bad_request): "), "{}", r.stdout);
    assert!(r.stdout.contains(&format!("{file}:2:")), "file and line: {}", r.stdout);
    accepted(&run, &["quit"]);
    let r = qmarc_tests::wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    // The path in gather.csv: from rest at 0, through each knot at its time, to rest.
    let cmds = commands(&run.out("out"));
    let start = cmds.iter().position(|c| c[0] != 0.0).expect("the path ran") - 1;
    let knot_every = (0.05 / s.period_s()).round() as usize;
    for (i, line) in qmarc_tests::smooth_step_pvt(2000.0, 8).lines().enumerate() {
        let p: f64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
        let at = cmds[start + i * knot_every];
        assert!((at[0] - p).abs() < 1e-6 && at[1] == 0.0, "knot {i}: {p} but {at:?}");
    }
    let ratio = sampled_ratio(&cmds, 3, s.period_s(), &MotionLimits::of(&s));
    assert!(ratio <= 1.0 + ROUNDING, "the path exceeds a limit: ratio {ratio}");
    run.assert_clean();
}

/// Issue 42, item 1: a second session on a live session's iceoryx2 prefix is refused before
/// it touches anything, naming the live one (its pid, its command, its output folder), and
/// the live one goes on answering as before, its files all there.
#[test]
fn a_live_sessions_prefix_is_refused_and_the_session_goes_on() {
    let run = TestRun::new("liveprefix");
    let config = run.config_with(&[]);
    let child = serve(&run, &config, &[]);
    let files = run.location().files();
    let run_file = qmarc_proto::service::run_file(&run.prefix);
    assert!(files.contains(&run_file), "{files:?}");
    let config_arg = format!("--config={}", config.display());
    for what in [&["serve"][..], &["home"], &["move", "--to", "-100,0,0"]] {
        let other = run.out("other");
        let mut args = vec![config_arg.as_str(), "--deterministic"];
        let out = format!("--out={}", other.display());
        args.push(&out);
        args.extend_from_slice(what);
        let r = run.starter(&args, TIMEOUT);
        assert_eq!(r.code, Some(3), "{what:?}: {}\n{}", r.stdout, r.stderr);
        let said = format!(
            "iceoryx2 prefix `{}` belongs to a live serving session: pid {} (",
            run.prefix,
            child.id()
        );
        assert!(r.stderr.contains(&said), "{what:?}: {}", r.stderr);
        assert!(r.stderr.contains(&format!("output folder {}", run.out("out").display())));
        assert!(r.stderr.contains(" serve), "), "its command: {}", r.stderr);
        assert!(!other.exists(), "nothing of the refused run was made");
    }
    // A prefix the live one starts with would take its files when its run ends: refused too.
    let cut = run.prefix[..run.prefix.len() - 1].rfind('_').expect("a prefix of parts");
    let short = &run.prefix[..=cut];
    let mut c = Command::new(bin_dir().join("qmarc-starter"));
    c.args([format!("--iox-prefix={short}"), format!("--iox-root={}", run.root())])
        .args([config_arg.as_str(), "--deterministic", "step"])
        .current_dir(qmarc_tests::workspace());
    let r = run_with_timeout(&mut c, TIMEOUT);
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    let said = format!("`{short}` would take the files of `{}`, which belongs to", run.prefix);
    assert!(r.stderr.contains(&said), "{}", r.stderr);
    // The live session's own files are all still there (its run file, its progress and
    // gather pages, its services; a client's connection comes and goes), and it answers as
    // before.
    let left = run.location().files();
    let own = |f: &&std::path::PathBuf| {
        let name = f.to_string_lossy();
        name.ends_with("run.json")
            || name.ends_with("_progress")
            || name.ends_with("_gather")
            || name.ends_with(".service")
    };
    let kept: Vec<_> = files.iter().filter(own).collect();
    assert!(kept.len() >= 4, "{files:?}");
    assert!(kept.iter().all(|f| left.contains(f)), "{kept:?}\n{left:?}");
    let status = accepted(&run, &["status"]);
    assert!(status.starts_with("at rest; loop serving"), "{status}");
    accepted(&run, &["quit"]);
    let r = qmarc_tests::wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    // It said, once serving, where it was and how to command it.
    let said = format!(
        "qmarc-starter: serving under iceoryx2 prefix {}, data to {}\n  command it: qmarc cmd \
         --iox-prefix {} status",
        run.prefix,
        run.out("out").display(),
        run.prefix
    );
    assert!(r.stderr.contains(&said), "{}", r.stderr);
    run.assert_clean();
}

/// Issue 42, items 2, 4 and 5: with two serving sessions and no prefix, `qmarc cmd` refuses
/// and lists them; every answer names the session it addressed; negative coordinates are
/// typed as they are; what the starter would refuse is refused at once in its words, with its
/// exit code; quit says what it does.
#[test]
fn qmarc_cmd_names_its_session_and_refuses_what_the_starter_refuses() {
    let run = TestRun::new("twosess");
    let config = run.config_with(&[]);
    let first = serve(&run, &config, &[]);
    // A second session under the same iceoryx2 root, another prefix (not one that starts
    // with the first's: a run removes the files that start with its prefix).
    let second_prefix = format!("qu{}", &run.prefix[2..]);
    let second = Command::new(bin_dir().join("qmarc-starter"))
        .args([
            format!("--iox-prefix={second_prefix}"),
            format!("--iox-root={}", run.root()),
            format!("--config={}", config.display()),
            format!("--out={}", run.out("second").display()),
            "--deterministic".into(),
            "serve".into(),
        ])
        .current_dir(qmarc_tests::workspace())
        .stdin(std::process::Stdio::null())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let root = format!("--iox-root={}", run.root());
    let anyone = |args: &[&str]| {
        let mut c = Command::new(bin_dir().join("qmarc"));
        c.arg("cmd").arg(&root).args(args);
        run_with_timeout(&mut c, TIMEOUT)
    };
    let started = Instant::now();
    let r = loop {
        let r = anyone(&["status"]);
        if r.stderr.contains(&second_prefix) {
            break r;
        }
        assert!(started.elapsed() < TIMEOUT, "the second session did not serve: {}", r.stderr);
        std::thread::sleep(Duration::from_millis(50));
    };
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("2 serving sessions run; say which with --iox-prefix"),
        "{}",
        r.stderr
    );
    for (prefix, pid, out) in [
        (&run.prefix, first.id(), run.out("out")),
        (&second_prefix, second.id(), run.out("second")),
    ] {
        let line = format!("--iox-prefix {prefix}   pid {pid} (");
        assert!(r.stderr.contains(&line), "{line} in {}", r.stderr);
        assert!(r.stderr.contains(&format!("output folder {}, started ", out.display())));
    }
    assert!(r.stdout.is_empty(), "nothing was sent: {}", r.stdout);
    // Every answer names its session.
    let named = format!(
        "  session {}: pid {}, output folder {}",
        run.prefix,
        first.id(),
        run.out("out").display()
    );
    let moved = accepted(&run, &["move", "--xyz", "-60,0,-650", "--speed", "0.5"]);
    assert!(moved.starts_with("accepted (move 1)\n") && moved.contains(&named), "{moved}");
    let done = accepted(&run, &["wait"]);
    assert!(done.contains(&named), "{done}");
    assert!((numbers_after(&done, "effector")[0] + 60.0).abs() < 0.01, "{done}");
    // What the starter refuses, in its words and with its code (3), before anything is sent.
    let starter = run.starter(
        &[&format!("--config={}", config.display()), "--print-settings", "move", "--to", "1,2,3,4"],
        TIMEOUT,
    );
    let words = "--to: one position per motor in use: 3 numbers, found 4";
    assert!(starter.code == Some(3) && starter.stderr.contains(words), "{}", starter.stderr);
    let r = cmd(&run, &["move", "--to", "1,2,3,4"]);
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    let refused = format!("refused (bad_request): {words}\n{named}");
    assert!(r.stdout.starts_with(&refused), "{}", r.stdout);
    let r = cmd(&run, &["move", "--to", "100,0,0", "--speed", "1e-300"]);
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(
        r.stdout
            .starts_with("refused (bad_request): no jerk-limited profile from the command's state"),
        "{}",
        r.stdout
    );
    let status = accepted(&run, &["status"]);
    assert!(status.contains("moves accepted 1, settled 1"), "nothing else was taken: {status}");
    // Quit says what it does.
    for (prefix, child) in [(run.prefix.clone(), first), (second_prefix.clone(), second)] {
        let r = anyone(&[&format!("--iox-prefix={prefix}"), "quit"]);
        assert!(
            r.stdout.starts_with("accepted (quit): the robot stops, then the session ends"),
            "{}\n{}",
            r.stdout,
            r.stderr
        );
        let end = qmarc_tests::wait_with_timeout(child, TIMEOUT);
        assert_eq!(end.code, Some(0), "{}\n{}", end.stdout, end.stderr);
    }
    run.assert_clean();
}
