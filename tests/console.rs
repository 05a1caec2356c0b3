//! The console, `qmarc`, driven as a user drives it: the real binary in an 80×24 tmux pane,
//! keys sent with `send-keys`, the screen read with `capture-pane`. Each test has its own tmux
//! server (a socket in its scratch directory) and its own iceoryx2 prefix, passed through the
//! console to every starter run.

use qmarc_tests::{
    TestRun, assert_aborted_with_motors_disabled, bin_dir, knots, processes_matching, read_summary,
};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// A tmux server of one test, with one 80×24 pane; killed on drop.
struct Tmux {
    socket: PathBuf,
}

impl Tmux {
    /// Starts `command` (a shell command line) in a detached 80×24 session, in `cwd`. The pane
    /// stays after the command ends, so its exit status and last output can be read.
    fn start(dir: &Path, cwd: &Path, command: &str) -> Tmux {
        let tmux = Tmux { socket: dir.join("tmux.sock") };
        let ok = Command::new("tmux")
            .arg("-S")
            .arg(&tmux.socket)
            .args(["-f", "/dev/null", "new-session", "-d", "-x", "80", "-y", "24", "-c"])
            .arg(cwd)
            .arg(command)
            .args([";", "set-option", "-g", "remain-on-exit", "on"])
            .status()
            .unwrap_or_else(|e| panic!("cannot run tmux (install it: .ci/run does): {e}"));
        assert!(ok.success(), "tmux new-session failed");
        tmux
    }

    fn tmux(&self, args: &[&str]) -> String {
        let out = Command::new("tmux").arg("-S").arg(&self.socket).args(args).output();
        let out = out.expect("tmux");
        assert!(out.status.success(), "tmux {args:?}: {}", String::from_utf8_lossy(&out.stderr));
        String::from_utf8_lossy(&out.stdout).into_owned()
    }

    /// The pane's text.
    fn screen(&self) -> String {
        self.tmux(&["capture-pane", "-p"])
    }

    /// Sends tmux key names (`Tab`, `F6`, `C-c`).
    fn keys(&self, keys: &[&str]) {
        let mut args = vec!["send-keys"];
        args.extend_from_slice(keys);
        self.tmux(&args);
    }

    /// Types `text` literally.
    fn type_text(&self, text: &str) {
        self.tmux(&["send-keys", "-l", text]);
    }

    /// Waits until the screen satisfies `pred`; panics with the screen after `timeout`.
    fn wait_for(&self, what: &str, timeout: Duration, pred: impl Fn(&str) -> bool) -> String {
        let start = Instant::now();
        loop {
            let s = self.screen();
            if pred(&s) {
                return s;
            }
            assert!(start.elapsed() < timeout, "waited {timeout:?} for {what}; the screen:\n{s}");
            std::thread::sleep(Duration::from_millis(100));
        }
    }

    /// Waits for the console to end; returns its exit status and the screen it left, with the
    /// scrollback. The status is the one [`console_command`]'s shell prints: tmux 3.3 at times
    /// leaves a dead pane's process unreaped, without a status.
    fn wait_exit(&self, timeout: Duration) -> (i32, String) {
        // The shell's line is the last one printed: on the screen, by the cursor.
        self.wait_for("the console to end", timeout, |s| s.contains("[qmarc exited "));
        let all = self.tmux(&["capture-pane", "-p", "-S", "-"]);
        let status = all.split("[qmarc exited ").nth(1).and_then(|r| r.split(']').next());
        (status.and_then(|s| s.parse().ok()).expect("exit status"), all)
    }

    /// Moves the focus with Tab until the message line names `field`: one Tab at a time, each
    /// waited for (the message line changes), so no key is ever queued past the target.
    fn focus(&self, field: &str) {
        let message = |s: &str| s.lines().rev().nth(1).unwrap_or_default().trim().to_string();
        for _ in 0..80 {
            let before = message(&self.screen());
            if before.starts_with(field) {
                return;
            }
            self.keys(&["Tab"]);
            self.wait_for("the focus to move", Duration::from_secs(10), |s| message(s) != before);
        }
        panic!("no field `{field}` reached with Tab; the screen:\n{}", self.screen());
    }
}

impl Drop for Tmux {
    fn drop(&mut self) {
        let _ = Command::new("tmux").arg("-S").arg(&self.socket).arg("kill-server").status();
        // The server's command line holds the console's (and so the test's prefix): wait
        // until it is gone, so the test's leftover check does not see it.
        let socket = self.socket.display().to_string();
        let start = Instant::now();
        while !processes_matching(&socket).is_empty() && start.elapsed() < Duration::from_secs(10) {
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// The setup page is drawn whole: its last panel and the key bar are there (a capture can
/// catch a screen half-updated).
fn setup_drawn(s: &str) -> bool {
    s.contains("Cancel (leave without saving)")
        && s.lines().last().is_some_and(|l| l.contains("F12"))
}

/// The results page is drawn whole, down to its last figure.
fn results_drawn(s: &str) -> bool {
    s.contains("Results of the last move") && s.contains("missed:")
}

/// The console's command line for `run`, in its scratch directory; the shell prints the exit
/// status when it ends.
fn console_command(run: &TestRun) -> String {
    format!(
        "'{}' --config qmarc.toml --iox-prefix={} --iox-root={}; echo \"[qmarc exited $?]\"",
        bin_dir().join("qmarc").display(),
        run.prefix,
        run.root()
    )
}

/// The `Kp` row of the gains table.
fn kp_row(screen: &str) -> String {
    let row = screen.lines().find(|l| l.contains("│Kp ")).expect("a Kp row");
    row.split("│Kp").nth(1).unwrap_or_default().to_string()
}

#[test]
fn console_edits_a_gain_steps_shows_results_and_charts_saves_and_reloads() {
    let run = TestRun::new("console");
    let sine = knots("sine-3motors.txt");
    let config = run.config_with(&[("knots", &format!("{:?}", sine.display().to_string()))]);
    {
        let tmux = Tmux::start(&run.dir, &run.dir, &console_command(&run));
        let s = tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);
        for section in ["General", "Trajectory", "Step", "Data gathering", "Actions"] {
            assert!(s.contains(section), "section {section} missing:\n{s}");
        }
        assert!(kp_row(&s).trim_start().starts_with("182000"), "shipped Kp M1:\n{s}");

        // Edit Kp of motor 1: typing replaces the value, Tab commits it.
        tmux.focus("Kp M1 =");
        tmux.type_text("185000");
        tmux.keys(&["Tab"]);
        tmux.wait_for("the edited gain", Duration::from_secs(10), |s| {
            kp_row(s).trim_start().starts_with("185000")
        });

        // Step: the console saves, runs the starter, then shows the summary.
        tmux.keys(&["F6"]);
        let s = tmux.wait_for("the step's results", Duration::from_secs(120), results_drawn);
        assert!(s.contains("step: ok"), "the step faulted:\n{s}");
        for want in ["min cnt", "Σ|e| cnt", "Σe² cnt²", "Σ|e| rad", "wake latency", "missed:"]
        {
            assert!(s.contains(want), "{want} missing from the results:\n{s}");
        }
        // The console's figures are the move's own: motor 1's accumulated error as written.
        let summary = read_summary(&run.out("out"));
        let acc = format!("{:.0}", summary.motors[0].accumulated_abs_error_counts);
        assert!(s.contains(&acc), "Σ|e| of motor 1 ({acc}) not shown:\n{s}");

        // The log page has the starter's output, its table included.
        tmux.keys(&["F3"]);
        tmux.wait_for("the starter's output", Duration::from_secs(10), |s| {
            s.contains("qmarc-starter output") && s.contains("data (") && s.contains("timing")
        });

        // Charts: command vs actual, following error, servo period.
        tmux.keys(&["F7"]);
        // All three drawn (a capture can catch the screen half-updated).
        let s = tmux.wait_for("the charts", Duration::from_secs(10), |s| {
            ["command vs actual", "following error", "servo period"].iter().all(|t| s.contains(t))
        });
        assert!(
            s.chars().any(|c| ('\u{2801}'..='\u{28ff}').contains(&c)),
            "no plotted points:\n{s}"
        );

        // Resizing, down to a few cells, redraws without a panic. Each size is waited for
        // by what only a redraw at that size shows: the charts' right border at its column
        // (the old picture, clipped or padded, has it elsewhere), the status bar on row h.
        for (w, h) in [(120, 40), (30, 8), (80, 24)] {
            tmux.tmux(&["resize-window", "-x", &w.to_string(), "-y", &h.to_string()]);
            tmux.wait_for(
                &format!("the charts redrawn at {w}×{h}"),
                Duration::from_secs(10),
                |s| {
                    let rows: Vec<&str> = s.lines().collect();
                    rows.len() == h
                        && rows.iter().any(|r| r.chars().count() == w && r.ends_with('┐'))
                        && rows[h - 1].contains("F2 Home")
                },
            );
        }

        // History: the move with the gains it ran with.
        tmux.keys(&["F8"]);
        tmux.wait_for("the history", Duration::from_secs(10), |s| {
            s.contains("185000/") && s.lines().any(|l| l.contains("│1   step"))
        });

        // Exit, saving.
        tmux.keys(&["F10"]);
        let (status, s) = tmux.wait_exit(Duration::from_secs(20));
        assert_eq!(status, 0, "the console's exit:\n{s}");
        assert!(s.contains("settings saved to qmarc.toml"), "{s}");
        assert!(!s.contains("Gains (one column"), "the terminal was not restored:\n{s}");
    }
    let saved = std::fs::read_to_string(&config).expect("saved settings");
    let first_kp = saved.lines().find(|l| l.starts_with("kp = ")).expect("kp line");
    assert_eq!(first_kp, "kp = 185000.0", "motor 1's Kp in the file");
    assert!(saved.contains("# motors driven, 1‥4"), "comments kept:\n{saved}");

    // Restart: the edited gain is loaded. Edit it again, step with it (which saves it, as the
    // thesis' buttons do), and Cancel: the file is as it was when the console opened.
    {
        let tmux = Tmux::start(&run.dir, &run.dir, &console_command(&run));
        let s = tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);
        assert!(kp_row(&s).trim_start().starts_with("185000"), "the saved gain:\n{s}");
        // The last move's results are loaded at start too.
        tmux.keys(&["F4"]);
        tmux.wait_for("the last results", Duration::from_secs(10), |s| s.contains("step: ok"));
        tmux.keys(&["F1"]);
        tmux.focus("Kp M1 =");
        tmux.type_text("190000");
        tmux.keys(&["Tab"]);
        tmux.wait_for("the unsaved edit", Duration::from_secs(10), |s| {
            kp_row(s).trim_start().starts_with("190000")
        });
        tmux.keys(&["F6"]);
        tmux.wait_for("the second step's results", Duration::from_secs(120), |s| {
            s.contains("step: ok") && s.contains("s ago)")
        });
        assert!(
            std::fs::read_to_string(&config).expect("settings").contains("kp = 190000.0"),
            "the step ran with the edited gain, saved first"
        );
        tmux.keys(&["F12"]);
        let (status, s) = tmux.wait_exit(Duration::from_secs(20));
        assert_eq!(status, 0, "the console's exit:\n{s}");
        assert!(s.contains("left without saving"), "{s}");
    }
    assert_eq!(std::fs::read_to_string(&config).expect("settings"), saved, "Cancel wrote the file");
    run.assert_clean();
}

/// Settings whose `run` is long enough to stop in the middle: 10 s of a slow raised cosine
/// (offline format, thesis A.2.3.1), in a knot file outside the repository.
fn long_run_config(run: &TestRun) -> PathBuf {
    let long = run.dir.join("long.txt");
    let mut text = String::from("1001\n");
    for i in 0..=1000 {
        let t = f64::from(i) * 0.01;
        let p = (300.0 * (1.0 - (std::f64::consts::PI * t / 5.0).cos())).round();
        text += &format!("{t:.2} {p} {p} {p}\n");
    }
    std::fs::write(&long, text).expect("knot file");
    run.config_with(&[("knots", &format!("{:?}", long.display().to_string()))])
}

/// Waits until the move the console started is under way, and then a little.
fn wait_until_moving(run: &TestRun) {
    qmarc_tests::wait_until_moving(&run.prefix, Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(300));
}

/// Waits up to 30 s until no process of the run is left but the tmux server (whose command
/// line holds the console's, prefix included); panics with `what` and the processes.
fn wait_until_stopped(run: &TestRun, what: &str) {
    let left = || -> Vec<(u32, String)> {
        processes_matching(&run.prefix)
            .into_iter()
            .filter(|(_, c)| !c.starts_with("tmux"))
            .collect()
    };
    let start = Instant::now();
    while !left().is_empty() {
        assert!(start.elapsed() < Duration::from_secs(30), "{what}: {:?}", left());
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A console on [`long_run_config`] that has started the run (F5), which is under way.
fn console_running_a_long_move(run: &TestRun) -> Tmux {
    long_run_config(run);
    let tmux = Tmux::start(&run.dir, &run.dir, &console_command(run));
    tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);
    tmux.keys(&["F5"]);
    wait_until_moving(run);
    tmux
}

#[test]
fn console_blocks_a_step_on_an_invalid_field_and_aborts_a_run_with_motors_disabled() {
    let run = TestRun::new("consabrt");
    let config = long_run_config(&run);
    let before = std::fs::read_to_string(&config).expect("settings");
    let tmux = Tmux::start(&run.dir, &run.dir, &console_command(&run));
    tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);

    // An invalid servo period is shown in place and blocks the step; nothing is written.
    tmux.focus("Period µs:");
    tmux.type_text("abc");
    tmux.keys(&["F6"]);
    // The message names the field.
    tmux.wait_for("the refusal", Duration::from_secs(10), |s| {
        s.contains("cannot step: general.period_us Period µs: invalid type")
    });
    assert_eq!(std::fs::read_to_string(&config).expect("settings"), before, "written anyway");
    assert!(!run.out("out").join("summary.json").exists(), "a move ran");
    // Corrected, the field validates again.
    tmux.type_text("400");
    tmux.keys(&["Tab"]);
    tmux.wait_for("the corrected period", Duration::from_secs(10), |s| !s.contains("blocked by"));

    // Run the trajectory and abort it: the summary says it was stopped, motors disabled.
    tmux.keys(&["F5"]);
    tmux.wait_for("the run", Duration::from_secs(30), |s| s.contains("run running"));
    wait_until_moving(&run);
    tmux.keys(&["F9"]);
    let s = tmux.wait_for("the aborted run's results", Duration::from_secs(60), results_drawn);
    assert_aborted_with_motors_disabled(&run.out("out"));
    assert!(s.contains("FAULT aborted"), "the fault is shown:\n{s}");
    tmux.keys(&["F12"]);
    let (status, s) = tmux.wait_exit(Duration::from_secs(20));
    assert_eq!(status, 0, "{s}");
    drop(tmux);
    run.assert_clean();
}

#[test]
fn plain_subcommands_run_the_starter_without_the_console() {
    let run = TestRun::new("conscli");
    let out = run.out("out");
    let config = qmarc_tests::default_config();
    let mut args = run.isolation_args();
    args.extend([
        format!("--config={}", config.display()),
        format!("--out={}", out.display()),
        "--deterministic".into(),
        "step".into(),
        "--duration=0.05".into(),
    ]);
    let r = qmarc_tests::run_with_timeout(
        Command::new(bin_dir().join("qmarc")).args(&args),
        Duration::from_secs(60),
    );
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("QMARC step: ok"), "{}", r.stdout);
    assert!(read_summary(&out).ok);
    // Bad settings: the starter's error (file, line, field) and exit code, nothing started.
    let bad = run.dir.join("bad.toml");
    std::fs::write(&bad, "[general]\nn_motors = \"x\"\n").expect("bad settings");
    let r = qmarc_tests::run_with_timeout(
        Command::new(bin_dir().join("qmarc"))
            .args([&format!("--config={}", bad.display()), "step"]),
        Duration::from_secs(60),
    );
    assert_ne!(r.code, Some(0));
    assert!(
        r.stderr.contains(&format!("{}:2:12: general.n_motors", bad.display())),
        "{}",
        r.stderr
    );
    run.assert_clean();
}

#[test]
fn closing_the_terminal_during_a_move_stops_it_with_motors_disabled() {
    let run = TestRun::new("conshup");
    let tmux = console_running_a_long_move(&run);
    // The terminal goes away under the console (its window closed, its ssh dropped).
    drop(tmux);
    wait_until_stopped(&run, "left running after the terminal closed");
    assert_aborted_with_motors_disabled(&run.out("out"));
    run.assert_clean();
}

#[test]
fn killing_the_console_during_a_move_stops_it_with_motors_disabled() {
    let run = TestRun::new("conskill");
    let tmux = console_running_a_long_move(&run);
    let console: Vec<u32> = processes_matching(&run.prefix)
        .into_iter()
        .filter(|(_, c)| c.contains("/qmarc --config"))
        .map(|(pid, _)| pid)
        .collect();
    assert_eq!(console.len(), 1, "{:?}", processes_matching(&run.prefix));
    qmarc_tests::send_signal(console[0], nix::sys::signal::Signal::SIGKILL);
    // The starter gets SIGTERM from the kernel (its parent-death signal) and stops the move.
    wait_until_stopped(&run, "the move outlived the console");
    assert_aborted_with_motors_disabled(&run.out("out"));
    drop(tmux);
    run.assert_clean();
}

/// Issue 10, items 8 and 17: every page usable at 80×24 and smaller — the log wraps and
/// scrolls, the charts have legends, the results of a homing show the switches, hints follow
/// the page, Ctrl-U empties a field, the actions fit a small terminal — and a second move is
/// never started while one runs.
#[test]
fn console_pages_are_usable_and_one_move_runs_at_a_time() {
    let run = TestRun::new("conspage");
    let long = run.dir.join("long.txt");
    let mut text = String::from("1001\n");
    for i in 0..=1000 {
        let t = f64::from(i) * 0.01;
        let p = (300.0 * (1.0 - (std::f64::consts::PI * t / 5.0).cos())).round();
        text += &format!("{t:.2} {p} {p} {p}\n");
    }
    std::fs::write(&long, text).expect("knot file");
    run.config_with(&[
        ("knots", &format!("{:?}", long.display().to_string())),
        ("velocity_counts_per_s", "20000.0"),
        ("creep_counts_per_s", "1000.0"),
        ("home_offset_counts", "2000.0"),
    ]);
    let tmux = Tmux::start(&run.dir, &run.dir, &console_command(&run));
    tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);
    let message = |s: &str| s.lines().rev().nth(1).unwrap_or_default().trim().to_string();

    // Ctrl-U empties the focused field (an error then), Esc brings the value back.
    tmux.focus("Period µs:");
    tmux.keys(&["C-u"]);
    tmux.wait_for("the emptied period", Duration::from_secs(10), |s| {
        message(s).contains("invalid type") && s.contains(" Period µs !")
    });
    tmux.keys(&["Escape"]);
    tmux.wait_for("the period back", Duration::from_secs(10), |s| s.contains("Period µs  400"));

    // F5 twice: one move, and the second key says why it did nothing.
    tmux.keys(&["F5", "F5"]);
    wait_until_moving(&run);
    let starters = processes_matching(&run.prefix)
        .into_iter()
        .filter(|(_, c)| c.contains("qmarc-starter"))
        .count();
    assert_eq!(starters, 1, "one move at a time");
    tmux.wait_for("the refusal of a second move", Duration::from_secs(10), |s| {
        message(s).contains("a move is running")
    });
    // The log page's keys, not a stale hint (longer than a row at 80 columns: wrapped above
    // the keys bar, not cut); then abort.
    tmux.keys(&["F3"]);
    tmux.wait_for("the log page's keys", Duration::from_secs(10), |s| {
        let rows: Vec<&str> = s.lines().rev().skip(1).take(2).map(str::trim).collect();
        rows.len() == 2
            && rows[1].starts_with("↑↓ PgUp PgDn scroll")
            && rows[0].ends_with("motor or axis")
    });
    tmux.keys(&["F9"]);
    tmux.wait_for("the aborted run's results", Duration::from_secs(60), results_drawn);
    // The log: the long data line wraps (its end is on the next row, not cut off); Home
    // shows the first line.
    tmux.keys(&["F3"]);
    tmux.wait_for("the wrapped data line", Duration::from_secs(10), |s| {
        let rows: Vec<&str> = s.lines().collect();
        let at = rows.iter().position(|r| r.contains("  data (") && r.contains("out/gather.csv"));
        // The row after it continues the line (no indent): it was wrapped, not cut.
        at.and_then(|i| rows.get(i + 1)).is_some_and(|next| {
            next.strip_prefix('│').is_some_and(|t| t.starts_with(|c: char| c.is_alphanumeric()))
        })
    });
    tmux.keys(&["Home"]);
    tmux.wait_for("the first log line", Duration::from_secs(10), |s| {
        s.contains("── run ──") && s.contains("(End: follow)")
    });
    // The charts name their lines.
    tmux.keys(&["F7"]);
    tmux.wait_for("the legends", Duration::from_secs(10), |s| {
        s.contains("━ command") && s.contains("━ actual") && s.contains("━ period")
    });
    // Home: the results show where each switch was found.
    tmux.keys(&["F2"]);
    let s = tmux.wait_for("the homing results", Duration::from_secs(90), |s| {
        s.contains("home: ok") && s.contains("M3 switch found")
    });
    assert!(s.contains("M1 switch found") && s.contains("reads 0"), "{s}");
    // A report longer than the screen scrolls: End shows its last line.
    tmux.keys(&["End"]);
    tmux.wait_for("the end of the report", Duration::from_secs(10), |s| s.contains("missed:"));
    // A short terminal: the actions shrink to one line instead of overflowing.
    tmux.keys(&["F1"]);
    tmux.tmux(&["resize-window", "-x", "80", "-y", "18"]);
    tmux.wait_for("the compact actions", Duration::from_secs(10), |s| {
        s.contains("ready: F2 F5 F6 F10 F12")
    });
    tmux.keys(&["F12"]);
    let (status, _) = tmux.wait_exit(Duration::from_secs(20));
    assert_eq!(status, 0);
    drop(tmux);
    run.assert_clean();
}

/// Issue 15's Tune action: Ctrl-T tunes the gains on the settings' path (the starter's
/// `tune run`), the progress comes as lines in the log, the results page shows the before →
/// after figures and gains, and Ctrl-A puts the tuned gains in the form, which F10 saves.
#[test]
fn console_tunes_the_gains_on_the_path_and_takes_them() {
    let run = TestRun::new("constune");
    let xz = knots("xz-pick-place-spline.txt");
    let config = run.config_with(&[
        ("knots", &format!("{:?}", xz.display().to_string())),
        ("tune.budget", "6"),
    ]);
    let tmux = Tmux::start(&run.dir, &run.dir, &console_command(&run));
    tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);
    let shipped_kp = kp_row(&tmux.screen());
    tmux.keys(&["C-t"]);
    // The page and the status line come in one redraw, which tmux may show half done: the
    // wait is for the whole of it.
    let s = tmux.wait_for("the tuning's results", Duration::from_secs(300), |s| {
        s.contains("Results of the last tuning")
            && s.contains("DAC sat.")
            && s.contains("tune done")
    });
    assert!(s.contains("candidates"), "{s}");
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(run.out("out").join("tune/tune-summary.json")).expect("summary"),
    )
    .expect("tune-summary.json");
    let abs = |m: usize, when: &str| summary["motors"][m][when]["abs_rad"].as_f64().expect("Σ|e|");
    for m in 0..3 {
        assert!(abs(m, "after") < abs(m, "before"), "motor {} not better: {summary}", m + 1);
    }
    // Σ|e| of motor 1 before → after, as the page shows it.
    let cell = format!("{:.3}→{:.3}", abs(0, "before"), abs(0, "after"));
    assert!(s.contains(&cell), "{cell} not shown:\n{s}");

    // The log has the starter's progress lines, the first at its top.
    tmux.keys(&["F3", "Home"]);
    tmux.wait_for("the progress lines", Duration::from_secs(10), |s| {
        s.contains("tune progress: motor 1/3, candidate 1,")
    });

    // Ctrl-A: the tuned gains in the form (shown on the setup page), then saved by F10.
    tmux.keys(&["C-a", "F1"]);
    tmux.wait_for("the tuned gains in the form", Duration::from_secs(10), |s| {
        setup_drawn(s) && kp_row(s) != shipped_kp
    });
    tmux.keys(&["F10"]);
    let (status, s) = tmux.wait_exit(Duration::from_secs(20));
    assert_eq!(status, 0, "{s}");
    let saved: toml::Table =
        toml::from_str(&std::fs::read_to_string(&config).expect("settings")).expect("TOML");
    for m in 0..3 {
        for (k, key) in ["kp", "ki", "kd", "kvff", "kaff"].iter().enumerate() {
            let want = summary["motors"][m]["gains_after"][k].as_f64().unwrap();
            let got = saved["motor"][m][key].as_float().unwrap();
            assert_eq!(got, want, "motor {} {key} saved", m + 1);
        }
    }
    drop(tmux);
    run.assert_clean();
}

/// Issue 16: while a move runs, the charts page draws its live telemetry — command and
/// actual, following error, servo period — redrawn as samples come (the count on its line
/// grows between two looks); when the move ends the page is the finished move's again.
#[test]
fn console_charts_a_running_move_live_then_its_results() {
    let run = TestRun::new("conslive");
    let tmux = console_running_a_long_move(&run);
    tmux.keys(&["F7"]);
    let samples = |s: &str| -> u64 {
        let line = s.lines().find(|l| l.contains("LIVE: the last")).unwrap_or_default();
        line.split(" · ").nth(1).and_then(|p| p.split(' ').next()?.parse().ok()).unwrap_or(0)
    };
    let s = tmux.wait_for("the live charts", Duration::from_secs(30), |s| {
        samples(s) > 0
            && ["command vs actual", "following error", "servo period"]
                .iter()
                .all(|t| s.contains(t))
    });
    let first = samples(&s);
    assert!(s.chars().any(|c| ('\u{2801}'..='\u{28ff}').contains(&c)), "no plotted points:\n{s}");
    // Redrawn as the move goes: more samples a moment later.
    tmux.wait_for("the live charts to move on", Duration::from_secs(30), |s| samples(s) > first);
    tmux.keys(&["F9"]);
    tmux.wait_for("the results", Duration::from_secs(60), results_drawn);
    tmux.keys(&["F7"]);
    let s = tmux.wait_for("the finished move's charts", Duration::from_secs(10), |s| {
        s.contains("servo period") && s.contains("PNG plots")
    });
    assert!(!s.contains("LIVE:"), "live charts after the move:\n{s}");
    tmux.keys(&["F12"]);
    let (status, s) = tmux.wait_exit(Duration::from_secs(20));
    assert_eq!(status, 0, "{s}");
    drop(tmux);
    run.assert_clean();
}

/// Issue 27, item 3: the jog keys in the console: Ctrl-↓ chooses motor 2, Ctrl-→ jogs it by
/// `[jog] counts` through the starter, and its results show; nothing else moved.
#[test]
fn the_console_jogs_a_motor_with_its_keys() {
    let run = TestRun::new("consjog");
    run.config_with(&[]);
    let edit = |key: &str, value: &str| {
        let text = std::fs::read_to_string(run.dir.join("qmarc.toml")).expect("settings");
        let text = text
            .lines()
            .map(|l| {
                if l.starts_with(&format!("{key} =")) {
                    format!("{key} = {value}")
                } else {
                    l.to_string()
                }
            })
            .collect::<Vec<_>>()
            .join("\n");
        std::fs::write(run.dir.join("qmarc.toml"), text + "\n").expect("settings");
    };
    edit("out_dir", &format!("{:?}", run.out("out").display().to_string()));
    let tmux = Tmux::start(&run.dir, &run.dir, &console_command(&run));
    tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);
    tmux.keys(&["F4"]);
    tmux.wait_for("the results page", Duration::from_secs(10), |s| s.contains("No move yet"));
    tmux.keys(&["C-Down"]);
    tmux.wait_for("motor 2 chosen", Duration::from_secs(10), |s| s.contains("jog: motor 2"));
    tmux.keys(&["C-Right"]);
    let s = tmux.wait_for("the jog's results", Duration::from_secs(60), results_drawn);
    assert!(s.contains("jog"), "{s}");
    let summary = qmarc_tests::read_summary(&run.out("out"));
    assert_eq!(summary.mode.to_string(), "jog");
    let (header, rows) = qmarc_tests::read_gather(&run.out("out"));
    let last = rows.last().expect("rows");
    let cmd = |m: usize| last[header.iter().position(|h| *h == format!("cmd{m}")).expect("cmd")];
    assert_eq!((cmd(1), cmd(2), cmd(3)), (0.0, 100.0, 0.0), "motor 2 by [jog] counts");
    tmux.keys(&["F12"]);
    let (status, s) = tmux.wait_exit(Duration::from_secs(20));
    assert_eq!(status, 0, "{s}");
    drop(tmux);
    run.assert_clean();
}

/// Issue 30: the console's Cartesian jog keys, go-to and gripper toggle: Ctrl-↓ past the
/// motors chooses the effector's axes (z), Ctrl-→ jogs it `[jog] mm` up on a line; Ctrl-G
/// asks for a point and goes there (`move --xyz`); Ctrl-O closes the gripper where the robot
/// is. Each is a move of its own, with its results.
#[test]
fn the_console_jogs_the_effector_goes_to_a_point_and_grips() {
    let run = TestRun::new("consxyz");
    let config = run.config_with(&[]);
    let text = std::fs::read_to_string(&config).expect("settings");
    let out = format!("{:?}", run.out("out").display().to_string());
    let text: Vec<String> = text
        .lines()
        .map(|l| if l.starts_with("out_dir =") { format!("out_dir = {out}") } else { l.into() })
        .collect();
    std::fs::write(&config, text.join("\n") + "\n").expect("settings");
    let robot = qmarc_config::Settings::load(&config, &qmarc_config::Names::any())
        .expect("settings")
        .robot()
        .expect("[robot]");
    let summary_json = run.out("out").join("summary.json");
    let modified = || std::fs::metadata(&summary_json).and_then(|m| m.modified()).ok();
    // The next move's results: a summary newer than the last one, and the page drawn.
    let next_results = |tmux: &Tmux, before: Option<std::time::SystemTime>| {
        tmux.wait_for("the move's results", Duration::from_secs(60), |s| {
            results_drawn(s) && modified() != before
        });
        let (header, rows) = qmarc_tests::read_gather(&run.out("out"));
        let col = |name: &str| header.iter().position(|h| h == name).expect("column");
        let last = rows.last().expect("rows").clone();
        let cmd = [last[col("cmd1")], last[col("cmd2")], last[col("cmd3")]];
        let first = [rows[0][col("cmd1")], rows[0][col("cmd2")], rows[0][col("cmd3")]];
        (
            robot.point_of(&first).unwrap() * 1e3,
            robot.point_of(&cmd).unwrap() * 1e3,
            last[col("grip")],
        )
    };
    let tmux = Tmux::start(&run.dir, &run.dir, &console_command(&run));
    tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);
    tmux.keys(&["F4"]);
    tmux.wait_for("the results page", Duration::from_secs(10), |s| s.contains("No move yet"));
    for _ in 0..5 {
        tmux.keys(&["C-Down"]);
    }
    tmux.wait_for("z chosen", Duration::from_secs(10), |s| {
        s.contains("jog: the effector along z (Ctrl-← / Ctrl-→ move it ∓5 mm)")
    });
    let before = modified();
    tmux.keys(&["C-Right"]);
    let (from, to, _) = next_results(&tmux, before);
    assert!(((to - from).z - 5.0).abs() < 1e-6 && (to - from).xy().norm() < 1e-6, "{from} → {to}");
    assert_eq!(qmarc_tests::read_summary(&run.out("out")).mode.to_string(), "jog");
    // Go to a point.
    tmux.keys(&["C-g"]);
    tmux.wait_for("the question", Duration::from_secs(10), |s| s.contains("go to X Y Z (mm)"));
    tmux.type_text("20 -10 -640");
    tmux.wait_for("the point typed", Duration::from_secs(10), |s| s.contains("20 -10 -640"));
    let before = modified();
    tmux.keys(&["Enter"]);
    let (_, to, grip) = next_results(&tmux, before);
    assert!((to - qmarc_kinematics::Point::new(20.0, -10.0, -640.0)).norm() < 1e-6, "{to}");
    assert_eq!(grip, 0.0, "open");
    // Close the gripper where the robot is.
    let before = modified();
    tmux.keys(&["C-o"]);
    let (from, to, grip) = next_results(&tmux, before);
    assert_eq!((from, grip), (to, 2.0), "closed, in place");
    // Issue 42, item 3: a go-to out of reach is refused before anything moves (the folder
    // keeps the grip's results): F7 charts those, said to be an earlier move's, and does not
    // say "No gathered data yet."
    let before = modified();
    tmux.keys(&["C-g"]);
    tmux.wait_for("the question", Duration::from_secs(10), |s| s.contains("go to X Y Z (mm)"));
    tmux.type_text("2000 -10 -640");
    tmux.wait_for("the point typed", Duration::from_secs(10), |s| s.contains("2000 -10 -640"));
    tmux.keys(&["Enter"]);
    tmux.wait_for("the refusal", Duration::from_secs(60), |s| {
        s.contains("move ended (exit status: 3) without results")
    });
    assert_eq!(modified(), before, "the refused move wrote nothing");
    tmux.keys(&["F7"]);
    let s = tmux.wait_for("the earlier move's charts", Duration::from_secs(10), |s| {
        s.contains("command vs actual") && s.contains("The gathered data of an earlier move")
    });
    assert!(!s.contains("No gathered data yet"), "{s}");
    // Issue 42, item 2: at rest, the setup page says where the robot is and whence.
    tmux.keys(&["F1"]);
    tmux.wait_for("the robot at rest", Duration::from_secs(10), |s| {
        s.contains("At rest: M1 ") && s.contains("gripper open") && setup_drawn(s)
    });
    tmux.keys(&["F12"]);
    let (status, s) = tmux.wait_exit(Duration::from_secs(20));
    assert_eq!(status, 0, "{s}");
    drop(tmux);
    run.assert_clean();
}

/// Issue 44: Ctrl-B runs a conveyor session (the starter's `conveyor`, `conveyor.run_s`
/// long); while it runs, the console shows the belt, the queue and the parts picked and
/// missed, as the session counts them; its results come when it ends, `parts.csv` with them.
#[test]
fn the_console_runs_the_belt_and_shows_its_parts() {
    let run = TestRun::new("consbelt");
    let out = format!("{:?}", run.out("out").display().to_string());
    run.config_with(&[("out_dir", &out), ("conveyor.run_s", "6.0")]);
    let tmux = Tmux::start(&run.dir, &run.dir, &console_command(&run));
    tmux.wait_for("the setup screen", Duration::from_secs(30), setup_drawn);
    tmux.keys(&["C-b"]);
    let picked = |s: &str| -> u32 {
        let at = s.find(" picked").map_or("", |i| &s[..i]);
        at.rsplit(|c: char| !c.is_ascii_digit()).next().and_then(|n| n.parse().ok()).unwrap_or(0)
    };
    let s = tmux.wait_for("a part picked", Duration::from_secs(60), |s| picked(s) > 0);
    assert!(s.contains("conveyor running") && s.contains("mm/s") && s.contains(" missed"), "{s}");
    let shown = picked(&s);
    tmux.wait_for("the results", Duration::from_secs(60), results_drawn);
    let parts = std::fs::read_to_string(run.out("out").join("parts.csv")).expect("parts.csv");
    let in_file = parts.lines().filter(|l| l.contains(",picked,")).count();
    assert!(in_file >= shown as usize, "the console showed {shown} picked, parts.csv {in_file}");
    tmux.keys(&["F12"]);
    let (status, s) = tmux.wait_exit(Duration::from_secs(20));
    assert_eq!(status, 0, "{s}");
    drop(tmux);
    run.assert_clean();
}
