//! The step move through the real process split: qmarc-starter → qmarc-hwserver ⇄
//! qmarc-controller over iceoryx2.

use qmarc_tests::{
    TestRun, config_arg, default_config, read_gather, read_summary, status_field, thread_statuses,
};
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_secs(60);

#[test]
fn step_of_1000_counts_settles() {
    let run = TestRun::new("settles");
    let out = run.out("out");
    let r = run.step_ok(&out, &["--deterministic", "step", "--size=1000", "--duration=3"]);
    assert!(r.stdout.contains("QMARC step: ok"), "{}", r.stdout);
    let s = read_summary(&out);
    assert!(s.ok && s.fault.is_none());
    assert_eq!(s.cycles, 7501, "3 s at 400 µs: duration / period + 1 samples");
    // Then the last command is held for trajectory.settle_s (0.2 s), and gathered too.
    let settle = s.settle.as_ref().expect("the path ended, then settled");
    assert_eq!((settle.cycles, settle.seconds), (500, 0.2));
    let (header, rows) = read_gather(&out);
    assert_eq!(header[..5], ["cycle", "time_s", "cmd1", "act1", "dac1"]);
    assert_eq!(rows.len(), 7501 + 500);
    let last = rows.last().unwrap();
    // With Table 5-1's gains and fe_scale 96 one count of error is 96·Kp/2²¹ ≈ 8.3 DAC codes:
    // at rest the loop holds the command to the count, hunting by at most one count (the
    // counter's quantum) with a DAC output of a few codes (millivolts).
    let last_half_second = &rows[rows.len() - 1250..];
    for m in 0..3 {
        let (cmd, act) = (last[2 + 3 * m], last[3 + 3 * m]);
        assert_eq!(cmd, 1000.0);
        assert!((cmd - act).abs() <= 1.0, "motor {} rests at {act}", m + 1);
        for r in last_half_second {
            let (act, dac) = (r[3 + 3 * m], r[4 + 3 * m]);
            assert!((act - cmd).abs() <= 1.0, "motor {} still moving: {act}", m + 1);
            assert!(dac.abs() <= 2.0 * 8.4, "motor {} still driven: {dac}", m + 1);
        }
        // The thesis' gains were tuned by Ziegler–Nichols on this step: it overshoots and
        // rings (thesis Fig. 5-1; the deltabot tests time the ringing), about 40 %.
        let overshoot = rows.iter().map(|r| r[3 + 3 * m] - 1000.0).fold(f64::MIN, f64::max);
        assert!((300.0..500.0).contains(&overshoot), "motor {} overshot by {overshoot}", m + 1);
    }
    run.assert_clean();
}

#[test]
fn two_deterministic_runs_write_identical_data() {
    let run = TestRun::new("determinism");
    let (a, b) = (run.out("a"), run.out("b"));
    for out in [&a, &b] {
        run.step_ok(out, &["--deterministic", "step", "--duration=0.4"]);
        run.assert_clean();
    }
    for f in ["gather.csv", "gather.m"] {
        let (x, y) = (std::fs::read(a.join(f)).unwrap(), std::fs::read(b.join(f)).unwrap());
        assert!(x.len() > 1000, "{f} has data");
        assert!(x == y, "{f} differs between two deterministic runs");
    }
}

#[test]
fn summary_figures_equal_the_ones_recomputed_from_gather_csv() {
    let run = TestRun::new("recompute");
    let out = run.out("out");
    // Real time, not deterministic: the figures come from the live loop.
    run.step_ok(&out, &["--gather-every=1", "step", "--size=-700", "--duration=0.6"]);
    let s = read_summary(&out);
    let (_, rows) = read_gather(&out);
    // The path's cycles, then the settle's: the error figures cover the path, the settle
    // has its own.
    let settle = s.settle.as_ref().expect("settle figures");
    assert_eq!(rows.len() as u64, s.cycles + settle.cycles);
    assert_eq!(s.gathered_rows, rows.len() as u64);
    assert_eq!(s.motors.len(), 3);
    let (path, held) = rows.split_at(s.cycles as usize);
    for m in 0..3 {
        let e = |r: &Vec<f64>| r[2 + 3 * m] - r[3 + 3 * m];
        assert!(held.iter().all(|r| r[2 + 3 * m] == path.last().unwrap()[2 + 3 * m]), "held");
        assert_eq!(settle.final_error_counts[m], e(held.last().unwrap()));
        let largest = held.iter().map(|r| e(r).abs()).fold(0.0, f64::max);
        assert_eq!(settle.max_abs_error_counts[m], largest);
    }
    for (m, fig) in s.motors.iter().enumerate() {
        let (mut min, mut max, mut sum_abs, mut sum_sq) = (f64::MAX, f64::MIN, 0.0, 0.0);
        for r in path {
            let e = r[2 + 3 * m] - r[3 + 3 * m];
            min = min.min(e);
            max = max.max(e);
            sum_abs += e.abs();
            sum_sq += e * e;
        }
        assert_eq!(fig.min_error_counts, min, "motor {}", m + 1);
        assert_eq!(fig.max_error_counts, max);
        assert_eq!(fig.accumulated_abs_error_counts, sum_abs);
        assert_eq!(fig.sum_squares_error_counts2, sum_sq);
        assert_eq!(fig.min_error_counts, -700.0, "a negative step: command below actual");
        assert!(fig.max_error_counts > 0.0, "then it overshoots (thesis Fig. 5-1)");
        let cpr = s.counts_per_rad;
        assert_eq!(fig.accumulated_abs_error_rad, sum_abs / cpr);
        assert_eq!(fig.sum_squares_error_rad2, sum_sq / (cpr * cpr));
    }
    // Real time: the timing figures are real measurements.
    assert!(s.timing.read_us.max > 0.0 && s.timing.output_latency_us.p50 > 0.0);
    run.assert_clean();
}

#[test]
fn gathering_every_fourth_cycle_keeps_a_quarter_of_the_rows() {
    let run = TestRun::new("every4");
    let out = run.out("out");
    run.step_ok(&out, &["--gather-every=4", "--deterministic", "step", "--duration=0.2"]);
    let s = read_summary(&out);
    let (_, rows) = read_gather(&out);
    assert_eq!(s.cycles, 501);
    // 501 cycles of the path and 500 of the settle: every fourth of 1001.
    assert_eq!(s.settle.as_ref().unwrap().cycles, 500);
    assert_eq!(rows.len(), 251);
    let cycles: Vec<f64> = rows.iter().map(|r| r[0]).collect();
    assert_eq!(cycles[..3], [0.0, 4.0, 8.0]);
    assert_eq!(rows[1][1], 0.0016, "deterministic time is n·T");
    let m = std::fs::read_to_string(out.join("gather.m")).unwrap();
    assert_eq!(m.lines().filter(|l| l.starts_with(|c: char| c.is_ascii_digit())).count(), 251);
    run.assert_clean();
}

#[test]
fn gathering_only_the_chosen_fields_keeps_the_full_error_figures() {
    let run = TestRun::new("fields");
    let out = run.out("out");
    let cfg = run.config_with(&[("fields", r#"["act", "cmd"]"#)]);
    run.starter_ok(&[
        &format!("--config={}", cfg.display()),
        &format!("--out={}", out.display()),
        "--deterministic",
        "step",
        "--duration=0.1",
    ]);
    let (header, rows) = read_gather(&out);
    assert_eq!(header, ["cycle", "cmd1", "act1", "cmd2", "act2", "cmd3", "act3"]);
    assert_eq!(rows.len(), 251 + 500, "the path, then the settle");
    let m = std::fs::read_to_string(out.join("gather.m")).unwrap();
    let columns = "qmarc_columns = {'cycle', 'cmd1', 'act1', 'cmd2', 'act2', 'cmd3', 'act3'};";
    assert!(m.lines().any(|l| l == columns), "{m:.400}");
    // The figures are over every cycle, whatever is gathered.
    let s = read_summary(&out);
    assert_eq!(s.motors[0].max_error_counts, 1000.0);
    // An unknown field is refused with file, line and field before anything starts.
    let bad = run.config_with(&[("fields", r#"["cmd", "torque"]"#)]);
    let r = run.starter(&[&format!("--config={}", bad.display()), "step"], TIMEOUT);
    assert_eq!(r.code, Some(3));
    let line = std::fs::read_to_string(&bad)
        .unwrap()
        .lines()
        .position(|l| l.starts_with("fields = "))
        .unwrap()
        + 1;
    let want = format!("{}:{line}:", bad.display());
    assert!(r.stderr.contains(&want) && r.stderr.contains("gather.fields"), "{}", r.stderr);
    assert!(r.stderr.contains("torque"), "{}", r.stderr);
    run.assert_clean();
}

#[test]
fn bad_settings_are_refused_before_anything_starts() {
    let run = TestRun::new("badconfig");
    let cfg = run.dir.join("bad.toml");
    let good = std::fs::read_to_string(default_config()).unwrap();
    std::fs::write(&cfg, good.replacen("kvff = 103500.0", "kvff = \"fast\"", 1)).unwrap();
    let r = run.starter(&[&format!("--config={}", cfg.display()), "step"], TIMEOUT);
    assert_eq!(r.code, Some(3));
    let line = good.lines().position(|l| l == "kvff = 103500.0").unwrap() + 1;
    let expected = format!(
        "{}:{line}:8: motor[2].kvff: invalid type: string \"fast\", expected f64",
        cfg.display()
    );
    assert!(r.stderr.contains(&expected), "stderr: {}\nexpected: {expected}", r.stderr);
    assert!(run.location().files().is_empty(), "no iceoryx2 file was ever created");
    // A bad flag is refused the same way.
    let r = run.starter(&[&config_arg(), "--period-us=20", "step"], TIMEOUT);
    assert_eq!(r.code, Some(3));
    assert!(
        r.stderr.contains("--period-us: servo period must be 100‥100000 µs, found 20"),
        "{}",
        r.stderr
    );
    run.assert_clean();
}

/// Issue 9, item 5: every global option works before or after the subcommand, for the
/// starter and for the console's plain subcommands.
#[test]
fn global_options_work_after_the_subcommand() {
    let run = TestRun::new("globals");
    let (a, b) = (run.out("a"), run.out("b"));
    let out_a = format!("--out={}", a.display());
    run.starter_ok(&[
        "step",
        &config_arg(),
        &out_a,
        "--deterministic",
        "--gather-every=2",
        "--period-us=500",
        "--motors=2",
        "--backend=sim",
        "--duration=0.1",
    ]);
    let s = read_summary(&a);
    assert_eq!((s.period_us, s.gather_every, s.motors.len()), (500, 2, 2));
    assert!(s.deterministic);
    // The console's `qmarc step …` passes them on the same way.
    let mut qmarc = std::process::Command::new(qmarc_tests::bin_dir().join("qmarc"));
    qmarc
        .args(["step", "--size=300", &config_arg(), &format!("--out={}", b.display())])
        .args(["--deterministic", "--duration=0.1"])
        .args(run.isolation_args())
        .current_dir(qmarc_tests::workspace());
    let r = qmarc_tests::run_with_timeout(&mut qmarc, TIMEOUT);
    assert_eq!(r.code, Some(0), "stdout:\n{}\nstderr:\n{}", r.stdout, r.stderr);
    assert_eq!(read_summary(&b).motors[0].max_error_counts, 300.0);
    // An unknown backend is refused naming the ones there are.
    let r = run.starter(&["step", &config_arg(), "--backend=s7"], TIMEOUT);
    assert_eq!(r.code, Some(3));
    assert!(r.stderr.contains("--backend: unknown backend `s7`; available: sim"), "{}", r.stderr);
    run.assert_clean();
}

#[test]
fn without_realtime_privileges_the_run_is_degraded_and_says_so() {
    use std::os::unix::fs::PermissionsExt;
    use std::os::unix::process::CommandExt;
    let run = TestRun::new("degraded");
    let out = run.out("out");
    let bin = run.out("bin");
    for d in [&run.dir, &out, &bin, &run.out("iox")] {
        std::fs::create_dir_all(d).unwrap();
        std::fs::set_permissions(d, std::fs::Permissions::from_mode(0o777)).unwrap();
    }
    // The checkout may live where `nobody` cannot go (a 0700 home, a `mktemp -d` folder): the
    // programs and the settings are copied into the run's own folder, and it runs from there.
    for b in ["qmarc-starter", "qmarc-hwserver", "qmarc-controller"] {
        std::fs::copy(qmarc_tests::bin_dir().join(b), bin.join(b)).unwrap();
    }
    let config = run.out("qmarc.toml");
    // The simulator's homed frame in the run's own folder: the shared one in /dev/shm may
    // have been made by root (another test, an earlier run), and nobody cannot write it.
    let shipped = std::fs::read_to_string(default_config()).unwrap();
    let state = format!("state_file = \"{}\"", run.dir.join("sim.state").display());
    let own = shipped.replace("state_file = \"/dev/shm/qmarc-sim.state\"", &state);
    assert!(own != shipped, "the shipped state_file moved");
    std::fs::write(&config, own).unwrap();
    let mut cmd = std::process::Command::new(bin.join("qmarc-starter"));
    cmd.args(run.isolation_args())
        .args([format!("--config={}", config.display()), format!("--out={}", out.display())])
        .args(["--deterministic", "step", "--duration=0.2"])
        .current_dir(&run.dir);
    let root = nix::unistd::geteuid().is_root();
    if root {
        cmd.uid(65534).gid(65534); // nobody: no CAP_SYS_NICE, RLIMIT_RTPRIO 0
    }
    let r = qmarc_tests::run_with_timeout(&mut cmd, TIMEOUT);
    assert_eq!(r.code, Some(0), "stdout:\n{}\nstderr:\n{}", r.stdout, r.stderr);
    let s = read_summary(&out);
    assert!(s.ok);
    assert_eq!(s.degraded, s.timing.policy == "SCHED_OTHER (degraded)");
    if root {
        assert!(s.degraded, "nobody cannot get SCHED_FIFO");
        assert!(r.stdout.contains("DEGRADED: not real time"), "{}", r.stdout);
        assert!(
            s.warnings.iter().any(|w| w.starts_with("SCHED_FIFO 80 refused")),
            "{:?}",
            s.warnings
        );
        assert!(
            r.stderr.contains("qmarc-hwserver: warning: SCHED_FIFO 85 refused"),
            "{}",
            r.stderr
        );
        assert_eq!(
            r.stderr.matches("SCHED_FIFO 80 refused").count(),
            1,
            "warned once: {}",
            r.stderr
        );
    }
    run.assert_clean();
}

#[test]
fn killing_the_starter_stops_both_children_with_the_motors_disabled() {
    let run = TestRun::new("killstarter");
    let out = run.out("out");
    // The default prefix (qmarc_<starter pid>_), so that the next starter can tell it is stale.
    let mut starter = std::process::Command::new(qmarc_tests::bin_dir().join("qmarc-starter"))
        .args([
            format!("--iox-root={}", run.root()),
            config_arg(),
            format!("--out={}", out.display()),
        ])
        .args(["--deterministic", "step", "--duration=30"])
        .current_dir(qmarc_tests::workspace())
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let prefix = format!("qmarc_{}_", starter.id());
    let deadline = std::time::Instant::now() + TIMEOUT;
    // Wait until the move runs, and a while longer.
    qmarc_tests::wait_until_moving(&prefix, TIMEOUT);
    std::thread::sleep(Duration::from_millis(300));
    starter.kill().unwrap();
    starter.wait().unwrap();
    while !qmarc_tests::processes_matching(&prefix).is_empty() {
        assert!(std::time::Instant::now() < deadline, "children outlived the starter");
        std::thread::sleep(Duration::from_millis(10));
    }
    // Both children get SIGTERM: the controller aborts and the hwserver acknowledges the
    // disable.
    let s = qmarc_tests::assert_aborted_with_motors_disabled(&out);
    assert!(s.cycles > 100, "it was moving: {} cycles", s.cycles);
    // The dead starter could not remove its shared memory; the next starter does (or any
    // other starter running meanwhile: the cleanup is by dead prefix).
    let stale = qmarc_proto::service::IpcLocation::new(&prefix, &run.root());
    run.step_ok(&out, &["--deterministic", "step", "--duration=0.05"]);
    assert!(stale.files().is_empty(), "stale files removed: {:?}", stale.files());
    run.assert_clean();
}

#[test]
fn a_controller_that_cannot_start_stops_the_hwserver() {
    use std::os::unix::fs::PermissionsExt;
    let run = TestRun::new("nocontrol");
    let bins = run.dir.join("bin");
    std::fs::create_dir_all(&bins).unwrap();
    std::os::unix::fs::symlink(
        qmarc_tests::bin_dir().join("qmarc-hwserver"),
        bins.join("qmarc-hwserver"),
    )
    .unwrap();
    let broken = bins.join("qmarc-controller");
    std::fs::write(&broken, b"not a program").unwrap();
    std::fs::set_permissions(&broken, std::fs::Permissions::from_mode(0o644)).unwrap();
    let r =
        run.starter(&[&config_arg(), &format!("--bin-dir={}", bins.display()), "step"], TIMEOUT);
    assert_eq!(r.code, Some(1), "{}", r.stderr);
    assert!(
        r.stderr.contains("cannot start") && r.stderr.contains("qmarc-controller"),
        "{}",
        r.stderr
    );
    run.assert_clean();
}

#[test]
fn a_starter_whose_output_is_closed_still_runs_and_cleans_up() {
    // `qmarc-starter step | head -1`, or a console that died: nobody reads its output.
    let run = TestRun::new("closedout");
    let out = run.out("out");
    let mut child = run.spawn_starter(&[
        &config_arg(),
        &format!("--out={}", out.display()),
        "--deterministic",
        "step",
        "--duration=0.05",
    ]);
    drop(child.stdout.take());
    drop(child.stderr.take());
    let deadline = std::time::Instant::now() + TIMEOUT;
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        assert!(std::time::Instant::now() < deadline, "the starter did not end");
        std::thread::sleep(Duration::from_millis(10));
    };
    // It cannot print its table, but the move ran, and nothing is left.
    assert!(read_summary(&out).ok);
    assert_eq!(status.code(), Some(0), "{status:?}");
    run.assert_clean();
}

/// Issue 14: with the hwserver spinning for requests and the controller polling for its
/// responses, a deterministic move writes the same data as with both blocking — the wait
/// mode changes how fast the exchange is, never what it carries.
#[test]
fn spin_mode_moves_exactly_as_blocking_mode() {
    let run = TestRun::new("spinmode");
    let moved = |name: &str, edits: &[(&str, &str)]| {
        let out = run.out(name);
        let cfg = run.config_with(edits);
        let r = run.starter(
            &[
                &format!("--config={}", cfg.display()),
                &format!("--out={}", out.display()),
                "--deterministic",
                "step",
                "--duration=0.3",
            ],
            TIMEOUT,
        );
        assert_eq!(r.code, Some(0), "{name}: {}", r.stderr);
        std::fs::read_to_string(out.join("gather.csv")).unwrap()
    };
    let blocking = moved("block", &[]);
    let spinning = moved("spin", &[("wait", "\"spin\""), ("response_spin_us", "400")]);
    assert_eq!(blocking, spinning);
    run.assert_clean();
}

/// CPUs in a `Cpus_allowed_list` ("1", "0-3", "0,2-3").
fn cpu_list(text: &str) -> Vec<usize> {
    text.trim()
        .split(',')
        .flat_map(|part| {
            let (a, b) = part.split_once('-').unwrap_or((part, part));
            a.parse::<usize>().unwrap()..=b.parse::<usize>().unwrap()
        })
        .collect()
}

/// (thread name, allowed CPUs) of every thread of process `pid`.
fn thread_cpus(pid: u32) -> Vec<(String, Vec<usize>)> {
    let field = |s: &str, k: &str| status_field(s, k).unwrap_or("").to_string();
    thread_statuses(pid)
        .iter()
        .map(|s| (field(s, "Name"), cpu_list(&field(s, "Cpus_allowed_list"))))
        .collect()
}

/// Issue 14: with the servo thread and the hwserver pinned to one CPU, everything else of
/// ours — the starter, the controller's main, telemetry and knot threads — runs on the other
/// CPUs, where the machine has any: their system calls never hold up the real-time pair's
/// wake. The knot thread is spawned by the pinned servo thread and must not inherit its CPU.
#[test]
fn threads_that_are_not_real_time_keep_off_the_pinned_cpu() {
    let run = TestRun::new("keepoff");
    let cfg = run.config_with(&[("servo_cpu", "0"), ("hwserver_cpu", "0")]);
    let status = std::fs::read_to_string("/proc/self/status").unwrap();
    let mine = cpu_list(status_field(&status, "Cpus_allowed_list").expect("our CPUs"));
    let others: Vec<usize> = mine.iter().copied().filter(|&c| c != 0).collect();
    // On a one-CPU machine there is nowhere else to go: nothing changes.
    let rest = if others.is_empty() { mine.clone() } else { others };
    let out = run.out("out");
    // A 2 s PVT path streamed on standard input, held open (at rest where it ends) while
    // the test looks: its knot thread stays alive.
    let mut child = run.spawn_starter(&[
        &format!("--config={}", cfg.display()),
        &format!("--out={}", out.display()),
        "--deterministic",
        "run",
        "--method=pvt",
        "--knots=-",
    ]);
    let path = qmarc_tests::smooth_step_pvt(2_000.0, 40);
    let stream =
        qmarc_tests::HeldStream::feed(child.stdin.take().unwrap(), &run.prefix, 400e-6, &path);
    qmarc_tests::wait_until_moving(&run.prefix, TIMEOUT);
    let mut seen = Vec::new();
    for (pid, cmd) in run.processes() {
        for (name, cpus) in thread_cpus(pid) {
            let pinned = cmd.contains("qmarc-hwserver") || name == "qmarc-servo";
            let want = if pinned { &vec![0] } else { &rest };
            assert_eq!(&cpus, want, "{name} of {cmd}");
            seen.push(name);
        }
    }
    stream.end();
    let r = qmarc_tests::wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    for name in ["qmarc-starter", "qmarc-hwserver", "qmarc-servo", "qmarc-knots", "qmarc-telemetry"]
    {
        assert!(seen.iter().any(|n| n == name), "no thread {name} among {seen:?}");
    }
    run.assert_clean();
}
