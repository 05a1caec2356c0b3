//! The live view (issue 45): `qmarc-starter serve --foxglove ADDR` serves a session's robot,
//! joint states, effector, rows and log over the Foxglove WebSocket protocol
//! (`foxglove.websocket.v1`), to a viewer with no Foxglove (`examples/foxglove_client.py`:
//! PyPI's websockets, protobuf, rosbags). Viewers that vanish (kill -9) or never read change
//! nothing in the session; the view's own death ends nothing; Ctrl-C ends everything and
//! leaves nothing behind; an address that is taken is refused before anything starts.

use nix::sys::signal::{Signal, kill};
use nix::unistd::Pid;
use qmarc_tests::{TestRun, config_arg, processes_matching, wait_with_timeout, workspace};
use serde_json::Value;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A TCP port nobody listens on now.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port()
}

/// The viewers a test started, killed if it fails (a failed assertion leaves no viewer
/// behind, not even one that `--hang`s); a test that passes has ended each itself.
#[derive(Default)]
struct Viewers(Vec<u32>);

impl Viewers {
    /// `foxglove_client.py` against `port` with `args`, its output piped.
    fn start(&mut self, port: u16, args: &[&str]) -> Child {
        let child = Command::new(qmarc_tests::python())
            .arg(workspace().join("examples/foxglove_client.py"))
            .arg(format!("--url=ws://127.0.0.1:{port}"))
            .args(args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("start the viewer");
        self.0.push(child.id());
        child
    }
}

impl Drop for Viewers {
    fn drop(&mut self) {
        if std::thread::panicking() {
            for &pid in &self.0 {
                let _ = kill(Pid::from_raw(pid as i32), Signal::SIGKILL);
            }
        }
    }
}

/// Waits until `qmarc cmd status` answers: the session serves.
fn until_serving(run: &TestRun) {
    let start = Instant::now();
    while run.cmd(&["status"]).code != Some(0) {
        assert!(start.elapsed() < Duration::from_secs(60), "the session never served");
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// The live view's pid, once it listens at `port`.
fn live_view(run: &TestRun, port: u16) -> u32 {
    let start = Instant::now();
    loop {
        let found = processes_matching(&run.prefix)
            .into_iter()
            .find(|(_, c)| c.contains("qmarc-foxglove live"));
        if let Some((pid, _)) = found
            && std::net::TcpStream::connect(("127.0.0.1", port)).is_ok()
        {
            return pid;
        }
        assert!(start.elapsed() < Duration::from_secs(60), "no live view at {port}");
        std::thread::sleep(Duration::from_millis(50));
    }
}

#[test]
fn a_viewer_sees_the_robot_move_live_and_viewers_that_vanish_or_stall_change_nothing() {
    let run = TestRun::new("live");
    let port = free_port();
    let out = run.out("out");
    let addr = format!("127.0.0.1:{port}");
    let starter = run.spawn_starter(&[
        &config_arg(),
        &format!("--out={}", out.display()),
        "serve",
        "--foxglove",
        &addr,
    ]);
    until_serving(&run);
    let view = live_view(&run, port);
    let mut viewers = Viewers::default();
    // One viewer that stops reading once subscribed, one killed mid-stream, one that watches.
    let mut stalled = viewers.start(port, &["--hang"]);
    let mut killed = viewers.start(port, &["--seconds=60"]);
    let ready = run.out("subscribed");
    let watching = viewers.start(port, &["--seconds=6", &format!("--ready={}", ready.display())]);
    let start = Instant::now();
    while !ready.exists() {
        assert!(start.elapsed() < Duration::from_secs(60), "the viewer never subscribed");
        std::thread::sleep(Duration::from_millis(50));
    }
    let _ = kill(Pid::from_raw(killed.id() as i32), Signal::SIGKILL);
    let _ = killed.wait();
    let target = [0.0, 50.0, -650.0];
    let moved = run.cmd(&["move", "--xyz", "0,50,-650"]);
    assert_eq!(moved.code, Some(0), "{}{}", moved.stdout, moved.stderr);
    let waited = run.cmd(&["wait"]);
    assert_eq!(waited.code, Some(0), "the move ends as sent: {}{}", waited.stdout, waited.stderr);
    let seen = wait_with_timeout(watching, Duration::from_secs(60));
    assert_eq!(seen.code, Some(0), "{}", seen.stderr);
    let found: Value =
        serde_json::from_str(seen.stdout.trim()).unwrap_or_else(|e| panic!("{e}: {}", seen.stdout));
    assert_eq!(found["subprotocol"], "foxglove.websocket.v1");
    let topics =
        ["/joint_states", "/qmarc/effector", "/qmarc/gather", "/qmarc/log", "/qmarc/scene"];
    assert_eq!(found["advertised"], serde_json::json!(topics));
    let count = |t: &str| found["counts"][t].as_u64().unwrap_or(0);
    // Samples and scenes stream (their rates, 625 and 50 a second, are the benchmark's: a
    // loaded machine running a debug build delivers fewer, the oldest dropped for a viewer
    // that falls behind).
    for (topic, at_least) in [("/joint_states", 50), ("/qmarc/effector", 50), ("/qmarc/scene", 5)] {
        assert!(count(topic) >= at_least, "{topic}: {found}");
    }
    assert_eq!(found["entities"], serde_json::json!(["deltabot"]));
    assert_eq!(found["joint_state"]["name"], serde_json::json!(["motor1", "motor2", "motor3"]));
    let act = &found["last_effector"]["act"];
    let at = [act["x"].as_f64().unwrap(), act["y"].as_f64().unwrap(), act["z"].as_f64().unwrap()];
    let off = (0..3).map(|k| (at[k] - target[k]).powi(2)).sum::<f64>().sqrt();
    assert!(off < 1.0, "the effector at {at:?}, {off} mm from the target");
    let said: Vec<&str> =
        found["log"].as_array().unwrap().iter().filter_map(|l| l[1].as_str()).collect();
    assert!(
        said.contains(&"order 1 accepted") && said.contains(&"at rest: order 1 done"),
        "{said:?}"
    );
    // The stalled viewer is still connected and the session still answers at once.
    assert!(stalled.try_wait().unwrap().is_none(), "the stalled viewer is still there");
    assert_eq!(run.cmd(&["status"]).code, Some(0));
    // The view itself killed: the session goes on.
    let _ = kill(Pid::from_raw(view as i32), Signal::SIGKILL);
    let moved = run.cmd(&["move", "--xyz", "0,0,-640"]);
    assert_eq!(moved.code, Some(0), "{}", moved.stderr);
    assert_eq!(run.cmd(&["wait"]).code, Some(0));
    // Ctrl-C ends the session, everything of it.
    let _ = kill(Pid::from_raw(starter.id() as i32), Signal::SIGINT);
    let end = wait_with_timeout(starter, Duration::from_secs(60));
    assert_eq!(end.code, Some(i32::from(qmarc_proto::exit::INTERRUPTED)), "{}", end.stderr);
    assert!(
        end.stderr.contains("qmarc-foxglove was killed by SIGKILL; the session goes on"),
        "{}",
        end.stderr
    );
    let _ = stalled.kill();
    let _ = stalled.wait();
    let s = qmarc_tests::read_summary(&out);
    assert_eq!(s.fault.map(|f| f.kind.name()), Some("aborted"));
    run.assert_clean();
}

/// `conveyor --foxglove`: the belt and the parts on it, live, and the log says each part
/// picked.
#[test]
fn a_conveyor_sessions_live_view_shows_the_belt_and_its_parts() {
    let run = TestRun::new("live-belt");
    let port = free_port();
    let out = run.out("out");
    let addr = format!("127.0.0.1:{port}");
    let config = qmarc_tests::tuned_config();
    let starter = run.spawn_starter(&[
        &format!("--config={}", config.display()),
        &format!("--out={}", out.display()),
        "conveyor",
        "--seconds=60",
        "--foxglove",
        &addr,
    ]);
    until_serving(&run);
    live_view(&run, port);
    let mut viewers = Viewers::default();
    // The first part reaches the window about 2 s after the belt starts.
    let seen = wait_with_timeout(viewers.start(port, &["--seconds=6"]), Duration::from_secs(60));
    assert_eq!(seen.code, Some(0), "{}", seen.stderr);
    let found: Value =
        serde_json::from_str(seen.stdout.trim()).unwrap_or_else(|e| panic!("{e}: {}", seen.stdout));
    assert_eq!(found["entities"], serde_json::json!(["belt", "deltabot"]), "{found}");
    assert!(found["max_parts"].as_u64().unwrap_or(0) >= 1, "{found}");
    let said: Vec<&str> =
        found["log"].as_array().unwrap().iter().filter_map(|l| l[1].as_str()).collect();
    assert!(said.iter().any(|l| l.starts_with("part picked (")), "{said:?}");
    assert_eq!(run.cmd(&["quit"]).code, Some(0));
    let end = wait_with_timeout(starter, Duration::from_secs(90));
    assert_eq!(end.code, Some(0), "{}", end.stderr);
    run.assert_clean();
}

/// `--foxglove` at an address something else holds: refused before anything starts.
#[test]
fn a_taken_address_is_refused_before_anything_starts() {
    let run = TestRun::new("live-taken");
    let held = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let addr = held.local_addr().unwrap().to_string();
    let r = run.starter(&[&config_arg(), "serve", "--foxglove", &addr], Duration::from_secs(60));
    assert_eq!(r.code, Some(i32::from(qmarc_proto::exit::REFUSED)), "{}", r.stderr);
    assert!(
        r.stderr.contains(&format!("--foxglove {addr}: cannot serve the live view there")),
        "{}",
        r.stderr
    );
    run.assert_clean();
}
