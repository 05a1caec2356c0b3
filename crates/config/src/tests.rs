//! Unit tests of the settings: exact error messages, defaults, overrides, and the round trip
//! of the value handed to the children.

use super::*;
use std::path::Path;

/// The names the tests accept (the registries' at the time of writing).
fn names() -> Names {
    Names { laws: vec!["pidff"], methods: vec!["step", "spline", "pvt"], any_plugin: false }
}

fn shipped_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml")
}

fn shipped() -> Settings {
    Settings::load(&shipped_path(), &names()).unwrap()
}

const MOTOR: &str = "[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n";

fn parse(text: &str) -> Result<Settings, ConfigLoadError> {
    Settings::parse(Path::new("q.toml"), text, &names())
}

fn check(text: &str, expected: &str) {
    match parse(text) {
        Ok(_) => panic!("accepted:\n{text}"),
        Err(e) => assert_eq!(e.to_string(), expected),
    }
}

#[test]
fn shipped_settings_are_the_thesis_defaults() {
    let s = shipped();
    assert_eq!((s.n_motors, s.period_us, s.law.as_str()), (3, 400, "pidff"));
    let table_5_1 = [(182_000.0, 119_000.0), (182_000.0, 103_500.0), (183_000.0, 104_000.0)];
    for (m, (kp, kvff)) in s.motors.iter().zip(table_5_1) {
        assert_eq!((m.kp, m.ki, m.kd, m.kvff, m.kaff), (kp, 100.0, 3_000.0, kvff, 100.0));
        assert_eq!(m.notch, [0.0; 4]);
    }
    assert!((s.counts_per_rad() - 7_822.78).abs() < 0.01, "{}", s.counts_per_rad());
    assert_eq!(s.timer.method, TimerMethod::Timerfd);
}

#[test]
fn minimal_file_takes_defaults() {
    let s = parse(&MOTOR.repeat(3)).unwrap();
    assert_eq!((s.n_motors, s.period_us, s.gather.every, s.step.size), (3, 400, 1, 1000));
    assert_eq!(s.hwserver.watchdog_periods, 250, "the simulated robot's default");
}

#[test]
fn errors_name_file_line_column_and_field() {
    check(
        "[general]\nperiod_us = 50\n",
        "q.toml:2:13: general.period_us: servo period must be 100‥100000 µs, found 50",
    );
    check("[general]\nn_motors = 5\n", "q.toml:2:12: general.n_motors: must be 1‥4, found 5");
    check(
        "[general]\nn_motors = 2\n[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n",
        "q.toml:2:12: general.n_motors: 2 motors need 2 [[motor]] tables, found 1",
    );
    check(
        &format!("{MOTOR}{MOTOR}[[motor]]\nkp = 1.0\nkpp = 2\n"),
        "q.toml:15:1: motor[3].kpp: unknown field `kpp`, expected one of `kp`, `ki`, `kd`, `kvff`, `kaff`, `kjff`, `notch`, `soft_limits`, `max_following_error_counts`, `max_integrated_error_counts`, `home_offset_counts`, `top_direction`, `max_velocity_counts_per_s`, `max_acceleration_counts_per_s2`, `max_jerk_counts_per_s3`",
    );
    check(
        &format!("{MOTOR}{MOTOR}[[motor]]\nkp = \"big\"\n"),
        "q.toml:14:6: motor[3].kp: invalid type: string \"big\", expected f64",
    );
    check(
        &format!("{MOTOR}[[motor]]\nkp = 1.0\n{MOTOR}"),
        "q.toml:7:1: motor[2].ki: missing key `ki`",
    );
    check(
        &format!(
            "{}[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\nnotch = [0, 0, -2.5, 0.9]\n",
            MOTOR.repeat(2)
        ),
        "q.toml:19:9: motor[3].notch: the denominator 1 + d1·z⁻¹ + d2·z⁻² with d1 = -2.5, d2 = 0.9 is unstable (needs |d2| < 1 and |d1| < 1 + d2)",
    );
    check(
        "[general]\nlaw = \"lqr\"\n",
        "q.toml:2:7: general.law: unknown servo law `lqr`; registered: pidff",
    );
    check(
        "[timer]\nmethod = \"posix\"\n",
        "q.toml:2:10: timer.method: must be \"timerfd\", \"nanosleep\" or \"timerfd-periodic\", found \"posix\"",
    );
    check(
        "[bogus]\nx = 1\n",
        "q.toml:1:2: bogus: unknown field `bogus`, expected one of `general`, `timer`, `gather`, `step`, `jog`, `pick`, `check`, `trajectory`, `homing`, `safety`, `hwserver`, `sim`, `s626`, `tune`, `telemetry`, `conveyor`, `camera`, `cell`, `robot`, `motor`",
    );
    check(
        "[trajectory]\nmethod = \"home\"\n",
        "q.toml:2:10: trajectory.method: unknown trajectory method `home`; registered: step, spline, pvt",
    );
    check(
        "[general]\nperiod_us = \n",
        "q.toml:2:13: general.period_us: string values must be quoted, expected literal string",
    );
    check(
        "[step]\nduration_s = nan\n",
        "q.toml:2:14: step.duration_s: duration must be > 0 and ≤ 86400 s (trajectory.max_duration_s), found NaN",
    );
    check(
        "[timer]\nservo_priority = 90\nhwserver_priority = 80\n",
        "q.toml:3:21: timer.hwserver_priority: must be at least timer.servo_priority (90): the servo thread waits on the hwserver, so the hwserver must not be preempted by it",
    );
}

/// Issue 10, item 1: every number that becomes a duration or a count is bounded, so none
/// can overflow or panic downstream (`stream_wait_s = 1e20` panicked in `Duration`).
#[test]
fn durations_and_counts_are_bounded() {
    let one = format!("[general]\nn_motors = 1\n{MOTOR}");
    let check = |text: &str, expected: &str| check(&format!("{text}{one}"), expected);
    check(
        "[trajectory]\nstream_wait_s = 1e20\n",
        "q.toml:2:17: trajectory.stream_wait_s: must be > 0 and ≤ 3600 s, found 1e20",
    );
    check(
        "[homing]\ncreep_counts_per_s = 1e-300\n",
        "q.toml:2:22: homing.creep_counts_per_s: must be 1‥10000000 counts/s, found 1e-300",
    );
    check(
        "[homing]\nmax_travel_counts = 1e12\n",
        "q.toml:2:21: homing.max_travel_counts: must be 1‥8388608 counts, found 1e12",
    );
    check(
        &format!("{MOTOR}home_offset_counts = 1e9\n"),
        "q.toml:7:22: motor[1].home_offset_counts: must be 0‥8388608 counts, found 1e9",
    );
    check(
        "[trajectory]\nmax_duration_s = 10\n[homing]\nvelocity_counts_per_s = 1000\n",
        "q.toml:4:25: homing.velocity_counts_per_s: homing could take 70 s, longer than the longest move (trajectory.max_duration_s = 10 s): raise the homing speeds or lower max_travel_counts",
    );
}

#[test]
fn overrides_are_checked() {
    let mut s = parse(&MOTOR.repeat(3)).unwrap();
    assert_eq!(
        s.set_period_us(99).unwrap_err().to_string(),
        "--period-us: servo period must be 100‥100000 µs, found 99"
    );
    assert_eq!(
        s.set_gather_every(0).unwrap_err().to_string(),
        "--gather-every: must be at least 1"
    );
    assert_eq!(
        s.set_step_duration(-1.0).unwrap_err().to_string(),
        "--duration: duration must be > 0 and ≤ 86400 s (trajectory.max_duration_s), found -1"
    );
    s.set_period_us(1000).unwrap();
    s.set_step_size(-500).unwrap();
    assert_eq!((s.period_us, s.step.size), (1000, -500));
}

#[test]
fn missing_file_is_named() {
    let e = Settings::load(Path::new("/nonexistent/q.toml"), &names()).unwrap_err().to_string();
    assert!(e.starts_with("/nonexistent/q.toml: cannot read the settings file: "), "{e}");
}

/// Issue 11: a value whose text spans lines is named by its key, at the element at fault.
#[test]
fn errors_in_values_that_span_lines_name_their_key() {
    check(
        &format!(
            "{}[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\nnotch = [\n  0,\n  \"x\",\n  0,\n  0,\n]\n",
            MOTOR.repeat(2)
        ),
        "q.toml:21:3: motor[3].notch: invalid type: string \"x\", expected f64",
    );
    check(
        "[sim]\nstart_counts = [\n  0,\n  true,\n]\n",
        "q.toml:4:3: sim.start_counts: invalid type: boolean `true`, expected f64",
    );
}

/// Issue 11: every field of the settings survives the trip to the children: each number
/// and flag of the serialized value is changed to a value of its own, and what the child
/// reads back serializes to exactly that.
#[test]
fn every_field_round_trips_to_the_children() {
    let spec = RunSpec {
        settings: shipped(),
        mode: Mode::Run,
        deterministic: true,
        unpaced: false,
        unhomed: false,
        iox_prefix: "qmarc_7_".into(),
        iox_root: "/tmp/iceoryx2/".into(),
        epoch_ns: 0,
    };
    let mut json: serde_json::Value = serde_json::from_str(&spec.to_json()).unwrap();
    let mut n = 0u32;
    fn vary(v: &mut serde_json::Value, n: &mut u32) {
        match v {
            serde_json::Value::Number(x) => {
                *n += 1;
                *v = if x.is_f64() {
                    serde_json::json!(f64::from(*n) + 0.25)
                } else {
                    serde_json::json!(*n)
                };
            }
            serde_json::Value::Bool(b) => *b = !*b,
            // Enums: another of their values.
            serde_json::Value::String(s) if s == "block" => *s = "spin".into(),
            serde_json::Value::String(s) if s == "abs" => *s = "sse".into(),
            serde_json::Value::String(s) if s == "sim" => *s = "s626".into(),
            serde_json::Value::String(s) if crate::TuneParam::named(s).is_some() => {
                let i = crate::TUNE_PARAMS.iter().position(|p| p == s).unwrap_or(0);
                *s = crate::TUNE_PARAMS[(i + 1) % crate::TUNE_PARAMS.len()].into();
            }
            serde_json::Value::String(s) if !matches!(s.as_str(), "timerfd" | "run") => {
                *n += 1;
                s.push_str(&n.to_string());
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(|x| vary(x, n)),
            serde_json::Value::Object(o) => o.values_mut().for_each(|x| vary(x, n)),
            _ => {}
        }
    }
    vary(&mut json, &mut n);
    assert!(n > 60, "every field was varied: {n}");
    let dir = std::env::temp_dir().join(format!("qmarc-runspec-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("run.json");
    std::fs::write(&file, json.to_string()).unwrap();
    let back = RunSpec::read(&file).unwrap();
    let again: serde_json::Value = serde_json::from_str(&back.to_json()).unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert_eq!(again, json, "a field was lost or changed on the way");
    // And the shipped settings themselves, unchanged.
    let file = std::env::temp_dir().join(format!("qmarc-runspec-{}.json", std::process::id()));
    spec.write(&file).unwrap();
    assert_eq!(RunSpec::read(&file).unwrap(), spec);
    let _ = std::fs::remove_file(&file);
    let e = RunSpec::read(Path::new("/nonexistent/run.json")).unwrap_err().to_string();
    assert!(e.starts_with("/nonexistent/run.json: "), "{e}");
}

/// Issue 11: each default is defined once, and the shipped file states it: for every section
/// but the per-motor tables, the knot file and the start positions (the shipped choices),
/// the shipped values are the defaults. (Homing's velocity was 1000 counts/s in the code and
/// 2000 in the file.)
#[test]
fn the_shipped_file_states_the_defaults() {
    let s = shipped();
    let tables = std::fs::read_to_string(shipped_path()).unwrap();
    let motors = &tables[tables.find("\n[[motor]]").unwrap()..];
    let d = parse(motors).unwrap();
    assert_eq!(s.homing, d.homing);
    assert_eq!(s.homing.velocity_counts_per_s, 2_000.0);
    assert_eq!(
        (s.n_motors, s.period_us, s.gains_period_us, &s.law, s.counts_per_rev, s.gear_ratio),
        (d.n_motors, d.period_us, d.gains_period_us, &d.law, d.counts_per_rev, d.gear_ratio)
    );
    // fe_scale: the shipped files keep PMAC's 96 on the error terms; a file without the key
    // (from before it) keeps eq. 3-1 as written, the loop its gains were tuned with.
    assert_eq!((s.fe_scale, d.fe_scale), (96.0, 1.0));
    assert_eq!((s.timer, &s.gather, s.step), (d.timer, &d.gather, d.step));
    assert_eq!((s.jog, s.check), (d.jog, d.check), "[jog], [check]");
    assert_eq!(
        TrajectorySettings { knots: None, ..s.trajectory.clone() },
        d.trajectory,
        "trajectory"
    );
    assert_eq!((&s.hwserver, s.max_missed_in_row), (&d.hwserver, d.max_missed_in_row));
    assert_eq!(SimSettings { start_counts: vec![], ..s.sim.clone() }, d.sim);
    // The shipped files wire a gripper on DIO6; without the key there is none (an output is
    // switched only where someone wired a gripper).
    assert_eq!((s.s626.gripper_dio, d.s626.gripper_dio), (Some(6), None));
    assert_eq!(S626Settings { gripper_dio: None, ..s.s626.clone() }, d.s626, "[s626]");
    assert!(s.sim.start_counts.iter().all(|&c| c == 0.0), "start at 0, the default");
    assert_eq!((&s.conveyor, &s.camera), (&d.conveyor, &d.camera), "[conveyor], [camera]");
}

/// Issue 11: `stall_motor = 0` is "none" (it used to wrap around on the way to the
/// hwserver), and a motor that is not simulated is refused by name.
#[test]
fn fault_injection_motors_are_one_based_or_none() {
    let s = parse(&format!("[sim]\nstall_motor = 0\nstuck_top_motor = 2\n{}", MOTOR.repeat(3)))
        .unwrap();
    assert_eq!((s.sim.plant.stall_motor, s.sim.plant.stuck_top_motor), (None, Some(2)));
    check(
        &format!("[sim]\nstall_motor = 4\n{}", MOTOR.repeat(3)),
        "q.toml:2:15: sim.stall_motor: must be 0‥3, found 4",
    );
}

/// A backend given on the command line brings its own timing defaults, unless the file
/// set them.
#[test]
fn the_backend_chooses_the_timing_defaults() {
    let names = names();
    let motors = MOTOR.repeat(3);
    let mut s = Settings::parse(Path::new("q.toml"), &motors, &names).unwrap();
    assert_eq!((s.hwserver.watchdog_periods, s.max_missed_in_row), (250, 250));
    s.set_backend("s626").unwrap();
    assert_eq!((s.hwserver.watchdog_periods, s.max_missed_in_row), (10, 25));
    let text = format!("[hwserver]\nwatchdog_periods = 40\n{motors}");
    let mut s = Settings::parse(Path::new("q.toml"), &text, &names).unwrap();
    s.set_backend("s626").unwrap();
    assert_eq!((s.hwserver.watchdog_periods, s.max_missed_in_row), (40, 25));
    assert_eq!(
        s.set_backend("s7").unwrap_err().to_string(),
        "--backend: unknown backend `s7`; available: sim, s626"
    );
}

/// The wiring's errors name the key they are about where the file sets it: the later of two
/// keys that take one channel, each list's length; the simulated robot's `--motors` leaves
/// the card's wiring alone.
#[test]
fn the_626_wiring_errors_name_the_key_where_it_is_set() {
    let motors = MOTOR.repeat(3);
    let on = |s626: &str| {
        format!(
            "[hwserver]\nbackend = \"s626\"\n[s626]\n{s626}[general]\ncounts_per_rev = 1024\n{motors}"
        )
    };
    check(
        &on("limit_bottom_dio = [10, 12, 9]\n"),
        "q.toml:4:20: s626.limit_bottom_dio: DIO9 is already s626.limit_top_dio",
    );
    // Both set: the later one is named.
    check(
        &on("limit_top_dio = [9, 11, 13]\nlimit_bottom_dio = [10, 12, 9]\n"),
        "q.toml:5:20: s626.limit_bottom_dio: DIO9 is already s626.limit_top_dio",
    );
    check(
        &on("counter_channels = [0, 1, 1]\n"),
        "q.toml:4:20: s626.counter_channels: each motor needs a channel of its own, found [0, 1, 1]",
    );
    // A list holds up to one entry per motor the card drives (four).
    assert_eq!(parse(&on("dac_channels = [0, 1, 2, 3]\n")).unwrap().s626.dac_channels.len(), 4);
    check(
        &on("dac_channels = [0, 1, 2, 3, 0]\n"),
        "q.toml:4:16: s626.dac_channels: at most 4 entries, found 5",
    );
    // Each per-motor list, the signs too, where it is set.
    let lists = [
        ("dac_sign", 12, "[1, -1]"),
        ("counter_sign", 16, "[1, -1]"),
        ("limit_bottom_dio", 20, "[10, 12]"),
    ];
    for (key, col, two) in lists {
        check(
            &on(&format!("{key} = {two}\n")),
            &format!("q.toml:4:{col}: s626.{key}: 3 motors need 3 entries, found 2"),
        );
    }
    let mut sim = parse(&format!("[s626]\nenable_dio = [0, 1]\n{motors}")).unwrap();
    sim.set_n_motors(3).unwrap();
    assert_eq!(sim.n_motors, 3);
}

/// Issue 12: the 626's wiring is checked where it is used — every motor with its channels,
/// no DIO channel twice or reserved — naming the key; `--device` and `--backend` too.
#[test]
fn the_626_wiring_is_checked_when_it_is_the_backend() {
    let motors = MOTOR.repeat(3);
    let on = |s626: &str| {
        format!(
            "[hwserver]\nbackend = \"s626\"\n[s626]\n{s626}[general]\ncounts_per_rev = 1024\n{motors}"
        )
    };
    check(
        &on("enable_dio = [0, 1]\n"),
        "q.toml:4:14: s626.enable_dio: 3 motors need 3 entries, found 2",
    );
    check(
        &on("limit_top_dio = [9, 8, 13]\n"),
        "q.toml:4:17: s626.limit_top_dio: DIO8 is reserved (s626.reserved_dio: the counters' index inputs)",
    );
    check(
        &on("charge_pump_dio = 9\n"),
        "q.toml:4:19: s626.charge_pump_dio: DIO9 is already s626.limit_top_dio",
    );
    // Issue 27: the emergency-stop input is one more input of the bank, on a pin of its own.
    check(
        &on("estop_dio = 13\n"),
        "q.toml:4:13: s626.estop_dio: DIO13 is already s626.limit_top_dio",
    );
    check(&on("estop_dio = 16\n"), "q.toml:4:13: s626.estop_dio: must be -1‥15, found 16");
    assert_eq!(parse(&on("estop_dio = 5\n")).unwrap().s626.estop_dio, Some(5));
    assert_eq!(parse(&on("estop_dio = -1\n")).unwrap().s626.estop_dio, None);
    // Issue 30: the gripper's output is a free output of the bank, never one the server keeps.
    check(
        &on("gripper_dio = 1\n"),
        "q.toml:4:15: s626.gripper_dio: DIO1 is already s626.enable_dio",
    );
    check(
        &on("gripper_dio = 14\n"),
        "q.toml:4:15: s626.gripper_dio: DIO14 is reserved (s626.reserved_dio: the counters' index inputs)",
    );
    let s = parse(&on("gripper_dio = 7\ngripper_close_s = 0.2\n")).unwrap();
    assert_eq!((s.s626.gripper_dio, s.s626.gripper_close_s), (Some(7), 0.2));
    check(
        &on("gripper_close_s = 0\n"),
        "q.toml:4:19: s626.gripper_close_s: must be above 0 and at most 10 s, found 0",
    );
    check(
        &on("dac_channels = [0, 1, 1]\n"),
        "q.toml:4:16: s626.dac_channels: each motor needs a channel of its own, found [0, 1, 1]",
    );
    check(
        &on("dac_sign = [1, 0, 1]\n"),
        "q.toml:4:12: s626.dac_sign: entries must be 1 or -1, found 0",
    );
    check(
        &on("enable_dio = [0, 1, 16]\n"),
        "q.toml:4:14: s626.enable_dio: entries must be 0‥15, found 16",
    );
    // The sim ignores the 626's wiring but for the gripper, which it wires as the card.
    let text = format!("[s626]\ngripper_dio = 10\n{motors}");
    assert_eq!(
        parse(&text).unwrap_err().to_string(),
        "q.toml:2:15: s626.gripper_dio: DIO10 is not a free output: it is an amplifier enable, \
         the charge pump, a reserved channel or an input (free: DIO5, DIO6, DIO7)"
    );
    let s = parse(&format!("[s626]\ngripper_dio = 6\n{motors}")).unwrap();
    assert_eq!(s.s626.free_outputs(3), 1 << 5 | 1 << 6 | 1 << 7);
    assert_eq!(s.s626.free_outputs(2), 1 << 5 | 1 << 6 | 1 << 7 | 1 << 3 | 1 << 13 | 1 << 15);
    // A channel named twice (the simulator does not check the card's wiring) is kept once
    // taken, not freed again.
    let twice = S626Settings { reserved_dio: vec![0, 2, 8, 14], ..s.s626.clone() };
    assert_eq!(twice.free_outputs(3), 1 << 5 | 1 << 6 | 1 << 7);
    // The switching to the 626 checks the rest of the wiring.
    let text = format!("[s626]\nenable_dio = [0, 1]\n{motors}");
    let mut s = parse(&text).unwrap();
    let e = s.set_backend("s626").unwrap_err();
    assert_eq!(
        e.to_string(),
        "--backend: s626.enable_dio in q.toml: 3 motors need 3 entries, found 2"
    );
    let mut s = parse(&on("")).unwrap();
    s.set_device(Path::new("/dev/comedi1")).unwrap();
    assert_eq!(s.s626.device, Path::new("/dev/comedi1"));
    // Counts meant for 4× on a card that counts 1×: named, for the backend to refuse.
    let four_x = parse(&format!("[hwserver]\nbackend = \"s626\"\n{motors}")).unwrap();
    assert!(
        four_x.s626_counts_problem().unwrap().starts_with(
            "q.toml: general.counts_per_rev = 4096 counts per revolution, but the 626 counts 1024"
        ),
        "{:?}",
        four_x.s626_counts_problem()
    );
    assert_eq!(parse(&on("")).unwrap().s626_counts_problem(), None);
}

/// Issue 13: the shipped `[robot]` is the notes' assumed Deltabot, its homed frame at the
/// work centre; a file without the table has no robot, and one with an empty table takes the
/// defaults, the home angle computed from the geometry.
#[test]
fn the_robot_table_is_the_notes_deltabot() {
    let s = shipped();
    let robot = s.robot().expect("the shipped file describes the robot");
    assert_eq!(robot.geometry, qmarc_kinematics::Geometry::ASSUMED);
    let centre = robot.counts_of(&WORK_CENTRE_M.into()).unwrap();
    assert!(centre.iter().all(|c| c.abs() < 0.01), "the work centre reads {centre:?} counts");
    assert_eq!(parse(&MOTOR.repeat(3)).unwrap().robot, None);
    let empty = parse(&format!("[robot]\n{}", MOTOR.repeat(3))).unwrap();
    let exact = empty.robot.unwrap().home_rad;
    assert!(exact.iter().zip(s.robot.unwrap().home_rad).all(|(a, b)| (a - b).abs() < 1e-6));
    assert_eq!(empty.robot().unwrap().counts_of(&WORK_CENTRE_M.into()).unwrap(), [0.0; 3]);
    assert!(
        parse(&format!("[general]\nn_motors = 1\n[robot]\n{MOTOR}")).unwrap().robot().is_none()
    );
    let s626 = Settings::load(&shipped_path().with_file_name("s626.toml"), &names()).unwrap();
    assert_eq!(s626.robot, s.robot, "config/s626.toml: the same robot");
}

#[test]
fn robot_errors_name_the_field() {
    let m = MOTOR.repeat(3);
    check(
        &format!("[robot]\nrod_length_m = -0.7\n{m}"),
        "q.toml:2:16: robot.rod_length_m: must be a finite number > 0, found -0.7",
    );
    check(
        &format!("[robot]\narm_azimuth_deg = [0, 120]\n{m}"),
        "q.toml:2:19: robot.arm_azimuth_deg: one value per arm: 3 numbers, found 2",
    );
    check(
        &format!("[robot]\narm_azimuth_deg = [0, 0.5, 240]\n{m}"),
        "q.toml:2:19: robot.arm_azimuth_deg: arms 1 and 2 are less than 1° apart",
    );
    check(
        &format!("[robot]\nrod_length_m = 0.1\nhome_angle_deg = [0, 0, 0]\n{m}"),
        "q.toml:3:18: robot.home_angle_deg: the homed frame is no pose of this robot: no pose \
         has the arm angles (0.0000°, 0.0000°, 0.0000°): the cables cannot all reach one point",
    );
    check(
        &format!("[robot]\nrod_length_m = 0.1\n{m}"),
        "q.toml:1:1: robot.home_angle_deg: not set, and its default, the arm angles of the \
         work centre (0, 0, −600) mm, does not exist: arm 1 cannot reach (0.0, 0.0, -600.0) mm: \
         the point is out of its reach; set home_angle_deg",
    );
}

/// Issue 13: the calibration's keys are checked and named like every other.
#[test]
fn plant_and_law_scale_errors_name_the_field() {
    let m = MOTOR.repeat(3);
    check(
        &format!("[general]\nfe_scale = 0\n{m}"),
        "q.toml:2:12: general.fe_scale: must be a finite number > 0, found 0",
    );
    check(
        &format!("[sim]\nvelocity_loop_hz = 0.5\n{m}"),
        "q.toml:2:20: sim.velocity_loop_hz: must be 0 (a first-order lag) or 1‥1000 Hz, found 0.5",
    );
    check(
        &format!("[sim]\nvelocity_loop_zeta = 1.0\n{m}"),
        "q.toml:2:22: sim.velocity_loop_zeta: must be 0.05‥0.99 (a velocity loop that rings), \
         found 1",
    );
    let s = parse(&format!("[sim]\nvelocity_loop_hz = 0\n{m}")).unwrap();
    assert_eq!(s.sim.plant.velocity_loop_hz, 0.0, "0: the first-order lag tau_s");
}

/// Issue 14: the wait mode, the response spin and the CPUs are checked and named like every
/// other key; blocking, no spin and no pinning are the defaults.
#[test]
fn wait_mode_and_cpus_are_checked() {
    let m = MOTOR.repeat(3);
    let d = parse(&m).unwrap();
    assert_eq!((d.hwserver.wait, d.hwserver.response_spin_us), (HwWait::Block, 0));
    assert_eq!((d.timer.servo_cpu, d.timer.hwserver_cpu), (None, None));
    let s = parse(&format!(
        "[timer]\nservo_cpu = 0\nhwserver_cpu = 1\n[hwserver]\nwait = \"spin\"\nresponse_spin_us = 400\n{m}"
    ))
    .unwrap();
    assert_eq!((s.timer.servo_cpu, s.timer.hwserver_cpu), (Some(0), Some(1)));
    assert_eq!((s.hwserver.wait, s.hwserver.response_spin_us), (HwWait::Spin, 400));
    check(
        &format!("[hwserver]\nwait = \"poll\"\n{m}"),
        "q.toml:2:8: hwserver.wait: must be \"block\" or \"spin\", found \"poll\"",
    );
    check(
        &format!("[timer]\nservo_cpu = -2\n{m}"),
        "q.toml:2:13: timer.servo_cpu: must be -1‥1023, found -2",
    );
    // One CPU for both: fine when the hwserver blocks, refused when it spins.
    let one = "[timer]\nservo_cpu = 1\nhwserver_cpu = 1\n[hwserver]\nwait = ";
    let s = parse(&format!("{one}\"block\"\n{m}")).unwrap();
    assert_eq!((s.timer.servo_cpu, s.timer.hwserver_cpu), (Some(1), Some(1)));
    check(
        &format!("{one}\"spin\"\n{m}"),
        "q.toml:5:8: hwserver.wait: \"spin\" needs a CPU of its own, but timer.servo_cpu and \
         timer.hwserver_cpu are both 1: the spinning hwserver would starve the servo thread; pin \
         them to different CPUs, or wait = \"block\" (one CPU shared by both is fast when they \
         block: BENCHMARKS.md)",
    );
}

/// `[tune]`: the shipped file states the defaults; gains, objective and bounds are checked
/// with the file, line and field named.
#[test]
fn tune_settings_are_checked() {
    let m = MOTOR.repeat(3);
    assert_eq!(parse(&m).unwrap().tune, crate::TuneSettings::default());
    assert_eq!(shipped().tune, crate::TuneSettings::default());
    let s = parse(&format!("[tune]\nparams = [\"kvff\"]\nkaff_bounds = [1.0, 5.0]\n{m}")).unwrap();
    assert_eq!(
        (s.tune.params.clone(), s.tune.bounds_of(crate::TuneParam::Kaff)),
        (vec![crate::TuneParam::Kvff], [1.0, 5.0])
    );
    check(
        &format!("[tune]\nparams = [\"kq\"]\n{m}"),
        "q.toml:2:10: tune.params: unknown gain `kq`: one of kp, ki, kd, kvff, kaff, kjff",
    );
    check(
        &format!("[tune]\nobjective = \"rms\"\n{m}"),
        "q.toml:2:13: tune.objective: unknown objective `rms`: one of abs, sse, max",
    );
    check(
        &format!("[tune]\nkp_bounds = [5.0, 1.0]\n{m}"),
        "q.toml:2:13: tune.kp_bounds: must be [min, max] with 0 ≤ min < max, found [5.0, 1.0]",
    );
    check(
        &format!("[tune]\nmargin = 0.5\n{m}"),
        "q.toml:2:10: tune.margin: must be 1‥10 ×, found 0.5",
    );
}

#[test]
fn telemetry_settings_are_checked() {
    let m = MOTOR.repeat(3);
    assert_eq!(parse(&m).unwrap().telemetry, crate::TelemetrySettings::default());
    assert_eq!(shipped().telemetry, crate::TelemetrySettings { enabled: true, every: 4 });
    let s = parse(&format!("[telemetry]\nenabled = false\nevery = 10\n{m}")).unwrap();
    assert_eq!(s.telemetry, crate::TelemetrySettings { enabled: false, every: 10 });
    let e = parse(&format!("[telemetry]\nevery = 0\n{m}")).unwrap_err().to_string();
    assert!(e.starts_with("q.toml:2:9: telemetry.every: "), "{e}");
    let e = parse(&format!("[telemetry]\nenabled = 1\n{m}")).unwrap_err().to_string();
    assert!(e.starts_with("q.toml:2:11: telemetry.enabled: "), "{e}");
}

/// Issue 27, item 2: gains are finite, not negative, and none so large that the encoder's
/// resolution alone asks more than the DAC's full scale (eq. 3-1, `gains_problem`); the motion
/// limits are positive and below the encoder-fault speed; homing may not outrun them.
#[test]
fn gains_and_motion_limits_are_checked() {
    let one = |motor: &str| format!("[general]\nn_motors = 1\nfe_scale = 96.0\n{motor}");
    let thesis =
        "[[motor]]\nkp = 182000.0\nki = 100.0\nkd = 3000.0\nkvff = 119000.0\nkaff = 100.0\n";
    assert!(parse(&one(thesis)).is_ok(), "the thesis' gains");
    let with = |key: &str, value: &str| {
        let line = thesis.lines().find(|l| l.starts_with(&format!("{key} ="))).unwrap();
        one(&thesis.replace(line, &format!("{key} = {value}")))
    };
    for (key, value, expected) in [
        (
            "kp",
            "1e308",
            "q.toml:5:6: motor[1].kp: 1e308 makes one count of following error alone ask 4.578e303 DAC codes (2⁻²¹·Kp·fe_scale, eq. 3-1), more than the full scale 8191: the encoder's resolution would jump the output from end to end; at most 1.789e8 here",
        ),
        (
            "kp",
            "-182000",
            "q.toml:5:6: motor[1].kp: must be ≥ 0, found -182000: a negative gain drives the motor away from its command",
        ),
        ("kp", "nan", "q.toml:5:6: motor[1].kp: must be a finite number, found NaN"),
        ("kd", "inf", "q.toml:7:6: motor[1].kd: must be a finite number, found inf"),
        (
            "kvff",
            "1e9",
            "q.toml:8:8: motor[1].kvff: 1e9 makes one count per period of commanded velocity alone ask 678003 DAC codes (2⁻²¹·Kp·Kvff/128, eq. 3-1), more than the full scale 8191: the encoder's resolution would jump the output from end to end; at most 1.208e7 here",
        ),
        (
            "kaff",
            "-1",
            "q.toml:9:8: motor[1].kaff: must be ≥ 0, found -1: a negative gain drives the motor away from its command",
        ),
    ] {
        check(&with(key, value), expected);
    }
    // At another period the law runs rescaled gains: they are the ones checked.
    let mut s = parse(&one(thesis).replace("kaff = 100.0", "kaff = 1000000.0")).unwrap();
    assert_eq!(
        s.set_period_us(100).unwrap_err().to_string(),
        "--period-us: motor[1].kaff of q.toml: rescaled from gains_period_us = 400 to period_us = 100, 1.6e7 makes one count per period² of commanded acceleration alone ask 10848 DAC codes (2⁻²¹·Kp·Kaff/128, eq. 3-1), more than the full scale 8191: the encoder's resolution would jump the output from end to end; at most 1.208e7 here"
    );
    assert_eq!(s.period_us, 400, "refused, unchanged");
    let d = MotorSafety::default();
    let limits = parse(&one(thesis)).unwrap().safety[0];
    assert_eq!(
        (
            limits.max_velocity_counts_per_s,
            limits.max_acceleration_counts_per_s2,
            limits.max_jerk_counts_per_s3
        ),
        (d.max_velocity_counts_per_s, d.max_acceleration_counts_per_s2, d.max_jerk_counts_per_s3)
    );
    check(
        &one(&format!("{thesis}max_jerk_counts_per_s3 = 0\n")),
        "q.toml:10:26: motor[1].max_jerk_counts_per_s3: must be a finite number > 0, found 0",
    );
    check(
        &one(&format!("{thesis}max_velocity_counts_per_s = 600000\n")),
        "q.toml:10:29: motor[1].max_velocity_counts_per_s: 600000 counts/s is not below hwserver.max_counts_per_s = 500000, the speed at which the hwserver takes an encoder for broken: a motion that fast would fault",
    );
    check(
        &one(&format!("{thesis}max_velocity_counts_per_s = 1500\n")),
        "q.toml:1:1: homing.velocity_counts_per_s: homing would move motor 1 at 2000 counts/s, faster than its max_velocity_counts_per_s = 1500",
    );
    // The shipped files state the defaults at 4×, a quarter of them at 1×.
    for m in shipped().safety {
        assert_eq!(
            (
                m.max_velocity_counts_per_s,
                m.max_acceleration_counts_per_s2,
                m.max_jerk_counts_per_s3
            ),
            (
                d.max_velocity_counts_per_s,
                d.max_acceleration_counts_per_s2,
                d.max_jerk_counts_per_s3
            )
        );
    }
    let s626 = Settings::load(&shipped_path().with_file_name("s626.toml"), &names()).unwrap();
    for m in s626.safety {
        assert_eq!(
            (
                m.max_velocity_counts_per_s * 4.0,
                m.max_acceleration_counts_per_s2 * 4.0,
                m.max_jerk_counts_per_s3 * 4.0
            ),
            (
                d.max_velocity_counts_per_s,
                d.max_acceleration_counts_per_s2,
                d.max_jerk_counts_per_s3
            )
        );
    }
}

/// Issue 28, item 8: numbers in messages as a person writes them — plain in the everyday
/// range, short exponent notation beyond (six significant digits at most), never 309 digits
/// or float noise.
#[test]
fn numbers_in_messages_are_short() {
    assert_eq!(crate::num(1e308), "1e308");
    assert_eq!(crate::num(-2.5e-9), "-2.5e-9");
    assert_eq!(crate::num(1e-3 * 1e-3 * 1e3 * 1e-3), "1e-6", "float noise rounded off");
    assert_eq!(crate::num(1.234_567_89e12), "1.23457e12");
    assert_eq!(crate::num(86_400.0), "86400");
    assert_eq!(crate::num(0.25), "0.25");
    assert_eq!(crate::num(0.0), "0");
    let text = std::fs::read_to_string(shipped_path()).unwrap();
    let big = text.replace("\nduration_s = 2.0", "\nduration_s = 1e308");
    assert!(big != text, "the shipped file's step duration moved");
    let e = parse(&big).unwrap_err().to_string();
    assert!(e.ends_with("(trajectory.max_duration_s), found 1e308"), "{e}");
}

/// `[pick]` (the pick cycle as a path) and `kjff` (the jerk feed-forward, not in eq. 3-1):
/// defaults, and bad values named by file, line and field.
#[test]
fn pick_and_the_jerk_feed_forward_are_checked() {
    let one = "[general]\nn_motors = 1\n";
    let s = parse(&format!("{one}{MOTOR}")).unwrap();
    assert_eq!(s.pick, crate::PickSettings::default());
    assert_eq!(s.motors[0].kjff, 0.0, "left out, Kjff is 0: eq. 3-1");
    let s = parse(&format!(
        "{one}[pick]\nat_mm = [0.0, 50.0, -650.0]\nspeed = 0.5\n{MOTOR}kjff = 2.0\n"
    ))
    .unwrap();
    assert_eq!((s.pick.at_mm, s.pick.speed, s.motors[0].kjff), ([0.0, 50.0, -650.0], 0.5, 2.0));
    check(
        &format!("{one}[pick]\nspeed = 1.5\n{MOTOR}"),
        "q.toml:4:9: pick.speed: must be > 0 and ≤ 1 (a fraction of the motors' limits), found 1.5",
    );
    check(
        &format!("{one}[pick]\nat_mm = [1.0, 2.0]\n{MOTOR}"),
        "q.toml:4:9: pick.at_mm: must be a point [x, y, z] in mm, found [1.0, 2.0]",
    );
    check(
        &format!("{one}{MOTOR}kjff = -1.0\n"),
        "q.toml:9:8: motor[1].kjff: must be ≥ 0, found -1: a negative gain drives the motor away \
         from its command",
    );
}
