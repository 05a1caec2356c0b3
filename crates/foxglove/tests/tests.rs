//! gather.mcap read back with the format's reference reader (`mcap`) and checked against what
//! it was written from: every row, the joint states, the effector, the scene — the Deltabot's
//! links against its kinematics, the parts against the belt — and the scene drawn to a PNG
//! whose pixels are looked at (issue 45).

use foxglove::Decode;
use foxglove::messages::{Log, SceneEntity, SceneUpdate};
use qmarc_config::{GatherFields, Mode, Names, Settings};
use qmarc_controller::gather::{Gather, GatherRow};
use qmarc_foxglove::channels;
use qmarc_foxglove::recording::{Part, Recording};
use qmarc_foxglove::scene::{self, EFFECTOR_COLOR, GRIP_COLORS, PART_COLOR};
use qmarc_report::Summary;
use std::collections::BTreeMap;
use std::path::PathBuf;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn settings() -> Settings {
    let names = Names { laws: vec!["pidff"], methods: vec!["spline"], any_plugin: true };
    Settings::load(&workspace().join("config/qmarc.toml"), &names).unwrap()
}

/// 1.2 s at the settings' period: the effector along a line under the base and back down,
/// the actual 2 counts behind the command, the gripper closing half way, the belt moving
/// a count a cycle.
fn rows(s: &Settings) -> Gather {
    let robot = s.robot().unwrap();
    let period = f64::from(s.period_us) * 1e-6;
    let n = (1.2 / period) as u64;
    let mut g = Gather::for_move(n, 1, 3).with_fields(GatherFields::default());
    for k in 0..n {
        let f = k as f64 / n as f64;
        let cmd = robot.counts_of_mm([-100.0 + 200.0 * f, 50.0 * f, -620.0 - 30.0 * f]).unwrap();
        let act = cmd.map(|c| (c - 2.0).round());
        let pad = |v: [f64; 3]| [v[0], v[1], v[2], 0.0];
        g.push(GatherRow {
            cycle: k,
            time_s: k as f64 * period,
            cmd: pad(cmd),
            act: pad(act),
            dac: [k as i32 % 100, -(k as i32 % 50), 7, 0],
            grip: if f < 0.5 { 0 } else { 2 },
            conv: k as i64,
        });
    }
    g
}

/// Every message of `bytes` by topic: (log time, payload), and each topic's schema name.
type Topics = BTreeMap<String, Vec<(u64, Vec<u8>)>>;

fn read(bytes: &[u8]) -> (Topics, BTreeMap<String, (String, String)>) {
    let (mut topics, mut schemas) = (Topics::new(), BTreeMap::new());
    for m in mcap::MessageStream::new(bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref().expect("every channel has a schema");
        schemas.insert(
            m.channel.topic.clone(),
            (schema.name.clone(), m.channel.message_encoding.clone()),
        );
        topics.entry(m.channel.topic.clone()).or_default().push((m.log_time, m.data.to_vec()));
    }
    (topics, schemas)
}

fn entity<'a>(update: &'a SceneUpdate, id: &str) -> &'a SceneEntity {
    update.entities.iter().find(|e| e.id == id).unwrap_or_else(|| panic!("no {id}"))
}

#[test]
fn every_row_and_the_robot_drawn_from_its_kinematics_read_back() {
    let s = settings();
    let g = rows(&s);
    let summary = Summary::controller_lost((Mode::Run, true), 3, s.period_us, 0, String::new());
    let part = Part {
        id: 7,
        belt_mm: 300.0,
        across_mm: 20.0,
        latched_counts: 0,
        state: "picked".into(),
        grip_cycle: Some(g.rows().len() as u64 / 2),
        place_cycle: None,
        error_mm: Some(0.3),
    };
    let parts = [part];
    let started = 1_700_000_000_000_000_000;
    let rec = Recording {
        settings: &s,
        gather: &g,
        summary: &summary,
        started_wall_ns: started,
        path_from: 0,
        settle_from: None,
        parts: &parts,
    };
    let bytes = rec.to_bytes().unwrap();
    let (topics, schemas) = read(&bytes);
    assert_eq!(schemas[channels::GATHER], ("qmarc.GatherRow".into(), "json".into()));
    assert_eq!(
        schemas[channels::JOINT_STATES],
        ("sensor_msgs/msg/JointState".into(), "cdr".into())
    );
    assert_eq!(schemas[channels::SCENE], ("foxglove.SceneUpdate".into(), "protobuf".into()));
    assert_eq!(schemas[channels::EFFECTOR], ("qmarc.Effector".into(), "json".into()));
    assert_eq!(schemas[channels::LOG], ("foxglove.Log".into(), "protobuf".into()));

    // Every row, its values and its time.
    let gathered = &topics[channels::GATHER];
    assert_eq!(gathered.len(), g.rows().len());
    for ((t, json), r) in gathered.iter().zip(g.rows()) {
        let v: serde_json::Value = serde_json::from_slice(json).unwrap();
        assert_eq!(*t, started + (r.time_s * 1e9).round() as u64);
        assert_eq!(v["cycle"], r.cycle);
        assert_eq!(v["time_s"].as_f64(), Some(r.time_s));
        assert_eq!(v["cmd2"].as_f64(), Some(r.cmd[1]));
        assert_eq!(v["act3"].as_f64(), Some(r.act[2]));
        assert_eq!(v["dac2"], r.dac[1]);
        assert_eq!(v["grip"], r.grip);
        assert_eq!(v["conv"], r.conv);
        assert_eq!(v.as_object().unwrap().len(), 13, "cycle, time, 3 × 3 motors, grip, conv");
    }
    // The joint states and the effector at the telemetry's rate.
    let every = s.telemetry.every as usize;
    let expected = g.rows().len().div_ceil(every);
    assert!((expected..=expected + 1).contains(&topics[channels::JOINT_STATES].len()));
    assert_eq!(topics[channels::EFFECTOR].len(), topics[channels::JOINT_STATES].len());
    let robot = s.robot().unwrap();
    for (t, json) in &topics[channels::EFFECTOR] {
        let r = &g.rows()
            [((t - started) as f64 / 1e9 / (f64::from(s.period_us) * 1e-6)).round() as usize];
        let v: serde_json::Value = serde_json::from_slice(json).unwrap();
        let act = robot.mm_of(&[r.act[0], r.act[1], r.act[2]]).unwrap();
        let cmd = robot.mm_of(&[r.cmd[0], r.cmd[1], r.cmd[2]]).unwrap();
        for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
            assert!((v["act"][axis].as_f64().unwrap() - act[k]).abs() < 1e-9);
            assert!((v["cmd"][axis].as_f64().unwrap() - cmd[k]).abs() < 1e-9);
        }
        let d = (0..3).map(|k| (cmd[k] - act[k]).powi(2)).sum::<f64>().sqrt();
        assert!((v["error_mm"].as_f64().unwrap() - d).abs() < 1e-9 && d > 0.01);
    }

    // The scene: at least 25 a second of loop time, each the robot where its row puts it.
    let scenes = qmarc_foxglove::read::scenes(&bytes).unwrap();
    let span_s = g.rows().last().unwrap().time_s;
    assert!(scenes.len() as f64 / span_s >= 25.0, "{} scenes in {span_s} s", scenes.len());
    let g_m = robot.geometry;
    for (t, update) in &scenes {
        let k = ((t - started) as f64 / 1e9 / (f64::from(s.period_us) * 1e-6)).round() as usize;
        let r = &g.rows()[k];
        let bot = entity(update, scene::DELTABOT);
        let p = robot.point_of(&[r.act[0], r.act[1], r.act[2]]).unwrap();
        let plate = bot.cylinders[1].pose.as_ref().unwrap().position.as_ref().unwrap();
        assert!((plate.x - p.x).abs() + (plate.y - p.y).abs() + (plate.z - p.z).abs() < 1e-12);
        let len = |a: &foxglove::messages::Point3, b: &foxglove::messages::Point3| {
            ((a.x - b.x).powi(2) + (a.y - b.y).powi(2) + (a.z - b.z).powi(2)).sqrt()
        };
        let (arms, rods) = (&bot.lines[0].points, &bot.lines[1].points);
        assert_eq!((arms.len(), rods.len()), (6, 12), "three arms, three pairs of rods");
        for pair in arms.chunks(2) {
            assert!((len(&pair[0], &pair[1]) - g_m.arm_length_m).abs() < 1e-9);
        }
        for pair in rods.chunks(2) {
            assert!((len(&pair[0], &pair[1]) - g_m.rod_length_m).abs() < 1e-9);
        }
        let fingers = &bot.cubes;
        assert_eq!(fingers.len(), 2);
        let c = fingers[0].color.as_ref().unwrap();
        assert_eq!([c.r, c.g, c.b], GRIP_COLORS[r.grip as usize]);
        // The part: on the belt where the belt has carried it, then in the gripper.
        let belt = entity(update, scene::BELT);
        assert_eq!(belt.cubes.len(), 2, "the belt and its part");
        let at = belt.cubes[1].pose.as_ref().unwrap().position.as_ref().unwrap();
        let h = s.camera.part_height_mm;
        let expected = if r.cycle >= parts[0].grip_cycle.unwrap() {
            [p.x, p.y, p.z - scene::FINGER_SIZE_M[2] / 2.0 - h / 2000.0]
        } else {
            let along = 300.0 + r.conv as f64 * s.conveyor.mm_per_count;
            s.conveyor.point_mm(along, 20.0, h / 2.0).map(|v| v / 1000.0)
        };
        assert!(
            (at.x - expected[0]).abs() + (at.y - expected[1]).abs() + (at.z - expected[2]).abs()
                < 1e-9
        );
    }

    // The log: the move, the part picked, the end.
    let log: Vec<Log> =
        topics[channels::LOG].iter().map(|(_, b)| Log::decode(&b[..]).unwrap()).collect();
    let said: Vec<&str> = log.iter().map(|l| l.message.as_str()).collect();
    assert!(said[0].starts_with("run began: 3 motors"), "{said:?}");
    assert!(said.contains(&"part 7 picked, 0.30 mm off"), "{said:?}");
    assert!(said.last().unwrap().starts_with("run ended: not ok"), "{said:?}");
}

/// The scene drawn: the effector plate's colour where the view puts the effector (side), the
/// gripper's where it is seen from above, a part's on the belt; the PNG holds the same pixels.
#[test]
fn the_scene_drawn_shows_the_robot_where_it_is() {
    let s = settings();
    let g = rows(&s);
    let summary = Summary::controller_lost((Mode::Run, true), 3, s.period_us, 0, String::new());
    let parts = [Part {
        id: 1,
        belt_mm: 100.0,
        across_mm: 0.0,
        latched_counts: 0,
        state: "missed".into(),
        grip_cycle: None,
        place_cycle: None,
        error_mm: None,
    }];
    let rec = Recording {
        settings: &s,
        gather: &g,
        summary: &summary,
        started_wall_ns: 0,
        path_from: 0,
        settle_from: None,
        parts: &parts,
    };
    let scenes = qmarc_foxglove::read::scenes(&rec.to_bytes().unwrap()).unwrap();
    let robot = s.robot().unwrap();
    let mut checked_part = false;
    for (when, grip) in [(0.1, 0), (1.0, 2)] {
        let (t, update) = qmarc_foxglove::read::scene_at(&scenes, when).unwrap();
        let r = &g.rows()[(*t as f64 / 1e9 / (f64::from(s.period_us) * 1e-6)).round() as usize];
        let p = robot.point_of(&[r.act[0], r.act[1], r.act[2]]).unwrap();
        let png =
            std::env::temp_dir().join(format!("qmarc-scene-{}-{grip}.png", std::process::id()));
        let view = qmarc_foxglove::render::png(update, &png, (400, 360), "test").unwrap();
        let buf = qmarc_foxglove::render::draw(update, &view, "test").unwrap();
        let decoded = image::open(&png).unwrap().to_rgb8();
        let _ = std::fs::remove_file(&png);
        assert_eq!(decoded.as_raw(), &buf, "the PNG holds what was drawn");
        let pixel = |(x, y): (i32, i32)| {
            let k = 3 * (y as usize * 800 + x as usize);
            [buf[k], buf[k + 1], buf[k + 2]]
        };
        let byte = |c: [f64; 3]| c.map(|v| (v * 255.0).round() as u8);
        assert_eq!(pixel(view.side([p.x, p.y, p.z])), byte(EFFECTOR_COLOR), "at {when} s");
        assert_eq!(pixel(view.top([p.x, p.y, p.z])), byte(GRIP_COLORS[grip]), "at {when} s");
        let along = 100.0 + r.conv as f64 * s.conveyor.mm_per_count;
        let part = s.conveyor.point_mm(along, 0.0, 0.0).map(|v| v / 1000.0);
        // Seen from above where the base plate does not cover it.
        if part[0].hypot(part[1]) > robot.geometry.base_radius_m + 0.05 {
            assert_eq!(pixel(view.top(part)), byte(PART_COLOR), "the part at {along} mm");
            checked_part = true;
        }
        // Away from everything: the background.
        assert_eq!(pixel((2, 120)), [255, 255, 255]);
    }
    assert!(checked_part);
}

/// docs/foxglove-layout.json: every panel the layout places is configured, and every topic
/// and message path its panels read is one gather.mcap has (the 3-D view, the plots, the log).
#[test]
fn the_shipped_layout_reads_only_what_the_file_has() {
    let text = std::fs::read_to_string(workspace().join("docs/foxglove-layout.json")).unwrap();
    let layout: serde_json::Value = serde_json::from_str(&text).unwrap();
    let panels = layout["configById"].as_object().unwrap();
    fn placed(v: &serde_json::Value, out: &mut Vec<String>) {
        match v {
            serde_json::Value::String(id) => out.push(id.clone()),
            v => {
                placed(&v["first"], out);
                placed(&v["second"], out);
            }
        }
    }
    let mut ids = Vec::new();
    placed(&layout["layout"], &mut ids);
    ids.sort();
    let mut configured: Vec<String> = panels.keys().cloned().collect();
    configured.sort();
    assert_eq!(ids, configured);
    assert_eq!(
        panels["3D!qmarc"]["topics"].as_object().unwrap().keys().collect::<Vec<_>>(),
        [channels::SCENE]
    );
    assert_eq!(panels["RosOut!log"]["topicToRender"], channels::LOG);
    let s = settings();
    let columns = qmarc_report::files::columns(&rows(&s));
    let mut paths = 0;
    for (id, panel) in panels.iter().filter(|(id, _)| id.starts_with("Plot!")) {
        for p in panel["paths"].as_array().unwrap() {
            let (topic, field) = p["value"].as_str().unwrap().split_once('.').unwrap();
            match topic {
                channels::GATHER => assert!(columns.iter().any(|c| c == field), "{id}: {field}"),
                channels::EFFECTOR => assert_eq!(field, "error_mm", "{id}"),
                other => panic!("{id} plots {other}"),
            }
            paths += 1;
        }
    }
    assert_eq!(paths, 1 + 6 + 3, "the error, command and actual of 3 motors, 3 DACs");
}
