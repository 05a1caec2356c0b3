//! The gripper (issue 30, thesis 6.2.2) through the real processes: `move … --grip on|off` on
//! the simulated robot and on the 626 backend (its fake card), `qmarc cmd grip` while
//! serving, and the refusals when none is wired.

use qmarc_tests::{TestRun, bin_dir, read_gather, read_sim_events, read_summary, run_with_timeout};
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

const TIMEOUT: Duration = Duration::from_secs(120);

/// The `grip` column of gather.csv.
fn grip_column(out: &Path) -> Vec<i64> {
    let (header, rows) = read_gather(out);
    let col = header.iter().position(|h| h == "grip").expect("a grip column");
    assert_eq!(col, header.len() - 1, "grip is the last column: {header:?}");
    rows.iter().map(|r| r[col] as i64).collect()
}

/// The states a column goes through, each once: `[0, 1, 2]` is open, closing, closed.
fn states(column: &[i64]) -> Vec<i64> {
    let mut s = column.to_vec();
    s.dedup();
    s
}

/// `move --to … --grip on` closes the gripper at the end of the move: gather.csv shows it open
/// through the path, closing from its last sample, and closed before the move ends; the
/// simulator's event log has the output switched once, on the gripper's channel. `--grip
/// off` opens it again. The move's time grows by the gripper's travel, not more.
#[test]
fn a_move_closes_the_gripper_at_its_end_on_the_simulated_robot() {
    let run = TestRun::new("gripsim");
    let events = run.out("events.csv");
    let events_value = format!("{:?}", events.display().to_string());
    let config = run.config_with(&[("events_file", &events_value)]);
    let out = run.out("on");
    let (c, o) = (format!("--config={}", config.display()), format!("--out={}", out.display()));
    let r = run
        .starter(&[&c, &o, "--deterministic", "move", "--to=2000,-1000,500", "--grip=on"], TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let grip = grip_column(&out);
    assert_eq!(states(&grip), [0, 1, 2], "open, closing, closed");
    // Closing for its 50 ms (125 cycles of 400 µs), from the path's last sample on.
    let closing = grip.iter().filter(|&&g| g == 1).count();
    assert!((124..=126).contains(&closing), "{closing} cycles closing");
    let (header, rows) = read_gather(&out);
    let cmd1 = header.iter().position(|h| h == "cmd1").unwrap();
    let first_closing = grip.iter().position(|&g| g == 1).unwrap();
    assert_eq!(rows[first_closing - 1][cmd1], 2000.0, "told at the path's end");
    assert!(rows[first_closing..].iter().all(|r| r[cmd1] == 2000.0), "held there");
    let outs: Vec<(String, usize)> = read_sim_events(&events)
        .into_iter()
        .filter(|(_, e, _)| e.starts_with("out_"))
        .map(|(_, e, c)| (e, c))
        .collect();
    assert_eq!(outs, [("out_on".to_string(), 6)], "DIO6 on, once");
    // Opened again at the end of a move back: the new hwserver finds it open (the simulator
    // keeps no outputs between runs), so `off` changes nothing and ends at once.
    let back = run.out("off");
    let o = format!("--out={}", back.display());
    let r = run.starter(&[&c, &o, "--deterministic", "move", "--to=0,0,0", "--grip=off"], TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert_eq!(states(&grip_column(&back)), [0]);
    assert!(read_summary(&back).cycles > 0);
    // `--grip on` alone: in place, the move ends once it is closed.
    let here = run.out("here");
    let o = format!("--out={}", here.display());
    let r = run.starter(&[&c, &o, "--deterministic", "move", "--grip=on"], TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert_eq!(states(&grip_column(&here)), [0, 1, 2], "told in the first cycle");
    assert_eq!(grip_column(&here)[..2], [0, 1], "closing from the second read on");
    let (header, rows) = read_gather(&here);
    assert!(rows.iter().all(|r| r[header.iter().position(|h| h == "cmd1").unwrap()] == 0.0));
    // Nothing at all to do: refused, saying what is missing.
    let r = run.starter(&[&c, &o, "--deterministic", "move"], TIMEOUT);
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("move: where to? --to C1,C2,C3 or --xyz X,Y,Z"), "{}", r.stderr);
    run.assert_clean();
}

/// The same on the 626 backend, over its fake card in real time: the gripper's output is
/// DIO6 of bank 0, and the card's state (no sensor) says closed its travel time after it
/// switched.
#[test]
fn a_move_closes_the_gripper_at_its_end_on_the_626_backend() {
    let run = TestRun::new("grip626");
    let config = qmarc_tests::s626_config();
    let out = run.out("on");
    let (c, o) = (format!("--config={}", config.display()), format!("--out={}", out.display()));
    let bounds = qmarc_tests::rehearsal_bounds();
    let r = run.starter(
        &[&c, &o, "--device=fake", &bounds, "move", "--to=800,-400,200", "--grip=on"],
        TIMEOUT,
    );
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let grip = grip_column(&out);
    assert_eq!(states(&grip), [0, 1, 2], "open, closing, closed");
    assert_eq!(*grip.last().unwrap(), 2);
    run.assert_clean();
}

/// `qmarc cmd grip on|off` while serving: accepted at once, `wait` returns once the gripper
/// is there, `status` says where it is; gather.csv has it. With no gripper wired, `grip` is
/// refused (`no_gripper`) and `move --grip` is refused before anything moves.
#[test]
fn serve_grips_on_command_and_refuses_without_a_gripper() {
    let run = TestRun::new("gripserve");
    let config = run.config_with(&[]);
    let (c, o) =
        (format!("--config={}", config.display()), format!("--out={}", run.out("out").display()));
    let child = run.spawn_starter(&[&c, &o, "--deterministic", "serve"]);
    let cmd = |args: &[&str]| {
        let mut c = Command::new(bin_dir().join("qmarc"));
        c.arg("cmd").args(run.isolation_args()).args(args);
        run_with_timeout(&mut c, TIMEOUT)
    };
    let started = Instant::now();
    while !cmd(&["status"]).stdout.contains("loop serving") {
        assert!(started.elapsed() < TIMEOUT, "the session did not start serving");
        std::thread::sleep(Duration::from_millis(20));
    }
    assert!(cmd(&["status"]).stdout.contains("gripper open"));
    let r = cmd(&["grip", "on"]);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    let r = cmd(&["wait"]);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stdout.contains("gripper closed"), "{}", r.stdout);
    let r = cmd(&["grip", "off"]);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(cmd(&["wait"]).stdout.contains("gripper open"));
    let r = cmd(&["grip", "half"]);
    assert_eq!(r.code, Some(64), "{}", r.stderr);
    assert_eq!(cmd(&["quit"]).code, Some(0));
    let r = qmarc_tests::wait_with_timeout(child, TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert_eq!(states(&grip_column(&run.out("out"))), [0, 1, 2, 3, 0]);

    // No gripper wired: no grip column, `grip` refused, `move --grip` refused.
    let none = run.config_as("none.toml", &qmarc_tests::default_config(), &[("gripper_dio", "-1")]);
    let c = format!("--config={}", none.display());
    let o = format!("--out={}", run.out("none").display());
    let r =
        run.starter(&[&c, &o, "--deterministic", "move", "--to=10,10,10", "--grip=on"], TIMEOUT);
    assert_eq!(r.code, Some(3), "{}\n{}", r.stdout, r.stderr);
    assert!(r.stderr.contains("--grip: no gripper is wired"), "{}", r.stderr);
    let r = run.starter(&[&c, &o, "--deterministic", "move", "--to=10,10,10"], TIMEOUT);
    assert_eq!(r.code, Some(0), "{}\n{}", r.stdout, r.stderr);
    assert!(!read_gather(&run.out("none")).0.contains(&"grip".to_string()));
    let child = run.spawn_starter(&[&c, &o, "--deterministic", "serve"]);
    let started = Instant::now();
    while !cmd(&["status"]).stdout.contains("loop serving") {
        assert!(started.elapsed() < TIMEOUT, "the session did not start serving");
        std::thread::sleep(Duration::from_millis(20));
    }
    let r = cmd(&["grip", "on"]);
    assert_eq!(r.code, Some(3), "{}", r.stdout);
    assert!(r.stdout.starts_with("refused (no_gripper): no gripper is wired"), "{}", r.stdout);
    assert_eq!(cmd(&["quit"]).code, Some(0));
    assert_eq!(qmarc_tests::wait_with_timeout(child, TIMEOUT).code, Some(0));
    run.assert_clean();
}
