//! gather.mcap (issue 45): every move writes its rows, the motors as ROS 2 joint states, the
//! effector, the Deltabot drawn and its log beside gather.csv, and the MCAP ecosystem's own
//! readers (PyPI `mcap`, `mcap-ros2-support`, `mcap-protobuf-support`, rosbags' message
//! definitions: `tests/mcap_check.py`) find exactly gather.csv's rows in it — after a step,
//! a conveyor session, a fault, and a controller killed mid-move (the starter writes the file
//! from the rows the controller left).

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use qmarc_tests::{TestRun, config_arg, processes_matching, read_summary, workspace};
use serde_json::Value;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

/// Runs `tests/mcap_check.py` on the output folder `out`: it exits 1 naming the first
/// difference between gather.mcap and gather.csv; its JSON line says what it found.
fn check(out: &Path) -> Value {
    let r = Command::new(qmarc_tests::python())
        .arg(workspace().join("tests/mcap_check.py"))
        .arg(out)
        .output()
        .expect("run mcap_check.py");
    let (stdout, stderr) = (String::from_utf8_lossy(&r.stdout), String::from_utf8_lossy(&r.stderr));
    assert!(r.status.success(), "mcap_check.py {}:\n{stdout}\n{stderr}", out.display());
    serde_json::from_str(stdout.trim()).unwrap_or_else(|e| panic!("{e}: {stdout}"))
}

/// The log's lines: (level, message); foxglove.Log's levels: 2 info, 3 warning, 4 error.
fn log(found: &Value) -> Vec<(i64, String)> {
    let lines = found["log"].as_array().expect("a log");
    lines.iter().map(|l| (l[0].as_i64().unwrap(), l[1].as_str().unwrap().to_string())).collect()
}

#[test]
fn a_steps_gather_mcap_holds_its_rows_as_foxglove_and_ros2_read_them() {
    let run = TestRun::new("mcap-step");
    let out = run.out("out");
    run.step_ok(&out, &["step"]);
    let found = check(&out);
    let summary = read_summary(&out);
    assert_eq!(found["rows"].as_u64(), Some(summary.gathered_rows));
    assert!(summary.files.contains(&out.join("gather.mcap")), "{:?}", summary.files);
    let topics: Vec<&str> =
        found["topics"].as_array().unwrap().iter().flat_map(Value::as_str).collect();
    assert_eq!(
        topics,
        ["/joint_states", "/qmarc/effector", "/qmarc/gather", "/qmarc/log", "/qmarc/scene"]
    );
    // The joint states at the live telemetry's rate: the first row, then the first at least
    // 4 cycles on (missed periods skip cycles), and the last; each the row's act.
    let (header, rows) = qmarc_tests::read_gather(&out);
    let cycle = header.iter().position(|h| h == "cycle").unwrap();
    let mut next = 0.0;
    let mut expected = 0;
    for (k, r) in rows.iter().enumerate() {
        if r[cycle] >= next || k + 1 == rows.len() {
            expected += 1;
            next = r[cycle] + 4.0;
        }
    }
    assert_eq!(found["joint_states"].as_u64(), Some(expected));
    assert_eq!(found["effector"], found["joint_states"]);
    assert!(found["max_position_error_rad"].as_f64().unwrap() < 1e-12);
    let hz = found["scene_hz"].as_f64().unwrap();
    assert!(hz >= 25.0, "the scene at {hz} Hz of loop time");
    let said = log(&found);
    assert!(said[0].1.starts_with("step began: 3 motors, period 400 µs"), "{said:?}");
    assert_eq!(
        said.last().map(|l| (l.0, l.1.starts_with("step ended: ok"))),
        Some((2, true)),
        "{said:?}"
    );
    run.assert_clean();
}

#[test]
fn a_conveyor_sessions_mcap_draws_the_belt_and_the_parts_it_picked() {
    let run = TestRun::new("mcap-conveyor");
    let out = run.out("out");
    let config = run.config_with(&[]);
    let args = [
        format!("--config={}", config.display()),
        format!("--out={}", out.display()),
        "--deterministic".into(),
        "conveyor".into(),
        "--seconds=3".into(),
    ];
    run.starter_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
    let found = check(&out);
    assert_eq!(found["entities"], serde_json::json!(["belt", "deltabot"]));
    assert!(found["max_parts"].as_u64().unwrap() >= 1, "{found}");
    let parts = std::fs::read_to_string(out.join("parts.csv")).unwrap();
    let picked: Vec<&str> = parts
        .lines()
        .skip(1)
        .filter(|l| l.contains(",picked,"))
        .map(|l| l.split(',').next().unwrap())
        .collect();
    assert!(!picked.is_empty(), "{parts}");
    let said = log(&found);
    for id in &picked {
        let line = format!("part {id} picked, ");
        assert!(said.iter().any(|(_, m)| m.starts_with(&line)), "{line} in {said:?}");
    }
    // The scene drawn without Foxglove, from the file.
    let png = out.join("scene.png");
    let r = Command::new(qmarc_tests::bin_dir().join("qmarc-foxglove"))
        .args(["scene", &out.join("gather.mcap").display().to_string(), "--at=2"])
        .arg(format!("--png={}", png.display()))
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
    run.assert_clean();
}

/// `gather.mcap = false`: no file, none listed; a fault is in the log at error level.
#[test]
fn gather_mcap_can_be_off_and_a_fault_is_in_its_log() {
    let run = TestRun::new("mcap-off");
    let off = run.out("off");
    let config = run.config_with(&[("gather.mcap", "false")]);
    let args = [format!("--config={}", config.display()), format!("--out={}", off.display())];
    let mut all: Vec<&str> = args.iter().map(String::as_str).collect();
    all.extend(["--deterministic", "step"]);
    run.starter_ok(&all);
    assert!(!off.join("gather.mcap").exists());
    let s = read_summary(&off);
    assert!(!s.files.iter().any(|f| f.ends_with("gather.mcap")), "{:?}", s.files);
    assert!(off.join("gather.csv").exists());

    let out = run.out("fault");
    let cfg = run.config_as(
        "stall.toml",
        &qmarc_tests::default_config(),
        &[("stall_motor", "1"), ("max_integrated_error_counts", "10000.0")],
    );
    let r = run.starter(
        &[
            &format!("--config={}", cfg.display()),
            &format!("--out={}", out.display()),
            "--deterministic",
            "step",
        ],
        Duration::from_secs(60),
    );
    assert_eq!(r.code, Some(i32::from(qmarc_proto::exit::FAULT)), "{}", r.stderr);
    let said = log(&check(&out));
    let fault = read_summary(&out).fault.expect("a fault");
    let line = format!("fault following_error: {}", fault.message);
    assert!(said.contains(&(4, line.clone())), "{line} in {said:?}");
    run.assert_clean();
}

/// A controller killed mid-move: the starter writes gather.csv from the rows it left in its
/// gather page, and gather.mcap of the same rows, the loss in its log.
#[test]
fn a_killed_controllers_rows_are_in_gather_mcap_too() {
    let run = TestRun::new("mcap-killed");
    let out = run.out("out");
    let child = run.spawn_starter(&[
        &config_arg(),
        &format!("--out={}", out.display()),
        "step",
        "--duration=30",
    ]);
    qmarc_tests::wait_until_moving(&run.prefix, Duration::from_secs(60));
    std::thread::sleep(Duration::from_millis(500));
    let start = Instant::now();
    let pid = loop {
        let found = processes_matching(&run.prefix)
            .into_iter()
            .find(|(_, c)| c.contains("qmarc-controller"));
        if let Some((pid, _)) = found {
            break pid;
        }
        assert!(start.elapsed() < Duration::from_secs(30), "no controller");
        std::thread::sleep(Duration::from_millis(5));
    };
    let _ = kill(Pid::from_raw(pid as i32), Signal::SIGKILL);
    let r = qmarc_tests::wait_with_timeout(child, Duration::from_secs(60));
    assert_eq!(r.code, Some(i32::from(qmarc_proto::exit::FAULT)), "{}", r.stderr);
    let s = read_summary(&out);
    assert!(s.gathered_rows > 100, "{}", s.gathered_rows);
    let found = check(&out);
    assert_eq!(found["rows"].as_u64(), Some(s.gathered_rows));
    let said = log(&found);
    assert!(
        said.iter().any(|(level, m)| *level == 4 && m.starts_with("fault controller_lost: ")),
        "{said:?}"
    );
    run.assert_clean();
}
