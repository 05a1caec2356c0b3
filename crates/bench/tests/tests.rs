//! `qmarc-bench` run as a user runs it, briefly: every subcommand completes, prints its table
//! and (jitter) writes the JSON the issue names; bad options are refused with a message. The
//! figures themselves are the machine's, never asserted.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn bench() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_qmarc-bench"))
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("qmarc-bench-test-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn run(args: &[&str]) -> Output {
    Command::new(bench()).args(args).current_dir(workspace()).output().unwrap()
}

fn text(o: &Output) -> String {
    format!("{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr))
}

/// The shipped settings with the simulated robot's state kept nowhere (tests never share
/// /dev/shm/qmarc-sim.state).
fn config(dir: &Path) -> PathBuf {
    let shipped = std::fs::read_to_string(workspace().join("config/qmarc.toml")).unwrap();
    let own: String = shipped
        .lines()
        .map(|l| if l.starts_with("state_file = ") { "state_file = \"\"" } else { l })
        .collect::<Vec<_>>()
        .join("\n");
    let path = dir.join("qmarc.toml");
    std::fs::write(&path, own + "\n").unwrap();
    path
}

#[test]
fn jitter_runs_both_loops_and_writes_the_ratio() {
    let starter = bench().with_file_name("qmarc-starter");
    assert!(starter.is_file(), "{} missing: build the workspace", starter.display());
    let dir = scratch("jitter");
    let json = dir.join("j.json");
    let cfg = config(&dir);
    let out = run(&[
        "jitter",
        "--rounds=2",
        "--segment-s=0.3",
        "--warmup-s=0.1",
        "--bare-work-us=10",
        &format!("--config={}", cfg.display()),
        &format!("--json={}", json.display()),
    ]);
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    assert!(t.contains("p99 ratio servo/bare: median"), "{t}");
    assert!(t.contains("the bare loop busy 10 µs after each wake"), "{t}");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    for key in ["p99_ratio_median", "p99_ratio_min", "p99_ratio_max", "p99_diff_us_median"] {
        assert!(j[key].as_f64().is_some_and(f64::is_finite), "{key}: {j}");
    }
    assert!(j["noisy_host"].is_boolean());
    assert!(j.get("missed_all_timers").is_some_and(serde_json::Value::is_null), "one timer: {j}");
    let rounds = j["timers"][0]["rounds"].as_array().unwrap();
    assert_eq!(rounds.len(), 2);
    assert_eq!(
        (rounds[0]["first"].as_str(), rounds[1]["first"].as_str()),
        (Some("bare"), Some("servo"))
    );
    assert!(j["timers"][0]["missed_worked"].is_u64(), "{j}");
    for r in rounds {
        assert!(r["bare"]["cycles"].as_u64().unwrap() >= 700, "{r}");
        assert!(r["worked"]["periods"].as_u64().unwrap() >= 700, "{r}");
        assert!(
            r["bare"]["output_us"].is_null() && r["servo"]["output_us"]["p99"].is_number(),
            "{r}"
        );
        assert!(r["servo"]["wake_us"]["p99"].as_f64().unwrap() > 0.0, "{r}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn ipc_prints_the_exchange_beside_both_baselines() {
    let dir = scratch("ipc");
    let json = dir.join("ipc.json");
    let out = run(&["ipc", "--samples=300", &format!("--json={}", json.display())]);
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    for row in [
        "controller ⇄ hwserver exchange",
        "the same, both pinned to CPU 0",
        "iceoryx2 request/response ports alone",
        "raw futex ping-pong, 2 threads",
        "raw futex ping-pong, 2 processes",
        "raw spin ping-pong",
        "blocking, one exchange per 400 µs tick",
    ] {
        assert!(t.contains(row), "{row}: {t}");
    }
    assert!(t.contains("exchange p50 ="), "{t}");
    let j: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
    assert_eq!(j["rows"].as_array().map(Vec::len), Some(12), "{j}");
    for key in [
        "blocking_over_futex",
        "one_cpu_over_futex",
        "blocking_over_process_futex",
        "one_cpu_over_process_futex",
        "spinning_over_spin",
        "ports_over_spin",
        "paced_over_back_to_back",
    ] {
        assert!(j[key].as_f64().is_some_and(|r| r.is_finite() && r > 0.0), "{key}: {j}");
    }
    assert!(j["rows"][0]["p99"].as_f64().unwrap() > 0.0, "{j}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn cycle_times_every_generator_and_law_for_1_to_4_motors() {
    let out = run(&["cycle", "--cycles=2000"]);
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    for name in qmarc_plugins::registry::GENERATORS.iter().map(|g| g.name) {
        let row = t.lines().find(|l| l.split_whitespace().nth(1) == Some(name));
        let row = row.unwrap_or_else(|| panic!("no row for {name}: {t}"));
        if name == "linear" || name == "pick" {
            // A line and the pick cycle need the Delta: three motors only, "—" for the others.
            let words: Vec<&str> = row.split_whitespace().collect();
            assert_eq!((words.len(), words[2], words[3], words[6]), (7, "—", "—", "—"), "{row}");
        } else {
            assert_eq!(row.split_whitespace().count(), 2 + 2 * 4, "{row}");
        }
    }
    assert!(t.contains("a new target mid-motion") && t.contains("recomputation mean"), "{t}");
}

#[test]
fn command_measures_a_serving_sessions_moves() {
    let t = serving_bench("cmd", &["command", "--moves=5"]);
    assert!(t.contains("qmarc-bench command: 5 moves"), "{t}");
    assert!(t.contains("read → taken by the loop") && t.contains("of 5"), "{t}");
}

/// Issue 30: the pick-and-place cycle runs through a serving session with the gripper and
/// prints its figures.
#[test]
fn pick_runs_the_delta_cycle_through_a_serving_session() {
    let t = serving_bench("pick", &["pick", "--cycles=2", "--blend-mm=3"]);
    assert!(t.contains("qmarc-bench pick: 2 cycles at (-150, 0, -600) mm"), "{t}");
    assert!(t.contains("picks/min") && t.contains("thesis X-Z path"), "{t}");
    // How many telemetry samples a loaded machine's reader lost is the benchmark's figure,
    // not this test's (issue 48): the line says it.
    assert!(t.contains("tracking error (") && t.contains(" lost): effector max"), "{t}");
}

/// Issue 46: detection timed on rendered frames beside imageproc's labelling, with its
/// accuracy and the calibration's fit (the conveyor session left out: `--seconds 0`).
#[test]
fn vision_times_detection_and_measures_its_accuracy() {
    let out = run(&["vision", "--frames=3", "--parts=20", "--seconds=0"]);
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    for says in [
        "calibration on the rendered 11x9 target: reprojection mean ",
        "detection, 3 frames of 1280×1024 with 20 parts, one core: p50 ",
        "imageproc's threshold + connected components",
        "accuracy, 60 parts: position error p50 ",
    ] {
        assert!(t.contains(says), "{says}: {t}");
    }
    let bad = run(&["vision", "--parts=21"]);
    assert_eq!(bad.status.code(), Some(64), "{}", text(&bad));
}

/// Issue 47: a cell of two robots — sharing the belt on one host, then the upstream one
/// killed mid-run — runs and prints its figures (one cell at a time on the machine: the
/// end-to-end cell tests' lock).
#[test]
fn cell_runs_two_robots_sharing_a_belt_and_one_killed() {
    let lock = std::fs::File::create(std::env::temp_dir().join("qmarc-tests-cell.lock")).unwrap();
    let _one_cell = nix::fcntl::Flock::lock(lock, nix::fcntl::FlockArg::LockExclusive)
        .map_err(|(_, e)| e)
        .unwrap();
    let t = serving_bench("cell", &["cell", "--seconds=12", "--kill-at-s=4", "--one-host"]);
    for says in [
        "both on this host (loopback): ",
        " picks/min together over ",
        "west's claims seen by east (",
        "west killed 4 s after both moved: until then ",
    ] {
        assert!(t.contains(says), "{says}: {t}");
    }
}

/// Runs `qmarc-bench ARGS` (a subcommand that serves a session under the prefix of `name`)
/// on the shipped settings; asserts it succeeded and left nothing behind; its output.
fn serving_bench(name: &str, args: &[&str]) -> String {
    let dir = scratch(name);
    let cfg = config(&dir);
    let child = Command::new(bench())
        .args(args)
        .arg(format!("--config={}", cfg.display()))
        .current_dir(workspace())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let prefix = format!("qmarc_bench{name}_{}_", child.id());
    let out = child.wait_with_output().unwrap();
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    let left: Vec<_> = std::fs::read_dir("/dev/shm")
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .collect();
    assert!(left.is_empty(), "left behind: {left:?}");
    let _ = std::fs::remove_dir_all(&dir);
    t
}

#[test]
fn bad_options_are_refused_with_a_message() {
    let out = run(&["jitter", "--rounds=0"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out).contains("--rounds must be ≥ 1"), "{}", text(&out));
    let child = Command::new(bench())
        .args(["jitter", "--timer=posix", "--segment-s=0.1"])
        .current_dir(workspace())
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let scratch = std::env::temp_dir().join(format!("qmarc-bench-jitter-{}", child.id()));
    let out = child.wait_with_output().unwrap();
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out).contains("\"posix\""), "{}", text(&out));
    assert!(!scratch.exists(), "{} left behind", scratch.display());
    let out = run(&["jitter", "--period-us=abc"]);
    assert_eq!(out.status.code(), Some(64), "a usage error");
    let out = run(&["jitter", "--spin", "--pin=same", "--segment-s=0.1"]);
    assert_eq!(out.status.code(), Some(1));
    assert!(text(&out).contains("--spin needs the hwserver on a CPU of its own"), "{}", text(&out));
}

/// `rounds` short rounds of `jitter` with `extra` options on the test's own settings copy in
/// `dir`: its output and its JSON.
fn short_jitter(dir: &Path, rounds: u32, extra: &[&str]) -> (String, serde_json::Value) {
    let json = dir.join("j.json");
    let cfg = config(dir);
    let (c, j) = (format!("--config={}", cfg.display()), format!("--json={}", json.display()));
    let r = format!("--rounds={rounds}");
    let mut args = vec!["jitter", &r, "--segment-s=0.2", "--warmup-s=0.1", &c, &j];
    args.extend_from_slice(extra);
    let out = run(&args);
    let t = text(&out);
    assert!(out.status.success(), "{t}");
    (t, serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap())
}

/// `--pin=same`: the blocking pair shares CPU 0 with the bare loop (the 10 kHz recipe of
/// BENCHMARKS.md); the settings copy pins both and the missed periods outside host stalls are
/// reported for both loops.
#[test]
fn jitter_runs_with_both_processes_on_one_cpu() {
    let dir = scratch("same");
    let (t, j) = short_jitter(&dir, 1, &["--period-us=200", "--pin=same"]);
    assert!(t.contains("servo, hwserver and bare loop on CPU 0"), "{t}");
    assert!(t.contains("outside host stalls (a wake ≥ 1 ms late) servo"), "{t}");
    assert!(t.contains("per 100 000 periods"), "{t}");
    assert_eq!((j["spin"].as_bool(), j["pin"].as_str()), (Some(false), Some("same")));
    let timer = &j["timers"][0];
    for key in [
        "missed_servo_outside_stalls",
        "missed_bare_outside_stalls",
        "periods_servo",
        "periods_bare",
    ] {
        assert!(timer[key].as_u64().is_some(), "{key}: {timer}");
    }
    let servo = &timer["rounds"][0]["servo"];
    assert!(servo["cycles"].as_u64().unwrap() > 0, "{servo}");
    assert!(servo["missed_in_stalls"].as_u64().unwrap() <= servo["missed"].as_u64().unwrap());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--spin --pin`: the servo segments run with a spinning hwserver on CPU 1 and a polling
/// controller; the settings copy says so and the pipeline still reports every figure.
#[test]
fn jitter_runs_with_a_spinning_hwserver() {
    let dir = scratch("spin");
    let (t, j) = short_jitter(&dir, 1, &["--spin", "--pin"]);
    assert!(
        t.contains("hwserver spinning, servo and bare loop on CPU 0, hwserver on CPU 1"),
        "{t}"
    );
    assert_eq!((j["spin"].as_bool(), j["pin"].as_str()), (Some(true), Some("split")));
    let servo = &j["timers"][0]["rounds"][0]["servo"];
    assert!(servo["output_us"]["p99"].as_f64().unwrap() > 0.0, "{servo}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--timer both`: the timers take turns within each round, the first one turning round by
/// round, so both meet the same hour of the host; each round says when it started, and the
/// missed periods of both timers are also given together.
#[test]
fn jitter_timers_take_turns_within_each_round() {
    let dir = scratch("turns");
    let (t, j) = short_jitter(&dir, 2, &["--timer=both", "--period-us=500"]);
    assert!(t.contains("the timers taking turns within each round"), "{t}");
    let start = |timer: usize, round: usize| {
        let r = &j["timers"][timer]["rounds"][round];
        r["started_s"].as_f64().unwrap_or_else(|| panic!("no started_s: {r}"))
    };
    assert_eq!(j["timers"][1]["timer"].as_str(), Some("nanosleep"), "{j}");
    assert!(start(0, 0) < start(1, 0), "round 1: timerfd, then nanosleep: {j}");
    assert!(start(1, 1) < start(0, 1), "round 2: nanosleep, then timerfd: {j}");
    assert!(t.contains("all timers together: missed periods servo"), "{t}");
    let together = &j["missed_all_timers"];
    for (key, of) in
        [("servo", "missed_servo"), ("bare_outside_stalls", "missed_bare_outside_stalls")]
    {
        let sum: u64 = (0..2).map(|i| j["timers"][i][of].as_u64().unwrap()).sum();
        assert_eq!(together[key].as_u64(), Some(sum), "{key}: {j}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
