//! `qmarc-bridge` against a real serving session and a real ROS 2 client with no ROS 2: the
//! Python client of `examples/ros2_client.py` (PyPI's eclipse-zenoh and rosbags, installed by
//! `scripts/test`), over Zenoh on loopback. It sees the joint states and the effector, calls
//! the services, sends a target the robot goes to, and what is malformed never reaches the
//! controller; kill -9 of the bridge mid-move changes nothing in the move.

use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation};
use qmarc_session::client::CommandClient;
use qmarc_session::wire::{CommandKind, CommandRequest};
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
/// homed frame kept nowhere (tests never share /dev/shm/qmarc-sim.state), the commands
/// gathered for five minutes: the folder and the settings file.
fn scratch(name: &str) -> (PathBuf, PathBuf) {
    let dir = std::env::temp_dir().join(format!("qmarc-bridge-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let shipped = std::fs::read_to_string(workspace().join("config/qmarc.toml")).unwrap();
    let own: Vec<&str> = shipped
        .lines()
        .map(|l| match l.split(" = ").next() {
            Some("state_file") => "state_file = \"\"",
            // The commands, for five minutes: a loaded machine's session keeps its path.
            Some("fields") => "fields = [\"time\", \"cmd\"]",
            Some("stream_max_s") => "stream_max_s = 300.0",
            _ => l,
        })
        .collect();
    let config = dir.join("qmarc.toml");
    std::fs::write(&config, own.join("\n") + "\n").unwrap();
    (dir, config)
}

/// A bridge's Zenoh configuration: a peer listening on `LISTEN`, scouting nothing.
const PEER: &str = "{ mode: \"peer\", listen: { endpoints: [\"LISTEN\"] }, \
                    scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }";

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
        Cell::start_with(name, namespace, PEER)
    }

    /// A cell whose bridge has the Zenoh configuration `zenoh`, `LISTEN` in it replaced by a
    /// free endpoint on loopback (the cell's `endpoint`).
    fn start_with(name: &str, namespace: &str, zenoh_config: &str) -> Cell {
        Cell::start_session(name, namespace, zenoh_config, &["serve"])
    }

    /// [`Cell::start_with`] on the session the starter's `session` arguments start.
    fn start_session(name: &str, namespace: &str, zenoh_config: &str, session: &[&str]) -> Cell {
        let (dir, config) = scratch(name);
        let prefix = format!("qmarc_bridge{name}_{}_", std::process::id());
        let starter = bridge_bin().with_file_name("qmarc-starter");
        assert!(starter.is_file(), "{} missing: build the workspace", starter.display());
        let session = Command::new(&starter)
            .arg(format!("--config={}", config.display()))
            .arg(format!("--out={}", dir.join("out").display()))
            .arg(format!("--iox-prefix={prefix}"))
            .arg("--deterministic")
            .args(session)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let endpoint = format!("tcp/127.0.0.1:{}", free_port());
        let zenoh = dir.join("zenoh.json5");
        std::fs::write(&zenoh, zenoh_config.replace("LISTEN", &endpoint)).unwrap();
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
                Ok((c, s)) if s.robot.phase == qmarc_proto::state::Phase::Moving.wire() => {
                    return c;
                }
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

    /// Waits (30 s at most: a loaded machine delivers late) until the bridge has logged `text`.
    fn log_says(&self, text: &str) {
        let started = Instant::now();
        while !self.bridge_log().contains(text) {
            assert!(started.elapsed() < Duration::from_secs(30), "{text}: {}", self.bridge_log());
            std::thread::sleep(Duration::from_millis(50));
        }
    }

    /// Diagnostics messages until one satisfies `found` (60 s at most: the bridge forwards
    /// and the controller answers when a loaded machine lets them, and a client that heard
    /// none in its 5 s asks again — a CI run once had one hear nothing in 20 s under load);
    /// that one.
    fn diagnostics_until(&self, found: impl Fn(&serde_json::Value) -> bool) -> serde_json::Value {
        let started = Instant::now();
        loop {
            let out = self.ros2(&["diagnostics", "1", "--timeout=5"]);
            let text = String::from_utf8_lossy(&out.stdout).into_owned();
            let heard = text.lines().filter_map(|l| serde_json::from_str(l).ok());
            if let Some(d) = heard.into_iter().find(|d| found(d)) {
                return d;
            }
            assert!(
                started.elapsed() < Duration::from_secs(60),
                "no such diagnostics in 60 s; the last client: {:?} {text}\n{}\nbridge: {}",
                out.status,
                String::from_utf8_lossy(&out.stderr),
                self.bridge_log()
            );
        }
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

/// Waits until the controller has accepted an order after the `before`-th (the bridge
/// forwarded what a client published; 30 s at most), then until it is done: the status then.
/// A bare [`CommandClient::wait`] would return at once, on the orders before it.
fn wait_for_order_after(
    client: &mut CommandClient,
    before: u64,
) -> qmarc_session::wire::CommandResponse {
    let started = Instant::now();
    while client.send(CommandRequest::of(CommandKind::Status)).unwrap().orders.accepted <= before {
        assert!(started.elapsed() < Duration::from_secs(30), "no order reached the controller");
        std::thread::sleep(Duration::from_millis(10));
    }
    client.wait(Duration::from_secs(30)).unwrap()
}

/// Issue 44: a conveyor session's bridge says the parts queued, picked and missed in
/// `/diagnostics`, as the session counts them (never more than its status says later).
#[test]
fn a_conveyor_sessions_diagnostics_count_its_parts() {
    let session = ["conveyor", "--seconds=30", "--parts-per-min=90"];
    let mut cell = Cell::start_session("conveyor", "/belt", PEER, &session);
    let count = |d: &serde_json::Value, k: &str| -> u64 {
        d["values"][k].as_str().and_then(|v| v.parse().ok()).unwrap_or(0)
    };
    let d = cell.diagnostics_until(|d| count(d, "picked") >= 1);
    assert!(d["values"]["queued"].is_string() && d["values"]["missed"].is_string(), "{d}");
    assert_eq!(d["level"], 0, "{d}");
    let later = cell.client().send(CommandRequest::of(CommandKind::Status)).unwrap().conveyor;
    assert_eq!(later.active, 1);
    assert!(u64::from(later.picked) >= count(&d, "picked"), "{later:?} after {d}");
    assert!(u64::from(later.missed) >= count(&d, "missed"), "{later:?} after {d}");
    assert!(cell.quit().success());
}

/// Issue 42: the example client says what it can do, and a session it cannot open is said
/// in its JSON, not a traceback.
#[test]
fn the_example_client_lists_its_commands_and_says_a_missing_router() {
    let help = Command::new(python())
        .arg(workspace().join("examples/ros2_client.py"))
        .arg("--help")
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&help.stdout);
    assert!(help.status.success(), "{text}");
    for command in ["joint-states N", "target X Y Z", "follow JSON", "stop", "gripper on|off"] {
        assert!(text.contains(command), "{command} in {text}");
    }
    let nowhere = format!("--connect=tcp/127.0.0.1:{}", free_port());
    let out = Command::new(python())
        .arg(workspace().join("examples/ros2_client.py"))
        .args([nowhere.as_str(), "--mode=client", "stop"])
        .output()
        .unwrap();
    let said = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(
        said.starts_with("{\"error\": \"cannot open a Zenoh session with tcp/127.0.0.1:"),
        "{said}"
    );
    assert!(!String::from_utf8_lossy(&out.stderr).contains("Traceback"));
}

/// Whether process `pid` runs (a zombie, dead but not yet reaped, does not).
fn alive(pid: &str) -> bool {
    let stat = std::fs::read_to_string(format!("/proc/{}/stat", pid.trim())).unwrap_or_default();
    // The state follows the command's closing parenthesis.
    stat.rsplit_once(") ").is_some_and(|(_, rest)| !rest.starts_with('Z'))
}

/// A TCP port free on loopback now, where no client's outgoing connection can take it.
fn free_port() -> u16 {
    qmarc_program::net::free_loopback_port()
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
    assert_eq!(diag[0]["values"]["phase"], "serving", "{diag:?}");
    assert_eq!(diag[0]["values"]["homed"], "true");
    // The services.
    let r = cell.lines(&["gripper", "on"]);
    assert_eq!((r[0]["success"].as_bool(), r[0]["gid_echoed"].as_bool()), (Some(true), Some(true)));
    // Issue 42, item 7: each call from a session of its own, in peer mode, the first of its
    // session: every one answered (the client waits for the service's token, as rmw_zenoh's
    // clients wait for the server).
    let r = cell.lines(&["--repeat=20", "stop"]);
    assert_eq!(r.len(), 20, "{r:?}");
    assert!(r.iter().all(|c| c["success"] == true), "{r:?}");
    // A target the robot goes to.
    let mut client = cell.client();
    let before = client.send(CommandRequest::of(CommandKind::Status)).unwrap().orders.accepted;
    cell.lines(&["target", "0.02", "-0.01", "-0.64"]);
    let s = wait_for_order_after(&mut client, before);
    let [x, y, z] = s.robot.effector_mm;
    assert!(close(x, 20.0, 1e-6) && close(y, -10.0, 1e-6) && close(z, -640.0, 1e-6), "{x} {y} {z}");
    // An unreachable one: the controller refuses it, the bridge says why.
    let before = client.send(CommandRequest::of(CommandKind::Status)).unwrap().orders.accepted;
    cell.lines(&["target", "0", "0", "-0.2"]);
    cell.diagnostics_until(|d| d["values"]["refused"].as_str().unwrap().contains("unreachable"));
    // Issue 42: a coordinate typed as a negative number is one (not an option), and an
    // absurd one is refused by the bridge, said in the diagnostics.
    cell.lines(&["target", "0", "0", "-1e9"]);
    cell.diagnostics_until(|d| {
        d["values"]["refused"].as_str().unwrap().contains("numbers within ±10 m")
    });
    // Garbage and an oversized payload: not taken, nothing sent on.
    cell.lines(&["raw-target", "3"]);
    cell.lines(&["raw-target", "2000000"]);
    cell.log_says("qmarc/target: not taken: not a geometry_msgs/msg/PointStamped");
    cell.log_says("more than the 1048576 taken");
    let after = client.send(CommandRequest::of(CommandKind::Status)).unwrap();
    assert_eq!(after.orders.accepted, before, "nothing reached the controller");

    // kill -9 of the bridge mid-move: the move goes on to its end.
    let r = client.send(CommandRequest::move_xyz([-30.0, 20.0, -650.0], false, 0.2)).unwrap();
    assert_eq!(r.answer.ok, 1);
    let bridge = cell.bridge.as_mut().unwrap();
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(bridge.id() as i32),
        nix::sys::signal::Signal::SIGKILL,
    )
    .unwrap();
    bridge.wait().unwrap();
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert_eq!(
        (s.robot.fault, s.orders.settled, s.orders.moving),
        (0, r.orders.accepted, 0),
        "the move ended as sent"
    );
    let [x, y, z] = s.robot.effector_mm;
    assert!(close(x, -30.0, 1e-6) && close(y, 20.0, 1e-6) && close(z, -650.0, 1e-6));
    drop(client);
    assert!(cell.quit().success());
}

/// `qmarc/joint_trajectory`: the robot follows a joint trajectory through its knots (its
/// joints out of order), as gather.csv shows; one with a wrong joint is not taken, one too
/// fast is refused, both said.
#[test]
fn a_joint_trajectory_is_followed_through_its_knots() {
    let mut cell = Cell::start("traj", "/robot1");
    let mut client = cell.client();
    let rest = client.send(CommandRequest::of(CommandKind::Status)).unwrap().robot.command;
    let knots = joint_trajectories(&cell, &mut client, rest);
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
    let before = client.send(CommandRequest::of(CommandKind::Status)).unwrap().orders.accepted;
    cell.lines(&["trajectory", &spec.to_string()]);
    let s = wait_for_order_after(client, before);
    assert_eq!(
        (s.orders.accepted, s.orders.settled, s.robot.fault),
        (before + 1, before + 1, 0),
        "{}",
        cell.bridge_log()
    );
    let counts = knots.map(|k| k.map(|r| r * per_rad));
    for m in 0..3 {
        assert!(
            close(s.robot.command[m], counts[1][m], 1e-6),
            "{:?} {:?}",
            s.robot.command,
            counts[1]
        );
    }
    // Not motor1…motor3: not taken. Too fast for the motors: the controller says why.
    let wrong = serde_json::json!({"names": ["motor1", "motor2", "elbow"], "points": [{"t": 1.0, "positions": [0.0, 0.0, 0.0]}]});
    cell.lines(&["trajectory", &wrong.to_string()]);
    let fast = serde_json::json!({"names": ["motor1", "motor2", "motor3"], "points": [{"t": 0.01, "positions": [1.0, 0.0, 0.0]}]});
    cell.lines(&["trajectory", &fast.to_string()]);
    cell.log_says("qmarc/joint_trajectory: not taken: joint_names must be motor1, motor2, motor3");
    cell.diagnostics_until(|d| {
        d["values"]["refused"].as_str().unwrap().contains("max_velocity_counts_per_s")
    });
    assert_eq!(
        client.send(CommandRequest::of(CommandKind::Status)).unwrap().orders.accepted,
        before + 1
    );
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

/// MoveIt's action, `qmarc/follow_joint_trajectory`: a goal followed to its end with feedback
/// and a successful result; a path tolerance the robot breaks aborts it with the robot
/// stopped; a goal tolerance it cannot meet in time aborts it once the path ends; a cancel
/// stops it; a goal with joints the robot has not is rejected.
#[test]
fn the_follow_joint_trajectory_action_reports_tolerance_violations() {
    let mut cell = Cell::start("fjt", "");
    let mut client = cell.client();
    let per_rad = settings().counts_per_rad();
    let rest = client.send(CommandRequest::of(CommandKind::Status)).unwrap().robot.command;
    let rad = |m: usize, by_counts: f64| (rest[m] + by_counts) / per_rad;
    let goal = |by: [f64; 3], t: f64, extra: serde_json::Value| {
        let mut spec = serde_json::json!({
            "names": ["motor1", "motor2", "motor3"],
            "points": [{"t": t, "positions": [rad(0, by[0]), rad(1, by[1]), rad(2, by[2])]}],
        });
        spec.as_object_mut().unwrap().extend(extra.as_object().unwrap().clone());
        let out = cell.lines(&["follow", &spec.to_string()]);
        out[0].clone()
    };
    let ok = goal(
        [400.0, -300.0, 200.0],
        0.4,
        serde_json::json!({"goal_tolerance": {"motor1": {"position": 0.01, "velocity": 0.05}}, "goal_time": 1.0}),
    );
    assert_eq!(
        (ok["accepted"].as_bool(), ok["status"].as_i64(), ok["error_code"].as_i64()),
        (Some(true), Some(4), Some(0)),
        "{ok}\n{}",
        cell.bridge_log()
    );
    assert!(ok["feedback"].as_i64().unwrap() >= 1, "{ok}");
    assert_eq!(ok["joint_names"], serde_json::json!(["motor1", "motor2", "motor3"]));
    assert!(ok["max_error"].as_f64().unwrap() < 0.05, "{ok}");
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert!(close(s.robot.command[0], rest[0] + 400.0, 1e-6), "{:?}", s.robot.command);
    // The gripper closed on the way is no other motion: the goal goes on to its end.
    let gripped = goal([800.0, -300.0, 200.0], 2.0, serde_json::json!({"grip_after": 0.3}));
    assert_eq!(
        (gripped["grip_success"].as_bool(), gripped["status"].as_i64()),
        (Some(true), Some(4)),
        "{gripped}"
    );
    // Feedback along its 2 s (50 a second at most; a loaded machine's bridge turns late).
    assert!(gripped["feedback"].as_i64().unwrap() >= 2, "{gripped}");
    // A path tolerance no servo meets: aborted, the robot stopped, the session unharmed.
    let tight = goal([0.0, 0.0, 0.0], 0.5, serde_json::json!({"path_tolerance": {"motor1": 1e-7}}));
    assert_eq!(
        (tight["status"].as_i64(), tight["error_code"].as_i64()),
        (Some(6), Some(-4)),
        "{tight}"
    );
    assert!(
        tight["error_string"]
            .as_str()
            .unwrap()
            .starts_with("path tolerance violated: motor1's position is"),
        "{tight}"
    );
    // A velocity no servo keeps to a millionth of a radian a second: aborted the same way.
    let tolerance = serde_json::json!({"motor2": {"position": 1.0, "velocity": 1e-6}});
    let tight = goal([0.0, 300.0, 0.0], 0.5, serde_json::json!({ "path_tolerance": tolerance }));
    assert_eq!(
        (tight["status"].as_i64(), tight["error_code"].as_i64()),
        (Some(6), Some(-4)),
        "{tight}"
    );
    assert!(
        tight["error_string"]
            .as_str()
            .unwrap()
            .starts_with("path tolerance violated: motor2's velocity is"),
        "{tight}"
    );
    client.wait(Duration::from_secs(30)).unwrap();
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert_eq!((s.robot.fault, s.orders.moving), (0, 0));
    assert!(
        s.orders.accepted > 2 && s.orders.settled == s.orders.accepted,
        "the stop was the last order, done"
    );
    // Half a count from the goal, which a motor at whole counts never is.
    let rest = s.robot.command;
    let rad = |m: usize, by_counts: f64| (rest[m] + by_counts) / per_rad;
    let spec = serde_json::json!({
        "names": ["motor1", "motor2", "motor3"],
        "points": [{"t": 0.3, "positions": [rad(0, 0.0), rad(1, 200.5), rad(2, 0.0)]}],
        "goal_tolerance": {"motor2": 1e-9}, "goal_time": 0.2,
    });
    let late = cell.lines(&["follow", &spec.to_string()])[0].clone();
    assert_eq!(
        (late["status"].as_i64(), late["error_code"].as_i64()),
        (Some(6), Some(-5)),
        "{late}"
    );
    assert!(
        late["error_string"].as_str().unwrap().contains("goal tolerance violated: motor2"),
        "{late}"
    );
    // Canceled mid-way (10 s of margin for a loaded machine): the robot stops short of the end.
    let spec = serde_json::json!({
        "names": ["motor1", "motor2", "motor3"],
        "points": [{"t": 10.0, "positions": [rad(0, 3000.0), rad(1, 0.0), rad(2, 0.0)]}],
        "cancel_after": 0.5,
    });
    let canceled = cell.lines(&["follow", &spec.to_string()])[0].clone();
    assert_eq!(
        (canceled["cancel_return_code"].as_i64(), canceled["status"].as_i64()),
        (Some(0), Some(5)),
        "{canceled}"
    );
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert!(s.robot.command[0] < rest[0] + 2900.0, "stopped short: {:?}", s.robot.command);
    let wrong = serde_json::json!({"names": ["motor1", "motor2", "wrist"], "points": [{"t": 1.0, "positions": [0.0, 0.0, 0.0]}]});
    let rejected = cell.lines(&["follow", &wrong.to_string()])[0].clone();
    assert_eq!(rejected["accepted"], false);
    cell.log_says("follow_joint_trajectory: not taken: joint_names must be");
    // A client that joins now hears the goals' last status at once, from the status topic's
    // cache (transient local: it is published on changes only, and nothing changes now).
    let late = cell.lines(&["goal-status", "1"]);
    assert_eq!(late[0]["status"], serde_json::json!([4, 4, 6, 6, 6, 5]), "{late:?}");
    drop(client);
    assert!(cell.quit().success());
}

/// A bridge that finds no router keeps retrying and still serves its own peers; SIGSTOP of it
/// mid-move changes nothing in the move, and after SIGCONT it goes on where the robot is.
#[test]
fn a_stopped_or_routerless_bridge_changes_nothing_in_a_move() {
    let nowhere = format!("tcp/127.0.0.1:{}", free_port());
    let lonely = format!(
        "{{ mode: \"peer\", connect: {{ endpoints: [\"{nowhere}\"] }}, \
         listen: {{ endpoints: [\"LISTEN\"] }}, \
         scouting: {{ multicast: {{ enabled: false }}, gossip: {{ enabled: false }} }} }}"
    );
    let mut cell = Cell::start_with("stop", "", &lonely);
    let js = cell.lines(&["joint-states", "3"]);
    assert_eq!(js.len(), 3, "served with no router");
    let mut client = cell.client();
    let r = client.send(CommandRequest::move_xyz([25.0, 15.0, -655.0], false, 0.2)).unwrap();
    assert_eq!(r.answer.ok, 1, "{}", r.reason());
    let pid = nix::unistd::Pid::from_raw(cell.bridge.as_ref().unwrap().id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGSTOP).unwrap();
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert_eq!(
        (s.robot.fault, s.orders.settled, s.orders.moving),
        (0, r.orders.accepted, 0),
        "the move ended as sent"
    );
    let [x, y, z] = s.robot.effector_mm;
    assert!(close(x, 25.0, 1e-6) && close(y, 15.0, 1e-6) && close(z, -655.0, 1e-6));
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGCONT).unwrap();
    let fx = cell.lines(&["effector", "1"]);
    let p = fx[0]["point"].as_array().unwrap();
    assert!(close(p[0].as_f64().unwrap(), 0.025, 1e-4), "where the robot is now: {fx:?}");
    assert!(cell.bridge.as_mut().unwrap().try_wait().unwrap().is_none(), "still running");
    drop(client);
    assert!(cell.quit().success());
}

/// kill -9 of the hwserver, the controller or the starter while the bridge serves: the
/// session ends with the motors disabled (a killed starter's children stop on the signal its
/// death sends them), `/diagnostics` says the fault, and the bridge ends by itself.
#[test]
fn a_robot_process_killed_is_said_in_the_diagnostics_and_ends_the_bridge() {
    // Each death and the fault it is said as.
    let deaths = [
        ("qmarc-hwserver", "hwserver_lost"),
        ("qmarc-controller", "controller_lost"),
        ("qmarc-starter", "aborted"),
    ];
    for (victim, words) in deaths {
        let mut cell = Cell::start(&format!("kill{}", victim.len()), "");
        cell.lines(&["joint-states", "1"]);
        // A listener, its lines as they come: subscribed once it has said the first (once a
        // second). One that hears nothing in 30 s (a CI run on a loaded machine had one hear
        // nothing in 60 s) is replaced, three times at most.
        let listen = || {
            let mut listener = Command::new(python())
                .arg(workspace().join("examples/ros2_client.py"))
                .arg(format!("--connect={}", cell.endpoint))
                .args(["--timeout=120", "diagnostics", "1000"])
                .stdout(Stdio::piped())
                .stderr(Stdio::null())
                .spawn()
                .unwrap();
            let (heard, said) = std::sync::mpsc::channel();
            let stdout = listener.stdout.take().unwrap();
            std::thread::spawn(move || {
                use std::io::BufRead;
                for line in std::io::BufReader::new(stdout).lines().map_while(Result::ok) {
                    let _ = heard.send(line);
                }
            });
            (listener, said)
        };
        let (mut listener, mut said) = listen();
        let mut attempts = 1;
        let first = loop {
            match said.recv_timeout(Duration::from_secs(30)) {
                Ok(line) => break line,
                Err(e) => {
                    assert!(attempts < 3, "no listener heard the diagnostics: {e:?}");
                    let _ = listener.kill();
                    let _ = listener.wait();
                    (listener, said) = listen();
                    attempts += 1;
                }
            }
        };
        let starter = cell.session.as_ref().unwrap().id();
        let pid: i32 = if victim == "qmarc-starter" {
            starter as i32
        } else {
            let pgrep =
                Command::new("pgrep").args(["-P", &starter.to_string(), "-f", victim]).output();
            String::from_utf8_lossy(&pgrep.unwrap().stdout).trim().parse().unwrap()
        };
        let pgrep = Command::new("pgrep").args(["-P", &starter.to_string()]).output();
        let orphans = String::from_utf8_lossy(&pgrep.unwrap().stdout).into_owned();
        nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), nix::sys::signal::Signal::SIGKILL)
            .unwrap();
        let ended = cell.session.take().unwrap().wait().unwrap();
        if victim == "qmarc-starter" {
            assert_eq!(ended.code(), None, "killed");
            // Its children, reparented, stop by themselves.
            let started = Instant::now();
            while orphans.lines().any(alive) {
                assert!(started.elapsed() < Duration::from_secs(30), "children left: {orphans}");
                std::thread::sleep(Duration::from_millis(50));
            }
        } else {
            assert_eq!(ended.code(), Some(2), "{victim}: the session ends with a fault");
        }
        let bridge = cell.bridge.as_mut().unwrap().wait().unwrap();
        assert!(bridge.success(), "{victim}: the bridge ends by itself: {}", cell.bridge_log());
        // What it heard after the kill, until it has been quiet for a while (it would hear
        // nothing more: the bridge is gone).
        let mut lines = vec![first];
        while let Ok(line) = said.recv_timeout(Duration::from_secs(5)) {
            lines.push(line);
        }
        let _ = listener.kill();
        let _ = listener.wait();
        let said: Vec<serde_json::Value> =
            lines.iter().filter_map(|l| serde_json::from_str(l).ok()).collect();
        let fault = said.iter().find(|d| d["level"] == 2);
        let fault = fault.unwrap_or_else(|| panic!("{victim}: no fault said: {said:?}"));
        assert!(fault["values"]["fault"].as_str().unwrap().starts_with(words), "{fault}");
    }
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
    let r = client.send(CommandRequest::move_to(&[500.0, -500.0, 250.0], 1.0)).unwrap();
    assert_eq!(r.answer.ok, 1, "still serving: {}", r.reason());
    let s = client.wait(Duration::from_secs(30)).unwrap();
    assert_eq!((s.robot.fault, s.robot.command[..3].to_vec()), (0, vec![500.0, -500.0, 250.0]));
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

/// Two robots on one PC, bridged under /robot1 and /robot2; the first bridge is the cell's
/// Zenoh router, reachable from a second host (a network namespace); a ROS 2 client there
/// sees both robots' joint states and commands each, and each command reaches its robot only.
#[test]
fn two_robots_are_seen_and_commanded_from_another_host_through_a_router() {
    let host = qmarc_program::net::Netns::new().expect("the two-host cell's second host");
    let router_port = free_port();
    let lan = format!("tcp/{}:{router_port}", host.here);
    let router = format!(
        "{{ mode: \"router\", listen: {{ endpoints: [\"LISTEN\", \"{lan}\"] }}, \
         scouting: {{ multicast: {{ enabled: false }} }} }}"
    );
    let mut robot1 = Cell::start_with("cell1", "/robot1", &router);
    let peer = format!(
        "{{ mode: \"peer\", connect: {{ endpoints: [\"{}\"] }}, listen: {{ endpoints: [\"LISTEN\"] }}, \
         scouting: {{ multicast: {{ enabled: false }} }} }}",
        robot1.endpoint
    );
    let mut robot2 = Cell::start_with("cell2", "/robot2", &peer);
    // The client on the other host, connected to the router only.
    let remote = |namespace: &str, args: &[&str]| -> Vec<serde_json::Value> {
        let out = host
            .command(&python())
            .arg(workspace().join("examples/ros2_client.py"))
            .args([
                "--mode=client",
                &format!("--connect={lan}"),
                &format!("--namespace={namespace}"),
            ])
            .args(args)
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(
            out.status.success(),
            "{namespace} {args:?}: {text}\n{}\nbridge 1: {}\nbridge 2: {}",
            String::from_utf8_lossy(&out.stderr),
            robot1.bridge_log(),
            robot2.bridge_log()
        );
        text.lines().map(|l| serde_json::from_str(l).unwrap()).collect()
    };
    for ns in ["/robot1", "/robot2"] {
        let js = remote(ns, &["joint-states", "5"]);
        assert_eq!(js.len(), 5, "{ns}");
        assert_eq!(js[0]["name"], serde_json::json!(["motor1", "motor2", "motor3"]));
    }
    // A target to robot 2 moves robot 2 only; robot 1's gripper service answers robot 1.
    let mut c1 = robot1.client();
    let mut c2 = robot2.client();
    let before = c1.send(CommandRequest::of(CommandKind::Status)).unwrap();
    remote("/robot2", &["target", "0.02", "-0.01", "-0.64"]);
    let s = c2.wait(Duration::from_secs(30)).unwrap();
    assert!(
        close(s.robot.effector_mm[0], 20.0, 1e-6) && close(s.robot.effector_mm[2], -640.0, 1e-6),
        "{s:?}"
    );
    let r = remote("/robot1", &["gripper", "on"]);
    assert_eq!(r[0]["success"], true, "{r:?}");
    let after = c1.send(CommandRequest::of(CommandKind::Status)).unwrap();
    assert_eq!(
        (after.robot.command, after.orders.accepted),
        (before.robot.command, before.orders.accepted + 1),
        "robot 1 gripped, unmoved"
    );
    drop((c1, c2));
    assert!(robot2.quit().success());
    assert!(robot1.quit().success());
}

/// A `qmarc-starter serve --bridge ARGS` session of scratch folder `dir` with settings
/// `config` under iceoryx2 prefix `prefix`; its standard error's lines as they come.
fn serve_bridged(
    dir: &Path,
    config: &Path,
    prefix: &str,
    args: &[&str],
) -> (Child, std::sync::mpsc::Receiver<String>) {
    let mut session = Command::new(bridge_bin().with_file_name("qmarc-starter"))
        .arg(format!("--config={}", config.display()))
        .arg(format!("--out={}", dir.join(prefix).display()))
        .arg(format!("--iox-prefix={prefix}"))
        .args(["--deterministic", "serve", "--bridge"])
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let (said, lines) = std::sync::mpsc::channel();
    let stderr = session.stderr.take().unwrap();
    std::thread::spawn(move || {
        use std::io::BufRead;
        for line in std::io::BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = said.send(line);
        }
    });
    (session, lines)
}

/// Serving sessions a test started (child, iceoryx2 prefix): killed and their files removed
/// on drop, should the test fail before it quits them.
struct Sessions(Vec<(Child, String)>);

impl Drop for Sessions {
    fn drop(&mut self) {
        for (child, prefix) in &mut self.0 {
            let _ = child.kill();
            let _ = child.wait();
            IpcLocation::new(prefix, DEFAULT_ROOT).remove_files();
        }
    }
}

/// Waits (60 s at most) for a line of `lines` containing `text`; the lines until it.
fn said(lines: &std::sync::mpsc::Receiver<String>, text: &str) -> String {
    let deadline = Instant::now() + Duration::from_secs(60);
    let mut all = String::new();
    loop {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok(line) => {
                all.push_str(&line);
                all.push('\n');
                if line.contains(text) {
                    return all;
                }
            }
            Err(_) => panic!("no line saying {text:?} in:\n{all}"),
        }
    }
}

/// Issue 42, item 3: a second bridge of the same node name in the same domain refuses to
/// start, naming the first (two would be one ROS node: joint states interleaved, a target
/// reaching both robots); its session goes on without it. `serve --bridge` forwards
/// `--namespace`, `--domain` and `--zenoh-config`: under another namespace it serves.
#[test]
fn a_second_bridge_of_one_node_name_is_refused_and_its_session_goes_on() {
    let (dir, config) = scratch("twins");
    // Its sessions' paths are not looked at: ten seconds of them, not five minutes (the
    // first session lives through the whole test, and a loaded machine took over the
    // starter's two minutes to write five minutes of a debug build's rows at its end).
    let text = std::fs::read_to_string(&config).unwrap();
    assert!(text.contains("stream_max_s = 300.0"), "{text}");
    std::fs::write(&config, text.replace("stream_max_s = 300.0", "stream_max_s = 10.0")).unwrap();
    let router = format!("tcp/127.0.0.1:{}", free_port());
    let files = |name: &str, text: String| {
        let f = dir.join(name);
        std::fs::write(&f, text).unwrap();
        f.display().to_string()
    };
    let quiet = "scouting: { multicast: { enabled: false }, gossip: { enabled: false } }";
    let as_router = files(
        "router.json5",
        format!("{{ mode: \"router\", listen: {{ endpoints: [\"{router}\"] }}, {quiet} }}"),
    );
    let as_peer = files(
        "peer.json5",
        format!("{{ mode: \"peer\", connect: {{ endpoints: [\"{router}\"] }}, {quiet} }}"),
    );
    let pid = std::process::id();
    let prefixes = [format!("qbtwa{pid}_"), format!("qbtwb{pid}_"), format!("qbtwc{pid}_")];
    let mut sessions = Sessions(Vec::new());
    let mut start = |k: usize, args: &[&str]| {
        let (child, lines) = serve_bridged(&dir, &config, &prefixes[k], args);
        sessions.0.push((child, prefixes[k].clone()));
        lines
    };
    let first = start(0, &[&format!("--zenoh-config={as_router}")]);
    said(&first, "as ROS 2 node /qmarc, domain 0");
    // The same name, the same domain: refused, naming the first; the session serves on.
    let second = start(1, &[&format!("--zenoh-config={as_peer}")]);
    let words = said(&second, "qmarc-bridge exited with code 3 (refused); the session goes on");
    assert!(
        words.contains(
            "qmarc-bridge: error: a ROS node /qmarc is already alive in domain 0 (its liveliness \
             token @ros2_lv/0/"
        ),
        "{words}"
    );
    let mut client = CommandClient::connect(&IpcLocation::new(&prefixes[1], DEFAULT_ROOT)).unwrap();
    let s = client.send(CommandRequest::of(CommandKind::Status)).unwrap();
    assert_eq!(s.answer.refusal, 0, "the second session serves: {}", s.reason());
    drop(client);
    // Another namespace (forwarded by serve --bridge): a node of its own.
    let third =
        start(2, &[&format!("--zenoh-config={as_peer}"), "--namespace=/robot2", "--domain=0"]);
    said(&third, "as ROS 2 node /robot2/qmarc, domain 0");
    let js = Command::new(python())
        .arg(workspace().join("examples/ros2_client.py"))
        .args([&format!("--connect={router}"), "--mode=client", "--namespace=/robot2"])
        .args(["joint-states", "3"])
        .output()
        .unwrap();
    assert!(js.status.success(), "{}", String::from_utf8_lossy(&js.stderr));
    assert_eq!(String::from_utf8_lossy(&js.stdout).lines().count(), 3);
    // Each quit in turn; those not yet quit stay in the guard.
    for lines in [first, second, third] {
        let (mut session, prefix) = sessions.0.remove(0);
        let location = IpcLocation::new(&prefix, DEFAULT_ROOT);
        let _ = CommandClient::connect(&location)
            .and_then(|mut c| c.send(CommandRequest::of(CommandKind::Quit)));
        let status = session.wait().unwrap();
        let rest: String = lines.try_iter().map(|l| l + "\n").collect();
        location.remove_files();
        assert!(status.success(), "{prefix}: {status}\n{rest}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}
