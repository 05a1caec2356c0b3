//! Issue 12: the Sensoray 626 backend from the outside — a missing card fails at once naming
//! its device, and the whole stack runs through the backend's instruction lists against the
//! in-process fake of the driver (`--device fake`), as it would against the card.

use qmarc_proto::exit;
use qmarc_tests::{TestRun, bin_dir, read_summary, run_with_timeout, s626_config, workspace};
use std::process::{Command, Stdio};
use std::time::Duration;

const TIMEOUT: Duration = Duration::from_secs(60);

#[test]
fn a_missing_card_fails_at_once_naming_its_device() {
    let run = TestRun::new("nocard");
    // The shipped settings (the simulated robot's): the device is what is wrong first.
    let config = run.config_with(&[]);
    let started = std::time::Instant::now();
    for (program, args) in [
        ("qmarc-starter", vec!["--backend", "s626", "--device", "/dev/comedi-none", "step"]),
        ("qmarc-starter", vec!["step", "--device=/dev/comedi-none", "--backend=s626"]),
        ("qmarc", vec!["home", "--backend", "s626", "--device", "/dev/comedi-none"]),
    ] {
        let mut cmd = Command::new(bin_dir().join(program));
        cmd.args(run.isolation_args())
            .arg(format!("--config={}", config.display()))
            .args(&args)
            .current_dir(workspace())
            .stdin(Stdio::null());
        let r = run_with_timeout(&mut cmd, TIMEOUT);
        assert_eq!(r.code, Some(i32::from(exit::REFUSED)), "{program} {args:?}: {}", r.stderr);
        assert_eq!(
            r.stderr.trim(),
            "qmarc-starter: error: /dev/comedi-none: no such device: is the card in and its \
             driver loaded (`sudo modprobe s626`)? `ls /dev/comedi*` lists the comedi devices",
            "{program} {args:?}"
        );
        run.assert_clean();
    }
    // Before anything was spawned: no watchdog, no connection timeout waited for.
    assert!(started.elapsed() < TIMEOUT, "bounded");
}

#[test]
fn the_hwserver_selftest_checks_the_card_and_times_its_lists() {
    let run = TestRun::new("selftest");
    // The shipped settings: the selftest moves nothing, their counts do not matter to it.
    let config = run.config_with(&[]);
    let selftest = |device: &str| {
        let mut cmd = Command::new(bin_dir().join("qmarc-hwserver"));
        cmd.arg(format!("--config={}", config.display()))
            .args(["--backend", "s626", "--device", device, "--selftest", "--count", "500"])
            .current_dir(workspace());
        run_with_timeout(&mut cmd, TIMEOUT)
    };
    let r = selftest("fake");
    assert_eq!(r.code, Some(0), "{}", r.stderr);
    for line in [
        "QMARC selftest: fake is a Sensoray 626",
        "motor 1: counter 0A reads  8388608, top switch DIO9 closed, bottom switch DIO10 closed",
        "motor 3: counter 2A reads  8388608, top switch DIO13 closed, bottom switch DIO15 closed",
        "instruction lists, 500 of each",
        "read  (3 counters + DIO bank 0)",
        "write (3 DACs + DIO bank 0)",
        "nothing was enabled; every DAC at 0 V",
    ] {
        assert!(r.stdout.contains(line), "`{line}` in\n{}", r.stdout);
    }
    let r = selftest("/dev/null");
    assert_eq!(r.code, Some(i32::from(exit::REFUSED)));
    assert!(r.stderr.contains("/dev/null is not a comedi device"), "{}", r.stderr);
}

#[test]
fn a_step_runs_through_the_626_backend_against_the_fake_card() {
    let run = TestRun::new("fakecard");
    let out = run.out("out");
    // The 626 keeps the hardware bounds (10 and 25 periods); this VM's stalls are not the
    // backend's to survive: the rehearsal's bounds (docs/hardware.md).
    let config = s626_config();
    let r = run.starter(
        &[
            &format!("--config={}", config.display()),
            &format!("--out={}", out.display()),
            &qmarc_tests::rehearsal_bounds(),
            "--backend=s626",
            "--device=fake",
            "step",
            "--duration=1",
        ],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let s = read_summary(&out);
    assert!(s.fault.is_none() && s.ok, "{:?}", s.fault);
    assert!(s.motors.iter().all(|m| m.followed), "{:?}", s.motors);
    // 1× counting: errors in rad use the 626's counts per revolution; the loop is the
    // simulated robot's at 4× (Kp × 4, counts ÷ 4), so its errors in rad are alike.
    let cpr = 1024.0 * 12.0 / std::f64::consts::TAU;
    assert!((s.counts_per_rad - cpr).abs() < 1e-9, "{}", s.counts_per_rad);
    // Settings in other counts than the card's are refused, naming what to do.
    let r = run.starter(
        &[
            &format!("--config={}", qmarc_tests::default_config().display()),
            "--backend=s626",
            "--device=fake",
            "step",
        ],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(i32::from(exit::REFUSED)));
    assert!(
        r.stderr.contains(
            "general.counts_per_rev = 4096 counts per revolution, but the 626 counts 1024"
        ),
        "{}",
        r.stderr
    );
    // The lock-step clock is the simulated robot's only.
    let r = run.starter(
        &[
            &format!("--config={}", config.display()),
            "--backend=s626",
            "--device=fake",
            "--deterministic",
            "step",
        ],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(i32::from(exit::REFUSED)));
    assert!(r.stderr.contains("--deterministic runs the simulated robot only"), "{}", r.stderr);
    run.assert_clean();
}

/// Issue 42, item 8: the fake card rehearses what the card will see — the e-stop chain
/// opening mid-move (`sim.estop_open_s`, on the chain's input `[s626] estop_dio`), a
/// seized motor (`sim.stall_motor`: a following error), each ending the move as on the
/// simulated robot; without the chain's input wired, the e-stop is refused, saying so.
#[test]
fn the_fake_card_plays_the_simulators_fault_injection() {
    let run = TestRun::new("fakefault");
    let out = run.out("out");
    let step = |config: &std::path::Path| {
        run.starter(
            &[
                &format!("--config={}", config.display()),
                &format!("--out={}", out.display()),
                "--backend=s626",
                "--device=fake",
                &qmarc_tests::rehearsal_bounds(),
                "step",
                "--duration=1",
            ],
            TIMEOUT,
        )
    };
    let with = |name: &str, edits: &[(&str, &str)]| run.config_as(name, &s626_config(), edits);
    let r = step(&with("estop.toml", &[("sim.estop_open_s", "[0.5, 0.6]")]));
    assert_eq!(r.code, Some(i32::from(exit::FAULT)), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("FAULT emergency_stop: EMERGENCY STOP"), "{}", r.stdout);
    let fault = read_summary(&out).fault.expect("a fault");
    assert_eq!(fault.kind.name(), "emergency_stop");
    assert!(fault.message.ends_with("all motors disabled"), "{}", fault.message);
    let r = step(&with("stall.toml", &[("sim.stall_motor", "2")]));
    assert_eq!(r.code, Some(i32::from(exit::FAULT)), "{}\n{}", r.stdout, r.stderr);
    let fault = read_summary(&out).fault.expect("a fault");
    assert_eq!(fault.kind.name(), "following_error", "{}", fault.message);
    assert!(fault.message.contains("motor 2"), "{}", fault.message);
    let unwired =
        with("unwired.toml", &[("sim.estop_open_s", "[0.5, 0.6]"), ("s626.estop_dio", "-1")]);
    let r = step(&unwired);
    assert_eq!(r.code, Some(i32::from(exit::REFUSED)), "{}\n{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains("sim.estop_open_s: the fake card sees the emergency-stop chain only on its input, [s626] estop_dio"),
        "{}",
        r.stderr
    );
    run.assert_clean();
}
