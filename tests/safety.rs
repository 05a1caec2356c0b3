//! Safety and homing through the real processes on the simulated robot: limit switches,
//! following error, software limits, the 24-bit counter wrap, each process killed with
//! SIGKILL at several points of a move, and homing from several start positions.
//!
//! Bounds are measured on the simulator's own clock, from its event log (`sim.events_file`):
//! in lock-step runs a disable "within one period" means before the next read.

use qmarc_tests::{
    TestRun, processes_matching, read_gather, read_sim_events, read_summary, wait_with_timeout,
};
use std::path::PathBuf;
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(120);
const PERIOD_NS: u64 = 400_000;

fn arg(key: &str, value: impl std::fmt::Display) -> String {
    format!("--{key}={value}")
}

fn write(run: &TestRun, name: &str, text: &str) -> PathBuf {
    let p = run.dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// An offline path that takes motor 1 from 0 to `end` counts in 1 s; the others stay.
fn motor1_path(end: i64) -> String {
    format!("3\n0.0 0 0 0\n0.5 {} 0 0\n1.0 {end} 0 0\n", end / 2)
}

/// Settings with the simulator's event log in the run's directory, plus `edits`.
fn with_events(run: &TestRun, edits: &[(&str, &str)]) -> (PathBuf, PathBuf) {
    let events = run.dir.join("sim-events.csv");
    let quoted = format!("\"{}\"", events.display());
    let mut all = vec![("events_file", quoted.as_str())];
    all.extend_from_slice(edits);
    (run.config_with(&all), events)
}

/// When each motor's amplifier was first switched off at or after `t`.
fn amps_off_after(events: &[(u64, String, usize)], t: u64, n_motors: usize) -> Vec<u64> {
    (1..=n_motors)
        .map(|m| {
            events
                .iter()
                .find(|e| e.1 == "amp_off" && e.2 == m && e.0 >= t)
                .unwrap_or_else(|| panic!("motor {m} was never disabled after {t}: {events:?}"))
                .0
        })
        .collect()
}

#[test]
fn a_path_into_the_top_switch_disables_every_motor_within_a_period() {
    let run = TestRun::new("topswitch");
    let (cfg, events) = with_events(&run, &[]);
    let knots = write(&run, "into-top.txt", &motor1_path(-12_000));
    let out = run.out("out");
    // --unhomed: the software limits would refuse this path before the move (tested below).
    let r = run.starter(
        &[
            &arg("config", cfg.display()),
            &arg("out", out.display()),
            "--deterministic",
            "--unhomed",
            "run",
            "--method=spline",
            &arg("knots", knots.display()),
        ],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    assert!(
        r.stdout.contains("FAULT limit_switch: motor 1 hit its top limit switch"),
        "{}",
        r.stdout
    );
    let fault = read_summary(&out).fault.expect("a fault");
    assert_eq!((fault.kind.name(), fault.motor), ("limit_switch", Some(1)));
    assert!(fault.message.ends_with("all motors disabled"), "{}", fault.message);
    let ev = read_sim_events(&events);
    let on = ev.iter().find(|e| e.1 == "top_on" && e.2 == 1).expect("the switch tripped").0;
    assert_eq!(fault.hw_time_ns, Some(on), "the fault is the read that saw the switch");
    for t in amps_off_after(&ev, on, 3) {
        assert!(t - on <= PERIOD_NS, "disabled {} ns after the trip", t - on);
    }
    run.assert_clean();
}

#[test]
fn the_software_limits_refuse_a_path_that_leaves_them_before_any_motor_is_enabled() {
    let run = TestRun::new("softpath");
    let (cfg, events) = with_events(&run, &[]);
    let knots = write(&run, "into-top.txt", &motor1_path(-12_000));
    let r = run.starter(
        &[&arg("config", cfg.display()), "run", "--method=spline", &arg("knots", knots.display())],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(3), "{}", r.stderr);
    assert!(
        r.stderr.contains("motor 1: the path reaches -12000.0 counts, outside its software limits [-9000, 10000]: refused before the move"),
        "{}",
        r.stderr
    );
    let ev = read_sim_events(&events);
    assert!(!ev.iter().any(|e| e.1 == "amp_on"), "no motor was enabled: {ev:?}");
    run.assert_clean();
}

#[test]
fn a_stream_that_leaves_the_software_limits_is_stopped_in_the_loop() {
    let run = TestRun::new("softloop");
    let (cfg, events) = with_events(&run, &[]);
    // PVT: motor 1 to −9600 counts in 1 s at rest at both ends, streamed from a FIFO-like pipe.
    let text = qmarc_tests::smooth_step_pvt(-9_600.0, 20);
    let knots = write(&run, "to-9600.txt", &text);
    let out = run.out("out");
    let mut child = run.spawn_starter(&[
        &arg("config", cfg.display()),
        &arg("out", out.display()),
        "--deterministic",
        "run",
        "--method=pvt",
        "--knots=-",
    ]);
    let mut stdin = child.stdin.take().unwrap();
    std::io::Write::write_all(&mut stdin, text.as_bytes()).unwrap();
    drop(stdin);
    let r = wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    let fault = read_summary(&out).fault.expect("a fault");
    assert_eq!((fault.kind.name(), fault.motor), ("software_limit", Some(1)));
    assert!(
        fault.message.starts_with("motor 1 was commanded to -900")
            && fault.message.contains("past its software limit -9000"),
        "{}",
        fault.message
    );
    let t = fault.hw_time_ns.expect("read time");
    for off in amps_off_after(&read_sim_events(&events), t, 3) {
        assert!(off - t <= PERIOD_NS);
    }
    let _ = knots;
    run.assert_clean();
}

#[test]
fn a_stalled_motor_trips_the_following_error_limit_within_a_period() {
    let run = TestRun::new("stall");
    // The integrated error would trip first (at cycle 467 with the thesis' 200 000): this test
    // is the instantaneous limit's.
    let (cfg, events) =
        with_events(&run, &[("stall_motor", "1"), ("max_integrated_error_counts", "10000000.0")]);
    let out = run.out("out");
    let k = qmarc_tests::knots("sine-3motors.txt");
    let r = run.starter(
        &[
            &arg("config", cfg.display()),
            &arg("out", out.display()),
            "--deterministic",
            "run",
            "--method=spline",
            &arg("knots", k.display()),
        ],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    let fault = read_summary(&out).fault.expect("a fault");
    assert_eq!((fault.kind.name(), fault.motor), ("following_error", Some(1)));
    assert!(
        fault.message.starts_with("motor 1 instantaneous following error 200"),
        "{}",
        fault.message
    );
    assert!(fault.message.contains("passed its limit 2000"), "{}", fault.message);
    let t = fault.hw_time_ns.expect("read time");
    for off in amps_off_after(&read_sim_events(&events), t, 3) {
        assert!(off - t <= PERIOD_NS);
    }
    // The motor never moved; the fault came as soon as the command was 2000 counts away.
    let (_, rows) = read_gather(&out);
    let last = rows.last().unwrap();
    assert_eq!(last[3], 0.0);
    assert!(last[2] <= 2_000.0 && last[2] > 1_900.0, "{}", last[2]);
    run.assert_clean();
}

#[test]
fn the_24_bit_counter_wraps_cleanly_during_a_move() {
    let run = TestRun::new("wrap");
    // 256 counts below the 24-bit wrap of the raw counter (0x800000 + 8 388 352 = 0xFFFF00).
    let cfg = run.config_with(&[
        ("start_counts", "[8388352, 0, 0]"),
        ("top_switch_counts", "-100000000"),
        ("bottom_switch_counts", "100000000"),
    ]);
    let out = run.out("out");
    run.starter_ok(&[
        &arg("config", cfg.display()),
        &arg("out", out.display()),
        "--deterministic",
        "--unhomed",
        "step",
        "--size=1000",
        "--duration=3",
    ]);
    let s = read_summary(&out);
    assert!(s.ok);
    let (_, rows) = read_gather(&out);
    let act: Vec<f64> = rows.iter().map(|r| r[3]).collect();
    assert_eq!(act[0], 8_388_352.0);
    assert!(act.iter().any(|&a| a > 8_388_608.0), "crossed the wrap");
    let biggest_step = act.windows(2).map(|w| (w[1] - w[0]).abs()).fold(0.0, f64::max);
    assert!(biggest_step < 150.0, "no jump at the wrap: {biggest_step}");
    assert!((act.last().unwrap() - 8_389_352.0).abs() <= 7.0, "settled at {}", act.last().unwrap());
    run.assert_clean();
}

/// Starts a 3 s step with `flags`, waits `delay` after the move is under way (zero: right
/// when the victim is up), SIGKILLs the process whose command line contains `victim`, and
/// waits for the starter.
fn kill_during_step(
    run: &TestRun,
    cfg: &std::path::Path,
    flags: &[&str],
    victim: &str,
    delay: Duration,
) -> qmarc_tests::Finished {
    let out = run.out("out");
    let mut args = vec![arg("config", cfg.display()), arg("out", out.display())];
    args.extend(flags.iter().map(|f| f.to_string()));
    // Long (the kill ends it): however late a loaded machine's kill arrives, it is mid-move.
    args.extend(["step", "--duration=10"].map(String::from));
    let child = run.spawn_starter(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let deadline = Instant::now() + TIMEOUT;
    let pid = loop {
        let procs = processes_matching(&run.prefix);
        let ready = procs.len() >= 2 || (victim == "qmarc-hwserver" && delay.is_zero());
        if let Some((pid, _)) = procs.iter().find(|(_, cmd)| cmd.contains(victim)).filter(|_| ready)
        {
            break *pid;
        }
        assert!(Instant::now() < deadline, "{victim} did not start");
        std::thread::sleep(Duration::from_millis(2));
    };
    if !delay.is_zero() {
        // `delay` counts from the start of the move, not of the processes.
        qmarc_tests::wait_until_moving(&run.prefix, TIMEOUT);
    }
    std::thread::sleep(delay);
    qmarc_tests::send_signal(pid, nix::sys::signal::Signal::SIGKILL);
    wait_with_timeout(child, TIMEOUT)
}

#[test]
fn killing_the_hwserver_during_a_move_ends_it_as_hwserver_lost() {
    for delay_ms in [300, 1_500] {
        let run = TestRun::new("killhw");
        // Lock-step: the hwserver's death is noticed by its death, and a host stall during
        // the move (this test is not about timing) cannot end it first.
        let r = kill_during_step(
            &run,
            &qmarc_tests::default_config(),
            &["--deterministic"],
            "qmarc-hwserver",
            Duration::from_millis(delay_ms),
        );
        assert_eq!(r.code, Some(2), "{delay_ms} ms: {}\n{}", r.stdout, r.stderr);
        assert!(r.stderr.contains("qmarc-hwserver was killed by SIGKILL"), "{}", r.stderr);
        let fault = read_summary(&run.out("out")).fault.expect("a fault");
        assert_eq!(fault.kind.name(), "hwserver_lost", "{delay_ms} ms");
        assert!(fault.message.contains("(server process gone)"), "{}", fault.message);
        assert!(
            fault.message.contains("did not acknowledge disabling the motors"),
            "{}",
            fault.message
        );
        run.assert_clean();
    }
}

#[test]
fn killing_the_hwserver_before_the_move_ends_the_run() {
    let run = TestRun::new("killhw0");
    let cfg = qmarc_tests::default_config();
    let r = kill_during_step(&run, &cfg, &["--deterministic"], "qmarc-hwserver", Duration::ZERO);
    assert_ne!(r.code, Some(0), "{}", r.stderr);
    assert!(r.stderr.contains("qmarc-hwserver was killed by SIGKILL"), "{}", r.stderr);
    run.assert_clean();
}

#[test]
fn killing_the_controller_during_a_move_trips_the_hwserver_watchdog_within_its_bound() {
    let run = TestRun::new("killctl");
    // Real time: the simulator's clock runs on while the controller is dead. The overrun
    // check is not what this test is about: a host stall must not end the move first.
    let (cfg, events) = with_events(&run, &[("safety.max_missed_in_row", "2500")]);
    let r = kill_during_step(&run, &cfg, &[], "qmarc-controller", Duration::from_millis(500));
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("qmarc-controller was killed by SIGKILL"), "{}", r.stderr);
    assert!(r.stderr.contains("qmarc-hwserver: watchdog: controller silent for"), "{}", r.stderr);
    let fault = read_summary(&run.out("out")).fault.expect("the starter's summary");
    assert_eq!(fault.kind.name(), "controller_lost");
    assert!(
        fault.message.contains("the hwserver's watchdog disabled the motors after 250 periods"),
        "{}",
        fault.message
    );
    let ev = read_sim_events(&events);
    let last = ev.iter().find(|e| e.1 == "last_access").expect("last access").0;
    // The simulated robot's default watchdog: 250 periods = 100 ms, measured on its clock,
    // plus what a VM stall of the server's own wake-up may add.
    let watchdog = 250 * PERIOD_NS;
    for off in amps_off_after(&ev, last, 3) {
        let silent = off - last;
        assert!(
            silent >= watchdog && silent <= watchdog + 25_000_000,
            "disabled {silent} ns after the last request"
        );
    }
    run.assert_clean();
}

#[test]
fn killing_the_controller_before_the_move_stops_the_hwserver() {
    let run = TestRun::new("killctl0");
    // The controller waits for its knots from a FIFO nobody writes: it is certainly before
    // its move when it is killed, however loaded the machine (a step would race ahead).
    let knots = run.dir.join("knots.fifo");
    nix::unistd::mkfifo(&knots, nix::sys::stat::Mode::S_IRUSR | nix::sys::stat::Mode::S_IWUSR)
        .unwrap();
    let child = run.spawn_starter(&[
        &arg("config", qmarc_tests::default_config().display()),
        &arg("out", run.out("out").display()),
        "--deterministic",
        "run",
        "--method=pvt",
        &arg("knots", knots.display()),
    ]);
    let deadline = Instant::now() + TIMEOUT;
    let pid = loop {
        let procs = processes_matching(&run.prefix);
        if let Some((pid, _)) = procs.iter().find(|(_, c)| c.contains("qmarc-controller")) {
            break *pid;
        }
        assert!(Instant::now() < deadline, "the controller did not start");
        std::thread::sleep(Duration::from_millis(2));
    };
    // Killed once its progress page says it is preparing (it then waits there for the knots),
    // however long a loaded machine takes to get it there.
    loop {
        let preparing = qmarc_proto::progress::Progress::snapshot(&run.prefix)
            .is_some_and(|s| s.phase == qmarc_proto::state::Phase::Preparing.wire());
        if preparing {
            break;
        }
        assert!(Instant::now() < deadline, "the controller did not begin preparing");
        std::thread::sleep(Duration::from_millis(2));
    }
    qmarc_tests::send_signal(pid, nix::sys::signal::Signal::SIGKILL);
    let r = wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    let fault = read_summary(&run.out("out")).fault.expect("the starter's summary");
    assert_eq!(fault.kind.name(), "controller_lost");
    assert!(
        fault.message.starts_with(
            "qmarc-controller was killed by SIGKILL at cycle 0 while preparing; the hwserver \
             disabled the motors as it stopped"
        ),
        "{}",
        fault.message
    );
    run.assert_clean();
}

#[test]
fn killing_the_starter_at_the_start_and_near_the_end_stops_everything() {
    use qmarc_proto::state::Phase;
    // Near the end: in the settle after the path, made long enough (10 s) that a loaded
    // machine cannot end the move before the kill arrives (issue 48).
    for near_the_end in [false, true] {
        let run = TestRun::new("killst");
        let out = run.out("out");
        let config = run.config_with(&[("trajectory.settle_s", "10.0")]);
        let mut child = run.spawn_starter(&[
            &arg("config", config.display()),
            &arg("out", out.display()),
            "--deterministic",
            "step",
            &arg("duration", "1"),
        ]);
        let deadline = Instant::now() + TIMEOUT;
        while processes_matching(&run.prefix).len() < 2 {
            assert!(Instant::now() < deadline, "children did not start");
            std::thread::sleep(Duration::from_millis(2));
        }
        if near_the_end {
            qmarc_tests::wait_for_progress(&run.prefix, TIMEOUT, "settle", |s| {
                s.phase == Phase::Settling.wire()
            });
        }
        child.kill().unwrap();
        child.wait().unwrap();
        while !processes_matching(&run.prefix).is_empty() {
            assert!(
                Instant::now() < deadline,
                "children outlived the starter (near the end: {near_the_end}):\n{}",
                qmarc_tests::describe_processes(&run.prefix)
            );
            std::thread::sleep(Duration::from_millis(10));
        }
        // If the move had begun, its summary says the motors were disabled; in the settle it
        // had.
        assert!(!near_the_end || out.join("summary.json").exists(), "no summary of the move");
        if out.join("summary.json").exists() {
            qmarc_tests::assert_aborted_with_motors_disabled(&out);
        }
        // The dead starter's shared memory goes with the next run.
        run.location().remove_files();
        run.assert_clean();
    }
}

/// Test settings for homing: an unhomed robot whose counters read 5000 counts off the homed
/// frame, a fast search (the test is about the sequence, not about patience), home 2000
/// counts below the top switch, and `edits`.
fn homing_config(run: &TestRun, edits: &[(&str, &str)]) -> PathBuf {
    let mut all = vec![
        ("homed", "false"),
        ("counter_offset", "5000"),
        ("velocity_counts_per_s", "20000.0"),
        ("creep_counts_per_s", "1000.0"),
        ("settle_s", "0.05"),
        ("home_offset_counts", "2000.0"),
    ];
    all.extend_from_slice(edits);
    run.config_with(&all)
}

#[test]
fn homing_from_several_start_positions_finds_every_switch() {
    // At rest mid-range; and: motor 1 on its top switch, motor 2 just below it, motor 3 on
    // its bottom switch (the switches are at −9500 and 10 500 in the homed frame).
    for start in ["[0, 0, 0]", "[-9600, -8000, 10600]"] {
        let run = TestRun::new("home");
        let cfg = homing_config(&run, &[("start_counts", start)]);
        let out = run.out("out");
        let r = run.starter_ok(&[
            &arg("config", cfg.display()),
            &arg("out", out.display()),
            "--deterministic",
            "home",
        ]);
        assert!(r.stdout.contains("QMARC home: ok"), "{}", r.stdout);
        let s = read_summary(&out);
        let homing = s.homing.expect("a homing report");
        let motors = &homing.motors;
        assert_eq!(motors.len(), 3);
        let after = homing.after.expect("the read after the preset");
        for (m, rep) in motors.iter().enumerate() {
            assert!(rep.home, "{start}: motor {} {rep:?}", m + 1);
            // The counters read 5000 off the homed frame: the switch at −9500 reads −4500.
            assert!(
                (rep.switch_found_counts.unwrap() - -4_500.0).abs() <= 10.0,
                "{start}: {rep:?}"
            );
            assert!(
                (rep.switch_cleared_counts.unwrap() - -4_500.0).abs() <= 10.0,
                "{start}: {rep:?}"
            );
            // Home: 2000 counts below where the switch cleared, away from it.
            assert_eq!(
                rep.home_counts.unwrap(),
                rep.switch_cleared_counts.unwrap() + 2_000.0,
                "{start}: {rep:?}"
            );
            // Afterwards home reads 0: the motor reads how far it stands from home.
            let stands = after.positions_counts[m];
            assert!(
                stands.abs() < 400.0,
                "{start}: motor {} stands {stands} counts from home",
                m + 1
            );
            assert!(after.homed[m]);
        }
        assert_eq!(motors[0].started_on_switch, start.starts_with("[-9600"));
        run.assert_clean();
    }
}

#[test]
fn a_stuck_top_switch_fails_homing_within_ten_counts() {
    let run = TestRun::new("stuck");
    let cfg = homing_config(&run, &[("stuck_top_motor", "1")]);
    let out = run.out("out");
    let r = run.starter(
        &[&arg("config", cfg.display()), &arg("out", out.display()), "--deterministic", "home"],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    let fault = read_summary(&out).fault.expect("a fault");
    assert_eq!(fault.kind.name(), "homing_failed");
    let backed: f64 = fault
        .message
        .strip_prefix("homing motor 1: its top switch was still active ")
        .and_then(|m| m.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{}", fault.message));
    // Caught at the first read 10 counts back (the encoder moves a count or two per cycle).
    assert!((10.0..13.0).contains(&backed), "{}", fault.message);
    assert!(fault.message.contains("(it must clear within 10 counts)"), "{}", fault.message);
    assert!(fault.message.ends_with("all motors disabled"), "{}", fault.message);
    run.assert_clean();
}

#[test]
fn moves_refuse_an_unhomed_frame_unless_told() {
    let run = TestRun::new("unhomed");
    let cfg = run.config_with(&[("homed", "false"), ("counter_offset", "5000")]);
    let out = run.out("out");
    let r =
        run.starter(&[&arg("config", cfg.display()), &arg("out", out.display()), "step"], TIMEOUT);
    assert_eq!(r.code, Some(3));
    assert!(
        r.stderr.contains("motor 1 is not homed: run `qmarc-starter home` first, or give --unhomed (software limits off)"),
        "{}",
        r.stderr
    );
    let r = run.starter_ok(&[
        &arg("config", cfg.display()),
        &arg("out", out.display()),
        "--deterministic",
        "--unhomed",
        "step",
        "--duration=0.2",
    ]);
    assert!(r.stdout.contains("warning: --unhomed"), "{}", r.stdout);
    run.assert_clean();
}

/// Issue 9, item 6: lock-step runs follow simulated time. Host stalls — here the controller,
/// then the hwserver, stopped with SIGSTOP for 300 ms each during the move — are no overrun
/// and no watchdog trip even with the hardware's bounds (10 and 25 periods), and the data are
/// those of an undisturbed run, byte for byte. A dead process is still noticed by its death
/// (`killing_the_controller_of_a_lock_step_run_trips_the_watchdog_at_once`).
#[test]
fn lock_step_runs_ride_out_host_stalls() {
    let run = TestRun::new("stalls");
    let cfg =
        run.config_with(&[("hwserver.watchdog_periods", "10"), ("safety.max_missed_in_row", "25")]);
    let (quiet, stalled) = (run.out("quiet"), run.out("stalled"));
    let args = |out: &std::path::Path| {
        [arg("config", cfg.display()), arg("out", out.display())]
            .into_iter()
            .chain(["--deterministic", "step", "--duration=1.5"].map(String::from))
            .collect::<Vec<_>>()
    };
    let quiet_args = args(&quiet);
    run.starter_ok(&quiet_args.iter().map(String::as_str).collect::<Vec<_>>());
    let stalled_args = args(&stalled);
    let child = run.spawn_starter(&stalled_args.iter().map(String::as_str).collect::<Vec<_>>());
    qmarc_tests::wait_until_moving(&run.prefix, TIMEOUT);
    for victim in ["qmarc-controller", "qmarc-hwserver"] {
        let procs = processes_matching(&run.prefix);
        let (pid, _) = procs.iter().find(|(_, c)| c.contains(victim)).expect(victim);
        qmarc_tests::send_signal(*pid, nix::sys::signal::Signal::SIGSTOP);
        std::thread::sleep(Duration::from_millis(300));
        qmarc_tests::send_signal(*pid, nix::sys::signal::Signal::SIGCONT);
        std::thread::sleep(Duration::from_millis(100));
    }
    let r = wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let s = read_summary(&stalled);
    assert!(s.ok && s.timing.missed_periods >= 700, "the stalls happened: {:?}", s.timing);
    for f in ["gather.csv", "gather.m"] {
        let (a, b) =
            (std::fs::read(quiet.join(f)).unwrap(), std::fs::read(stalled.join(f)).unwrap());
        assert!(a == b, "{f}: a stalled lock-step run differs from an undisturbed one");
    }
    run.assert_clean();
}

/// In lock-step the watchdog follows the controller's death, not the clock: killed during a
/// move, it is noticed within the watchdog's wall time and the motors are disabled.
#[test]
fn killing_the_controller_of_a_lock_step_run_trips_the_watchdog_at_once() {
    let run = TestRun::new("killlock");
    let out = run.out("out");
    let child = run.spawn_starter(&[
        &arg("config", qmarc_tests::default_config().display()),
        &arg("out", out.display()),
        "--deterministic",
        "step",
        "--duration=3",
    ]);
    qmarc_tests::wait_until_moving(&run.prefix, TIMEOUT);
    let procs = processes_matching(&run.prefix);
    let (pid, _) = procs.iter().find(|(_, c)| c.contains("qmarc-controller")).expect("controller");
    qmarc_tests::send_signal(*pid, nix::sys::signal::Signal::SIGKILL);
    let r = wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("its process is gone"), "{}", r.stderr);
    let fault = read_summary(&out).fault.expect("the starter's summary");
    assert_eq!(fault.kind.name(), "controller_lost");
    assert!(fault.message.contains("the hwserver's watchdog disabled the motors"), "{fault:?}");
    run.assert_clean();
}

/// Issue 27, item 3: the emergency-stop chain opening mid-move (the simulator's
/// `sim.estop_open_s`, a button pressed at 0.5 s and released at 0.6 s) disables every motor
/// in the read that sees it and ends the move in `emergency_stop`, named in the table and
/// summary.json (the latch while the chain closes again is the conformance suite's check); a
/// move with the chain open is refused before anything is enabled; closed, the next runs.
#[test]
fn the_emergency_stop_disables_every_motor_at_once_and_refuses_moves_while_open() {
    let run = TestRun::new("estop");
    let (cfg, events) = with_events(&run, &[("sim.estop_open_s", "[0.5, 0.6]")]);
    let out = run.out("out");
    let r = run.starter(
        &[&arg("config", cfg.display()), &arg("out", out.display()), "--deterministic", "step"],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(2), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("FAULT emergency_stop: EMERGENCY STOP"), "{}", r.stdout);
    let fault = qmarc_tests::read_summary(&out).fault.expect("a fault");
    assert_eq!(fault.kind.name(), "emergency_stop");
    assert!(fault.message.ends_with("all motors disabled"), "{}", fault.message);
    // The hwserver's read at 0.5 s saw it: every amplifier off within that period, before the
    // controller had a say.
    let opened = 500_000_000;
    let off = amps_off_after(&qmarc_tests::read_sim_events(&events), opened, 3);
    assert!(off.iter().all(|&t| t - opened <= 400_000), "{off:?}");

    let (open, _) = with_events(&run, &[("sim.estop_open_s", "[0.0, 1e9]")]);
    let r = run.starter(
        &[&arg("config", open.display()), &arg("out", out.display()), "--deterministic", "step"],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("EMERGENCY STOP: the emergency-stop chain is open"), "{}", r.stderr);
    let events = qmarc_tests::read_sim_events(&events);
    assert!(events.iter().all(|e| e.1 != "amp_on"), "nothing was enabled: {events:?}");
    let (closed, _) = with_events(&run, &[]);
    let r = run.starter(
        &[&arg("config", closed.display()), &arg("out", out.display()), "--deterministic", "step"],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    run.assert_clean();
}
