//! Unit tests of `rest`.

use super::*;
use crate::results::Series;
use qmarc_report::summary::Summary;

/// A scratch folder, removed when dropped.
struct Scratch(PathBuf);
impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn scratch(name: &str) -> Scratch {
    let dir = std::env::temp_dir().join(format!("qmarc-rest-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    Scratch(dir)
}

/// The shipped settings (the simulated Deltabot, three motors, a gripper on DIO 6).
fn settings() -> Settings {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
    Settings::load(&path, &qmarc_config::Names::any()).unwrap()
}

/// A move's results in `dir` whose `gather.csv` ends with `last` (`cycle,act1,act2,act3,grip`).
fn moved(dir: &Path, last: &str) -> MoveResult {
    let csv = format!("cycle,act1,act2,act3,grip\n0,0,0,0,0\n{last}\n");
    let mut summary =
        Summary::controller_lost((qmarc_config::Mode::Move, false), 3, 400, 0, String::new());
    summary.fault = None;
    summary.trajectory = "move".into();
    MoveResult {
        summary,
        series: Series::parse(&csv, 0.0004),
        end: EndRow::parse("cycle,act1,act2,act3,grip", last),
        written: None,
        plots: Vec::new(),
        dir: dir.to_path_buf(),
    }
}

/// Issue 42, item 2: the simulated robot is where every move starts — `[sim] start_counts`,
/// `counter_offset` off where unhomed — homed as `[sim] homed` or its state file says (only
/// a file written for the simulator counts), the gripper open; the effector only in a homed
/// frame; and the last move's end is not taken for where it is.
#[test]
fn the_simulated_robot_is_where_every_move_starts() {
    let d = scratch("sim");
    let mut s = settings();
    s.sim.start_counts = vec![100.0, -200.0, 300.0];
    let last = moved(&d.0, "9,1,2,3,2");
    let rest = Rest::of(&s, &[], &d.0, Some(&last), SystemTime::now());
    assert_eq!(rest.counts, Ok(vec![100.0, -200.0, 300.0]), "not the last move's end");
    assert_eq!(rest.homed, Ok(vec![true; 3]));
    assert_eq!(rest.gripper, Ok(Gripper(Gripper::OPEN)));
    let robot = s.robot().unwrap();
    let p = robot.point_of(&[100.0, -200.0, 300.0]).unwrap() * 1e3;
    assert_eq!(rest.effector_mm, Some(Ok([p.x, p.y, p.z])));
    assert_eq!(
        rest.source(),
        "from the simulator: every move starts at [sim] start_counts, gripper open; homed: [sim] \
         homed = true"
    );
    // Unhomed but for what its state file keeps.
    s.sim.plant.homed = false;
    s.sim.plant.counter_offset = 5000;
    let state = d.0.join("sim.state");
    s.sim.state_file = Some(state.clone());
    std::fs::write(&state, "homed 1 0 1\ncard the simulated Deltabot\n").unwrap();
    let rest = Rest::of(&s, &[], &d.0, None, SystemTime::now());
    assert_eq!(rest.homed, Ok(vec![true, false, true]));
    assert_eq!(rest.counts, Ok(vec![100.0, 4800.0, 300.0]), "motor 2 counter_offset off");
    assert_eq!(rest.effector_mm, Some(Err("not known: the frame is not homed".into())));
    let items: Vec<String> = rest.items().into_iter().map(|(t, _)| t).collect();
    assert_eq!(
        items,
        [
            "M1 100  M2 4800  M3 300 counts",
            "effector not known: the frame is not homed",
            "homed M1 M3, not homed M2",
            "gripper open",
        ]
    );
    assert!(rest.source().ends_with(&format!("homed: kept in {}", state.display())));
    // A file of something else keeps nothing; no file: nothing homed yet.
    std::fs::write(&state, "homed 1 1 1\ncard /dev/comedi0 ino 1\n").unwrap();
    let rest = Rest::of(&s, &[], &d.0, None, SystemTime::now());
    assert_eq!(rest.homed, Ok(vec![false; 3]));
    std::fs::remove_file(&state).unwrap();
    let rest = Rest::of(&s, &[], &d.0, None, SystemTime::now());
    assert_eq!(rest.homed, Ok(vec![false; 3]));
    // A state file that cannot be read: neither the frame nor the counts are known.
    std::fs::create_dir(&state).unwrap();
    let rest = Rest::of(&s, &[], &d.0, None, SystemTime::now());
    assert!(rest.homed.as_ref().is_err_and(|e| e.starts_with("not known: ")), "{rest:?}");
    assert!(rest.counts.is_err(), "{rest:?}");
    // No gripper wired.
    s.s626.gripper_dio = None;
    let rest = Rest::of(&s, &[], &d.0, None, SystemTime::now());
    assert_eq!(rest.items().last().map(|i| i.0.as_str()), Some("no gripper wired"));
}

/// Issue 42, item 2: on the Sensoray 626 the motors and the gripper are where the last move
/// left them (its last gathered row), homed only where the card's state file keeps the frame
/// for this very card (its device node, counters and signs); without a move's results, the
/// positions are not known. `--backend` and `--device` given to the starter count.
#[test]
fn the_card_is_where_the_last_move_left_it() {
    let d = scratch("card");
    let mut s = settings();
    s.hwserver.backend = BackendKind::S626;
    s.s626.state_dir = d.0.join("state");
    // A file stands for the card's device node: its identity is its inode and ctime.
    let device = d.0.join("comedi7");
    std::fs::write(&device, "").unwrap();
    s.s626.device = device.clone();
    let state = d.0.join("state").join("s626-comedi7.state");
    std::fs::create_dir_all(state.parent().unwrap()).unwrap();
    let identity = card_identity(&device.display().to_string(), &s.s626);
    assert!(identity.contains(" ino ") && identity.ends_with("counters [0, 1, 2] signs [1, 1, 1]"));
    std::fs::write(&state, format!("homed 1 1 1\ncard {identity}\n")).unwrap();
    let robot = s.robot().unwrap();
    let counts = robot.counts_of(&qmarc_kinematics::Point::new(0.02, -0.01, -0.64)).unwrap();
    let row = format!("586,{},{},{},2", counts[0], counts[1], counts[2]);
    let last = moved(&d.0, &row);
    let rest = Rest::of(&s, &[], &d.0, Some(&last), SystemTime::now());
    assert_eq!(rest.counts, Ok(counts.to_vec()));
    assert_eq!(rest.homed, Ok(vec![true; 3]));
    let Some(Ok([x, y, z])) = rest.effector_mm else { panic!("{rest:?}") };
    assert!((x - 20.0).abs() < 1e-6 && (y + 10.0).abs() < 1e-6 && (z + 640.0).abs() < 1e-6);
    assert_eq!(rest.gripper.clone().map(Gripper::name), Ok("closed"));
    assert_eq!(
        rest.source(),
        format!(
            "from where the last move (move) left them: {}, cycle 586; homed: kept in {} for \
             this card",
            d.0.join("gather.csv").display(),
            state.display()
        )
    );
    // Another card (a reloaded driver makes a new node): nothing homed, no effector.
    std::fs::write(
        &state,
        "homed 1 1 1\ncard /dev/comedi0 ino 1 ctime 2.3 counters [0, 1, 2] \
                            signs [1, 1, 1]\n",
    )
    .unwrap();
    let rest = Rest::of(&s, &[], &d.0, Some(&last), SystemTime::now());
    assert_eq!(rest.homed, Ok(vec![false; 3]));
    assert_eq!(rest.effector_mm, Some(Err("not known: the frame is not homed".into())));
    // No move's results: where it is is not known.
    let rest = Rest::of(&s, &[], &d.0, None, SystemTime::now());
    assert_eq!(rest.counts, Err("not known: no move's results in the output folder".into()));
    assert_eq!(rest.effector_mm, Some(Err("not known".into())));
    assert!(rest.gripper.is_err());
    // The starter's options choose: the simulated robot, or the fake card.
    let sim = Rest::of(&s, &["--backend=sim".into()], &d.0, Some(&last), SystemTime::now());
    assert_eq!(sim.counts, Ok(vec![0.0; 3]));
    let fake = Rest::of(&s, &["--device=fake".into()], &d.0, Some(&last), SystemTime::now());
    assert_eq!((fake.counts, fake.homed), (Ok(vec![0.0; 3]), Ok(vec![true; 3])));
    assert!(fake.whence.starts_with("the fake card"), "{}", fake.whence);
}

/// Nothing known is said once, with its reason, and no source.
#[test]
fn nothing_known_is_said_once() {
    let rest = Rest::unknown("not known: the settings do not validate");
    assert_eq!(rest.items(), [("not known: the settings do not validate".to_string(), false)]);
    assert_eq!(rest.source(), "");
}
