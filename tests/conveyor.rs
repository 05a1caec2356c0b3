//! `qmarc-starter conveyor` (issue 44): a serving session at the belt. The belt's encoder is
//! read in the same exchange as the motors' and gathered as `conv`; the session ends by
//! itself after `--seconds`, at rest, its data written.

use qmarc_tests::{TestRun, read_gather, read_summary};

/// The belt as the loop read it, at two servo periods: the same physical belt gives the
/// same counts against time (to a count's rounding), and the session ends after the seconds it was given, the periods it takes each way.
#[test]
fn the_belt_is_read_with_the_motors_and_the_session_ends_by_itself() {
    let run = TestRun::new("conveyor-belt");
    // Lock-step: the belt runs on the simulated robot's clock, every read one period on.
    let (speed, mm_per_count, seconds) = (400.0, 0.05, 1.0);
    for period_us in [400.0, 1600.0] {
        let config = run.config_with(&[]);
        let out = run.out(&format!("out-{period_us}"));
        let args = [
            format!("--config={}", config.display()),
            format!("--out={}", out.display()),
            format!("--period-us={period_us}"),
            "--deterministic".into(),
            "conveyor".into(),
            format!("--seconds={seconds}"),
            format!("--belt-mm-s={speed}"),
        ];
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        run.starter_ok(&args);
        let summary = read_summary(&out);
        assert!(summary.fault.is_none(), "{period_us} µs: {:?}", summary.fault);
        let (header, rows) = read_gather(&out);
        let col = |name: &str| header.iter().position(|h| h == name).unwrap();
        let (time, conv) = (col("time_s"), col("conv"));
        assert_eq!(header.last().map(String::as_str), Some("conv"), "{header:?}");
        // The belt ran before the loop began (the reads before it): the counts since its first
        // sample follow the time since it, to a count's rounding, while the session serves.
        // (Lock-step time is the simulated robot's reads: the end's own reads move it on.)
        let (t0, c0) = (rows[0][time], rows[0][conv]);
        for r in rows.iter().filter(|r| r[time] < seconds) {
            let expected = speed * (r[time] - t0) / mm_per_count;
            assert!(
                (r[conv] - c0 - expected).abs() <= 1.0 + 1e-9,
                "{period_us} µs at {} s: {} counts since the first sample, the belt's {expected}",
                r[time],
                r[conv] - c0
            );
        }
        // It quit after `seconds` of cycles, then settled: not before, and not long after.
        let last = rows.last().unwrap()[time];
        assert!(last >= seconds && last < seconds + 1.0, "{period_us} µs: ended at {last} s");
    }
    run.assert_clean();
}

/// `parts.csv`'s rows: its header's names to each row's fields.
fn read_parts(out: &std::path::Path) -> Vec<std::collections::HashMap<String, String>> {
    let text = std::fs::read_to_string(out.join("parts.csv")).expect("parts.csv");
    let mut lines = text.lines();
    let header: Vec<String> =
        lines.next().expect("a header").split(',').map(String::from).collect();
    assert_eq!(
        header.join(","),
        "id,t_seen_s,latched_counts,belt_mm,across_mm,state,grip_cycle,place_cycle,error_mm"
    );
    lines.map(|l| header.iter().cloned().zip(l.split(',').map(String::from)).collect()).collect()
}

/// A conveyor session of `seconds` on `config` into `out`, in lock-step (the loop and the
/// simulated robot's belt on the simulated clock; the camera latches the belt's count, so
/// its detections hold whatever the clock), with `extra` options of `conveyor`.
fn conveyor_args(
    config: &std::path::Path,
    out: &std::path::Path,
    seconds: f64,
    extra: &[&str],
) -> Vec<String> {
    let mut args = vec![
        format!("--config={}", config.display()),
        format!("--out={}", out.display()),
        "--deterministic".into(),
        "conveyor".into(),
        format!("--seconds={seconds}"),
    ];
    args.extend(extra.iter().map(|a| a.to_string()));
    args
}

fn field(row: &std::collections::HashMap<String, String>, name: &str) -> f64 {
    row[name].parse().unwrap_or_else(|_| panic!("{name} = {}", row[name]))
}

/// The error of each picked part, recomputed from the files as a user would: the forward
/// kinematics of gather.csv's actual positions at the part's grip cycle against the part's
/// top centre where the belt (that row's `conv`) had carried it.
fn recomputed_errors(out: &std::path::Path, s: &qmarc_config::Settings) -> Vec<(f64, f64)> {
    let (header, rows) = read_gather(out);
    let col = |name: &str| header.iter().position(|h| h == name).unwrap();
    let robot = s.robot().expect("the Delta");
    let c = &s.conveyor;
    read_parts(out)
        .iter()
        .filter(|p| p["state"] == "picked")
        .map(|p| {
            let cycle = field(p, "grip_cycle");
            let r = rows.iter().find(|r| r[col("cycle")] == cycle).expect("the grip row");
            let act = [r[col("act1")], r[col("act2")], r[col("act3")]];
            let effector = robot.mm_of(&act).unwrap();
            let along = field(p, "belt_mm")
                + (r[col("conv")] - field(p, "latched_counts")) * c.mm_per_count;
            let part = c.point_mm(along, field(p, "across_mm"), s.camera.part_height_mm);
            let e = (0..3).map(|i| (effector[i] - part[i]).powi(2)).sum::<f64>().sqrt();
            (e, field(p, "error_mm"))
        })
        .collect()
}

/// Parts picked at a constant and at a stepping belt speed with the gains tuned for online
/// moves (`config/tuned.toml`): every part that has passed the window is picked, none twice,
/// none missed; each grip inside the window and within 1 mm of the part; the error the file
/// says is the one its rows give; the session ends at rest with the gripper open.
#[test]
fn parts_are_picked_off_the_belt_at_a_constant_and_a_stepping_speed() {
    let run = TestRun::new("conveyor-pick");
    let steps = ("conveyor.speed_steps", "[[2.0, 300.0], [3.5, 450.0]]");
    for (name, edits) in [("constant", vec![]), ("stepping", vec![steps])] {
        let config = run.config_from(&qmarc_tests::tuned_config(), &edits);
        let s = qmarc_config::Settings::load(&config, &qmarc_config::Names::any()).unwrap();
        let out = run.out(name);
        let args = conveyor_args(&config, &out, 6.0, &["--parts-per-min=60", "--seed=3"]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        run.starter_ok(&args);
        let summary = read_summary(&out);
        assert!(summary.fault.is_none(), "{name}: {:?}", summary.fault);
        let parts = read_parts(&out);
        let picked: Vec<_> = parts.iter().filter(|p| p["state"] == "picked").collect();
        let section = summary.conveyor.expect("the conveyor section");
        assert_eq!(section.missed, 0, "{name}: {parts:?}");
        assert!(picked.len() >= 4, "{name}: {} picked of {parts:?}", picked.len());
        assert_eq!(section.picked, picked.len());
        // None twice: distinct parts, one grip and one place each, in turn.
        let mut cycles: Vec<(f64, f64)> =
            picked.iter().map(|p| (field(p, "grip_cycle"), field(p, "place_cycle"))).collect();
        cycles.sort_by(|a, b| a.0.total_cmp(&b.0));
        for w in cycles.windows(2) {
            assert!(w[0].1 < w[1].0, "{name}: a grip before the last place: {cycles:?}");
        }
        for (g, p) in &cycles {
            assert!(g < p && *g >= 0.0, "{name}: {cycles:?}");
        }
        // Each grip inside the window, measured from the files.
        let (header, rows) = read_gather(&out);
        let (cyc, conv) = (
            header.iter().position(|h| h == "cycle").unwrap(),
            header.iter().position(|h| h == "conv").unwrap(),
        );
        for p in &picked {
            let r = rows.iter().find(|r| r[cyc] == field(p, "grip_cycle")).unwrap();
            let along = field(p, "belt_mm")
                + (r[conv] - field(p, "latched_counts")) * s.conveyor.mm_per_count;
            let [start, end] = s.conveyor.window_mm;
            assert!(along >= start - 1.0 && along <= end, "{name}: gripped at {along} mm");
        }
        for (recomputed, said) in recomputed_errors(&out, &s) {
            assert!((recomputed - said).abs() < 1e-6, "{name}: {recomputed} against {said}");
            // Issue 44's bound (the thesis' gains are 3 mm off, a missed intercept tens).
            assert!(said <= 1.0, "{name}: {said} mm at the grip");
        }
        // And through the whole closing of the gripper.
        let closing = section.closing_error_max_mm;
        assert!(closing <= 1.0, "{name}: {closing} mm while the gripper closed");
        // At rest with the gripper open at the end.
        let last = rows.last().unwrap();
        assert_eq!(last[header.iter().position(|h| h == "grip").unwrap()], 0.0, "{name}");
    }
    run.assert_clean();
}

/// Parts spread wider than the robot reaches: those it cannot reach inside the window are
/// missed and never chased — no grip, no fault (the soft limits held), the others picked.
#[test]
fn a_part_beyond_reach_is_missed_never_chased() {
    let run = TestRun::new("conveyor-reach");
    let config = run.config_with(&[("camera.spread_mm", "2000.0")]);
    let out = run.out("out");
    let args = conveyor_args(&config, &out, 8.0, &["--parts-per-min=60", "--seed=5"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    run.starter_ok(&args);
    let summary = read_summary(&out);
    assert!(summary.fault.is_none(), "{:?}", summary.fault);
    let parts = read_parts(&out);
    let missed: Vec<_> = parts.iter().filter(|p| p["state"] == "missed").collect();
    assert!(!missed.is_empty(), "no part out of reach in {parts:?}");
    for p in &missed {
        assert_eq!((field(p, "grip_cycle"), field(p, "place_cycle")), (-1.0, -1.0), "{p:?}");
        assert!(field(p, "across_mm").abs() > 300.0, "a part near the middle missed: {p:?}");
    }
    assert!(parts.iter().any(|p| p["state"] == "picked"), "{parts:?}");
    run.assert_clean();
}

/// A conveyor session of `seconds` at 90 parts a minute on the test settings with `edits`,
/// started and picking for `after_s` s: the starter and the output folder.
fn picking(
    run: &TestRun,
    edits: &[(&str, &str)],
    seconds: f64,
    after_s: u64,
) -> (std::process::Child, std::path::PathBuf) {
    let config = run.config_with(edits);
    let out = run.out("out");
    let args = conveyor_args(&config, &out, seconds, &["--parts-per-min=90"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let child = run.spawn_starter(&args);
    qmarc_tests::wait_until_moving(&run.location().prefix, std::time::Duration::from_secs(60));
    std::thread::sleep(std::time::Duration::from_secs(after_s));
    (child, out)
}

/// `qmarc cmd status`'s conveyor line, `belt B mm at V mm/s · Q queued · … · P picked · M
/// missed`, as (B, V, Q, P, M); `None` while the session does not serve.
fn status_counts(run: &TestRun) -> Option<(f64, f64, u32, u32, u32)> {
    let r = run.cmd(&["status"]);
    let line = r.stdout.lines().find(|l| l.trim_start().starts_with("belt "))?;
    let words: Vec<&str> = line.split_whitespace().collect();
    let before = |w: &str| words[words.iter().position(|x| *x == w)? - 1].parse().ok();
    let belt = words[1].parse().ok()?;
    let speed = words[4].parse().ok()?;
    Some((belt, speed, before("queued")?, before("picked")?, before("missed")?))
}

/// The camera killed mid-run is said at once and ends nothing: the session picks the parts
/// it had seen and ends when its time is up, every file written. While it runs, `qmarc cmd
/// status` says the belt, the queue and the parts picked and missed, as they are. The
/// camera is the one that finds the parts in frames (issue 46); the simulated camera's
/// death is the same death.
#[test]
fn the_camera_killed_mid_run_ends_nothing() {
    use nix::sys::signal::Signal;
    let run = TestRun::new("conveyor-camkill");
    let (child, out) = picking(&run, &[("camera.backend", "\"images\"")], 8.0, 1);
    // The status: the belt moving at its speed, then a part picked.
    let s =
        qmarc_config::Settings::load(&run.config_with(&[]), &qmarc_config::Names::any()).unwrap();
    let started = std::time::Instant::now();
    let (mut first, mut picked) = (None, 0);
    while picked == 0 {
        assert!(started.elapsed().as_secs() < 60, "no part picked in a minute");
        if let Some((belt, speed, _, p, _)) = status_counts(&run) {
            first.get_or_insert((belt, speed));
            picked = p;
        }
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let (belt, speed) = first.expect("a status");
    let ratio = speed / s.conveyor.speed_mm_s;
    assert!((0.9..1.1).contains(&ratio), "the status says the belt at {speed} mm/s");
    let (later, ..) = status_counts(&run).expect("a status");
    assert!(later > belt, "the belt moves: {belt} then {later} mm");
    let camera = run.processes().into_iter().find(|(_, c)| c.contains("qmarc-camera"));
    let (pid, _) = camera.expect("the camera runs");
    qmarc_tests::send_signal(pid, Signal::SIGKILL);
    let r = qmarc_tests::wait_with_timeout(child, std::time::Duration::from_secs(60));
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(
        r.stderr.contains(
            "qmarc-camera was killed by SIGKILL; the session goes on, picking the parts it has \
             already seen"
        ),
        "{}",
        r.stderr
    );
    let summary = read_summary(&out);
    assert!(summary.fault.is_none(), "{:?}", summary.fault);
    let parts = read_parts(&out);
    let in_file = parts.iter().filter(|p| p["state"] == "picked").count();
    assert!(in_file >= picked as usize, "the status said {picked} picked, parts.csv {in_file}");
    run.assert_clean();
}

/// Ctrl-C ends a conveyor session as it ends any move, motors disabled, with every file
/// written: the parts seen so far among them.
#[test]
fn ctrl_c_ends_a_conveyor_session_with_every_file_written() {
    use nix::sys::signal::Signal;
    let run = TestRun::new("conveyor-ctrlc");
    let (child, out) = picking(&run, &[], 30.0, 3);
    qmarc_tests::send_signal(child.id(), Signal::SIGINT);
    let r = qmarc_tests::wait_with_timeout(child, std::time::Duration::from_secs(60));
    assert_eq!(r.code, Some(130), "{}\n{}", r.stdout, r.stderr);
    qmarc_tests::assert_aborted_with_motors_disabled(&out);
    for f in ["gather.csv", "gather.m", "summary.json", "parts.csv"] {
        assert!(out.join(f).is_file(), "{f} was not written");
    }
    assert!(!read_parts(&out).is_empty(), "the parts seen are in parts.csv");
    run.assert_clean();
}

/// An emergency stop while the robot picks ends the session as it ends every move: all
/// motors disabled, the fault said, and every file written, the parts picked before it among
/// them.
#[test]
fn an_emergency_stop_while_picking_ends_as_every_move_ends() {
    let run = TestRun::new("conveyor-estop");
    let config = run.config_with(&[("sim.estop_open_s", "[3.0, 3.5]")]);
    let out = run.out("out");
    let args = conveyor_args(&config, &out, 8.0, &["--parts-per-min=90"]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let r = run.starter(&args, std::time::Duration::from_secs(120));
    assert_eq!(r.code, Some(i32::from(qmarc_proto::exit::FAULT)), "{}\n{}", r.stdout, r.stderr);
    let fault = read_summary(&out).fault.expect("a fault");
    assert_eq!(fault.kind.name(), "emergency_stop", "{}", fault.message);
    assert!(fault.message.ends_with("all motors disabled"), "{}", fault.message);
    let parts = read_parts(&out);
    assert!(parts.iter().any(|p| p["state"] == "picked"), "picked before the stop: {parts:?}");
    // Nothing was placed after the stop.
    let stop_cycle = 3.0 / 400e-6;
    for p in parts.iter().filter(|p| p["state"] == "picked") {
        assert!(field(p, "place_cycle") < stop_cycle + 10.0, "{p:?}");
    }
    run.assert_clean();
}

/// A conveyor session needs a gripper, and every point it picks at and places to in reach
/// and inside the soft limits: else it is refused before anything starts.
#[test]
fn a_conveyor_session_that_cannot_pick_is_refused() {
    let run = TestRun::new("conveyor-nogrip");
    let config = run.config_with(&[("s626.gripper_dio", "-1")]);
    let out = run.out("out");
    let args = conveyor_args(&config, &out, 2.0, &[]);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let r = run.starter(&args, std::time::Duration::from_secs(60));
    assert_eq!(r.code, Some(i32::from(qmarc_proto::exit::REFUSED)), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("conveyor grips the parts: [s626] gripper_dio = -1"), "{}", r.stderr);
    assert!(!out.join("parts.csv").exists());
    // A place out of reach, a window past the soft limits: refused, naming the setting.
    for (key, value, says) in [
        (
            "conveyor.place_mm",
            "[0.0, 0.0, -300.0]",
            "[conveyor] place_mm: 0.0, 0.0, -300.0 mm is unreachable",
        ),
        (
            "conveyor.window_mm",
            "[300.0, 1200.0]",
            "[conveyor] window_mm: the grip point at 1200 mm along",
        ),
    ] {
        let config = run.config_with(&[(key, value)]);
        let args = conveyor_args(&config, &out, 2.0, &[]);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let r = run.starter(&args, std::time::Duration::from_secs(60));
        assert_eq!(r.code, Some(i32::from(qmarc_proto::exit::REFUSED)), "{key}: {}", r.stderr);
        assert!(r.stderr.contains(says), "{key}: {}", r.stderr);
        assert!(!out.join("parts.csv").exists());
    }
    run.assert_clean();
}

/// A paced session (on the clock, not in lock-step) measures how fast a part goes from the
/// camera to the command: its summary has both latencies, the first at least the camera's
/// own latency and the second under a period or so on a quiet machine (the bounds here only
/// catch a wrong clock or unit, not a slow machine: no timed test).
#[test]
fn a_paced_session_measures_its_latencies() {
    let run = TestRun::new("conveyor-latency");
    let config = run.config_from(&qmarc_tests::tuned_config(), &[]);
    let out = run.out("out");
    let (c, o) = (format!("--config={}", config.display()), format!("--out={}", out.display()));
    run.starter_ok(&[&c, &o, "conveyor", "--seconds=4", "--parts-per-min=90"]);
    let summary = read_summary(&out);
    assert!(summary.fault.is_none(), "{:?}", summary.fault);
    let s = qmarc_config::Settings::load(&config, &qmarc_config::Names::any()).unwrap();
    let section = summary.conveyor.expect("the conveyor section");
    let l = section.latency_ms.expect("a paced session's latencies");
    let camera_ms = s.camera.latency_s * 1e3;
    let q = l.exposure_to_queue;
    assert!(q.count >= 2 && q.p50 >= camera_ms && q.p99 >= q.p50 && q.max < 2_000.0, "{q:?}");
    let h = l.queue_to_command;
    assert!(h.count >= 1 && h.p50 < 100.0 && h.max >= h.p99, "{h:?}");
    // In lock-step the camera's clock is the simulation's: no latencies.
    let o2 = format!("--out={}", run.out("lockstep").display());
    run.starter_ok(&[&c, &o2, "--deterministic", "conveyor", "--seconds=2"]);
    let section = read_summary(&run.out("lockstep")).conveyor.expect("the section");
    assert!(section.latency_ms.is_none());
    run.assert_clean();
}
