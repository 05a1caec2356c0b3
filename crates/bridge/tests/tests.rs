//! `qmarc-bridge` against a real serving session and a real ROS 2 client with no ROS 2: the
//! Python client of `examples/ros2_client.py` (PyPI's eclipse-zenoh and rosbags, installed by
//! `scripts/test`), over Zenoh on loopback. It sees the joint states and the effector, calls
//! the services, sends a target the robot goes to, and what is malformed never reaches the
//! controller; kill -9 of the bridge mid-move changes nothing in the move.

use qmarc_proto::command::{CommandClient, CommandKind, CommandRequest};
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

fn bridge_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_qmarc-bridge"))
}

fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The interpreter with eclipse-zenoh and rosbags.
fn python() -> PathBuf {
    let python = std::env::var_os("QMARC_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target/pyenv/bin/python3"));
    let ok = Command::new(&python)
        .args(["-c", "import zenoh, rosbags"])
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success());
    assert!(
        ok,
        "{} cannot import zenoh and rosbags: run the tests with scripts/test, which installs \
         tests/requirements.txt into target/pyenv (or set QMARC_PYTHON)",
        python.display()
    );
    python
}

/// A scratch folder of test `name` with the shipped settings in it, the simulated robot's
/// homed frame kept nowhere (tests never share /dev/shm/qmarc-sim.state): the folder and the
/// settings file.
fn scratch(name: &str) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("qmarc-bridge-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let shipped = std::fs::read_to_string(workspace().join("config/qmarc.toml")).unwrap();
    let own: Vec<&str> = shipped
        .lines()
        .map(|l| if l.starts_with("state_file = ") { "state_file = \"\"" } else { l })
        .collect();
    let config = dir.join("qmarc.toml");
    std::fs::write(&config, own.join("\n") + "\n").unwrap();
    (dir, config)
}

/// A serving session, its bridge and their scratch folder; stopped and cleaned up on drop.
struct Cell {
    dir: PathBuf,
    prefix: String,
    session: Option<Child>,
    bridge: Option<Child>,
    endpoint: String,
    namespace: String,
}

impl Cell {
    fn start(name: &str, namespace: &str) -> Cell {
        let (dir, config) = scratch(name);
        let prefix = format!("qmarc_bridge{name}_{}_", std::process::id());
        let starter = bridge_bin().with_file_name("qmarc-starter");
        assert!(starter.is_file(), "{} missing: build the workspace", starter.display());
        let session = Command::new(&starter)
            .arg(format!("--config={}", config.display()))
            .arg(format!("--out={}", dir.join("out").display()))
            .arg(format!("--iox-prefix={prefix}"))
            .arg("--deterministic")
            .arg("serve")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap().local_addr().unwrap().port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let zenoh = dir.join("zenoh.json5");
        std::fs::write(
            &zenoh,
            format!(
                "{{ mode: \"peer\", listen: {{ endpoints: [\"{endpoint}\"] }}, \
                 scouting: {{ multicast: {{ enabled: false }}, gossip: {{ enabled: false }} }} }}"
            ),
        )
        .unwrap();
        let mut cell = Cell {
            dir,
            prefix,
            session: Some(session),
            bridge: None,
            endpoint,
            namespace: namespace.into(),
        };
        cell.client();
        let bridge = Command::new(bridge_bin())
            .arg(format!("--iox-prefix={}", cell.prefix))
            .arg(format!("--zenoh-config={}", zenoh.display()))
            .arg(format!("--namespace={namespace}"))
            .stdout(Stdio::null())
            .stderr(std::fs::File::create(cell.dir.join("bridge.log")).unwrap())
            .spawn()
            .unwrap();
        cell.bridge = Some(bridge);
        cell
    }

    /// A command client, once the session serves.
    fn client(&self) -> CommandClient {
        let location = IpcLocation::new(&self.prefix, DEFAULT_ROOT);
        let started = Instant::now();
        loop {
            let c = CommandClient::connect(&location)
                .and_then(|mut c| c.send(CommandRequest::of(CommandKind::Status)).map(|s| (c, s)));
            match c {
                Ok((c, s)) if s.phase == qmarc_proto::state::Phase::Moving.code() => return c,
                _ => assert!(started.elapsed() < Duration::from_secs(30), "no serving session"),
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// `ros2_client.py ARGS` against the bridge; its output.
    fn ros2(&self, args: &[&str]) -> Output {
        Command::new(python())
            .arg(workspace().join("examples/ros2_client.py"))
            .arg(format!("--connect={}", self.endpoint))
            .arg(format!("--namespace={}", self.namespace))
            .args(args)
            .output()
            .unwrap()
    }

    /// The JSON lines of a client run that must succeed.
    fn lines(&self, args: &[&str]) -> Vec<serde_json::Value> {
        let out = self.ros2(args);
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "{args:?}: {text}\n{}\nbridge: {}",
            String::from_utf8_lossy(&out.stderr),
            self.bridge_log()
        );
        text.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
    }

    fn bridge_log(&self) -> String {
        std::fs::read_to_string(self.dir.join("bridge.log")).unwrap_or_default()
    }

    /// Quits the session; its exit status.
    fn quit(&mut self) -> std::process::ExitStatus {
        let _ = self.client().send(CommandRequest::of(CommandKind::Quit));
        self.session.take().unwrap().wait().unwrap()
    }
}

impl Drop for Cell {
    fn drop(&mut self) {
        for child in [self.bridge.as_mut(), self.session.as_mut()].into_iter().flatten() {
            let _ = child.kill();
            let _ = child.wait();
        }
        IpcLocation::new(&self.prefix, DEFAULT_ROOT).remove_files();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

/// ROS 2 sees the robot (joint states at rest at home, the effector, the diagnostics), calls
/// its services, moves it to a target; garbage and impossible targets are refused on the
/// bridge and said in the diagnostics, the robot unmoved; kill -9 of the bridge mid-move
/// changes nothing in the move.
#[test]
fn a_ros2_client_sees_and_commands_the_robot_through_the_bridge() {
    let mut cell = Cell::start("cmd", "/robot1");
    let js = cell.lines(&["joint-states", "20"]);
    assert_eq!(js.len(), 20);
    assert_eq!(js[0]["name"], serde_json::json!(["motor1", "motor2", "motor3"]));
    for j in &js {
        for p in j["position"].as_array().unwrap() {
            assert!(close(p.as_f64().unwrap(), 0.0, 1e-3), "at home: {j}");
        }
    }
    let seqs: Vec<i64> = js.iter().map(|j| j["seq"].as_i64().unwrap()).collect();
    assert!(seqs.windows(2).all(|w| w[1] > w[0]), "sequence numbers rise: {seqs:?}");
    let fx = cell.lines(&["effector", "1"]);
    assert_eq!(fx[0]["frame"], "base");
    let diag = cell.lines(&["diagnostics", "1"]);
    assert_eq!(diag[0]["values"]["phase"], "moving", "{diag:?}");
    assert_eq!(diag[0]["values"]["homed"], "true");
    // The services.
    let r = cell.lines(&["gripper", "on"]);
    assert_eq!((r[0]["success"].as_bool(), r[0]["gid_echoed"].as_bool()), (Some(true), Some(true)));
    let r = cell.lines(&["stop"]);
    assert_eq!(r[0]["success"], true, "{r:?}");
    // A target the robot goes to.
    cell.lines(&["target", "0.02", "-0.01", "-0.64"]);
    let mut client = cell.client();
    let s = client.wait(Duration::from_secs(30)).unwrap();
    let [x, y, z] = s.effector_mm;
    assert!(close(x, 20.0, 1e-6) && close(y, -10.0, 1e-6) && close(z, -640.0, 1e-6), "{x} {y} {z}");
    // An unreachable one: the controller refuses it, the bridge says why.
    let before = client.send(CommandRequest::of(CommandKind::Status)).unwrap().accepted;
    cell.lines(&["target", "0", "0", "-0.2"]);
    let diag = cell.lines(&["diagnostics", "2"]);
    assert!(
        diag.iter().any(|d| d["values"]["refused"].as_str().unwrap().contains("unreachable")),
        "{diag:?}"
    );
    // Garbage and an oversized payload: not taken, nothing sent on.
    cell.lines(&["raw-target", "3"]);
    cell.lines(&["raw-target", "2000000"]);
    let log = cell.bridge_log();
    assert!(log.contains("qmarc/target: not taken: not a geometry_msgs/msg/PointStamped"), "{log}");
    assert!(log.contains("more than the 1048576 taken"), "{log}");
    let after = client.send(CommandRequest::of(CommandKind::Status)).unwrap();
    assert_eq!(after.accepted, before, "nothing reached the controller");
    let knots = joint_trajectories(&cell, &mut client, after.command);

    // kill -9 of the bridge mid-move: the move goes on to its end.
    let r = client.send(CommandRequest::move_xyz([-30.0, 20.0, -650.0], false, 0.2)).unwrap();
    assert_eq!(r.ok, 1);
    let bridge = cell.bridge.as_mut().unwrap();
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(bridge.id() as i32),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    bridge.wait().unwrap();
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert_eq!((s.fault, s.settled, s.moving), (0, r.accepted, 0), "the move ended as sent");
    let [x, y, z] = s.effector_mm;
    assert!(close(x, -30.0, 1e-6) && close(y, 20.0, 1e-6) && close(z, -650.0, 1e-6));
    drop(client);
    assert!(cell.quit().success());
    // What the robot did: the trajectory's knots are commands of gather.csv, exactly.
    let (header, rows) = qmarc_tests::read_gather(&cell.dir.join("out"));
    let col = |m: usize| header.iter().position(|h| *h == format!("cmd{}", m + 1)).unwrap();
    for knot in knots {
        let hit = rows.iter().any(|r| (0..3).all(|m| close(r[col(m)], knot[m], 1e-6)));
        assert!(hit, "no command at the knot {knot:?}");
    }
}

/// A joint trajectory from where the robot rests (`rest`, counts): followed through its
/// knots, each in rad from home; one with a wrong joint is not taken by the bridge, one too
/// fast is refused by the controller, both said. The knots, counts.
fn joint_trajectories(cell: &Cell, client: &mut CommandClient, rest: [f64; 4]) -> Vec<[f64; 3]> {
    let per_rad = settings().counts_per_rad();
    let rad = |m: usize, by: f64| rest[m] / per_rad + by;
    let knots =
        [[rad(0, 0.05), rad(1, -0.03), rad(2, 0.02)], [rad(0, 0.1), rad(1, 0.0), rad(2, 0.0)]];
    let spec = serde_json::json!({
        "names": ["motor2", "motor1", "motor3"],
        "points": [
            {"t": 0.3, "positions": [knots[0][1], knots[0][0], knots[0][2]]},
            {"t": 0.6, "positions": [knots[1][1], knots[1][0], knots[1][2]]},
        ],
    });
    let before = client.send(CommandRequest::of(CommandKind::Status)).unwrap().accepted;
    cell.lines(&["trajectory", &spec.to_string()]);
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert_eq!(
        (s.accepted, s.settled, s.fault),
        (before + 1, before + 1, 0),
        "{}",
        cell.bridge_log()
    );
    let counts = knots.map(|k| k.map(|r| r * per_rad));
    for m in 0..3 {
        assert!(close(s.command[m], counts[1][m], 1e-6), "{:?} {:?}", s.command, counts[1]);
    }
    // Not motor1…motor3: not taken. Too fast for the motors: the controller says why.
    let wrong = serde_json::json!({"names": ["motor1", "motor2", "elbow"], "points": [{"t": 1.0, "positions": [0.0, 0.0, 0.0]}]});
    cell.lines(&["trajectory", &wrong.to_string()]);
    let fast = serde_json::json!({"names": ["motor1", "motor2", "motor3"], "points": [{"t": 0.01, "positions": [1.0, 0.0, 0.0]}]});
    cell.lines(&["trajectory", &fast.to_string()]);
    let log = cell.bridge_log();
    assert!(
        log.contains(
            "qmarc/joint_trajectory: not taken: joint_names must be motor1, motor2, motor3"
        ),
        "{log}"
    );
    let diag = cell.lines(&["diagnostics", "2"]);
    assert!(
        diag.iter().any(|d| d["values"]["refused"]
            .as_str()
            .unwrap()
            .contains("max_velocity_counts_per_s")),
        "{diag:?}"
    );
    assert_eq!(client.send(CommandRequest::of(CommandKind::Status)).unwrap().accepted, before + 1);
    counts.to_vec()
}

/// The shipped settings.
fn settings() -> qmarc_config::Settings {
    qmarc_config::Settings::load(
        &workspace().join("config/qmarc.toml"),
        &qmarc_config::Names::any(),
    )
    .unwrap()
}

/// `qmarc-starter serve --bridge`: the bridge starts with the session, on rmw_zenoh's
/// defaults (it connects to a router at tcp/localhost:7447, which the client stands in for);
/// kill -9 of it changes nothing in the session, which says so; the session's end leaves no
/// bridge behind.
#[test]
fn serve_with_bridge_starts_it_and_outlives_its_death() {
    let (dir, config) = scratch("serve");
    let prefix = format!("qmarc_bridgeserve_{}_", std::process::id());
    let session = Command::new(bridge_bin().with_file_name("qmarc-starter"))
        .arg(format!("--config={}", config.display()))
        .arg(format!("--out={}", dir.join("out").display()))
        .arg(format!("--iox-prefix={prefix}"))
        .args(["--deterministic", "serve", "--bridge"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let out = Command::new(python())
        .arg(workspace().join("examples/ros2_client.py"))
        .args(["--listen=tcp/127.0.0.1:7447", "joint-states", "5"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(String::from_utf8_lossy(&out.stdout).lines().count(), 5);
    let bridges = || -> Vec<i32> {
        let pgrep = Command::new("pgrep")
            .args(["-f", &format!("qmarc-bridge --iox-prefix={prefix}")])
            .output()
            .unwrap();
        String::from_utf8_lossy(&pgrep.stdout)
            .lines()
            .filter_map(|l| l.trim().parse().ok())
            .collect()
    };
    let pids = bridges();
    assert_eq!(pids.len(), 1, "one bridge: {pids:?}");
    nix::sys::signal::kill(nix::unistd::Pid::from_raw(pids[0]), nix::sys::signal::Signal::SIGKILL)
        .unwrap();
    let location = IpcLocation::new(&prefix, DEFAULT_ROOT);
    let mut client = CommandClient::connect(&location).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let r = client.send(CommandRequest::move_to(&[500.0, -500.0, 250.0], 1.0)).unwrap();
    assert_eq!(r.ok, 1, "still serving: {}", r.reason());
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert_eq!((s.fault, s.command[..3].to_vec()), (0, vec![500.0, -500.0, 250.0]));
    client.send(CommandRequest::of(CommandKind::Quit)).unwrap();
    drop(client);
    let end = session.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&end.stderr);
    assert!(end.status.success(), "{stderr}");
    assert!(stderr.contains("qmarc-bridge was killed by SIGKILL; the session goes on"), "{stderr}");
    assert!(bridges().is_empty(), "no bridge left");
    location.remove_files();
    let _ = std::fs::remove_dir_all(&dir);
}
