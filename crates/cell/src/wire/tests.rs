//! The cell's wire: a robot whose belt is not the cell's is refused, saying which setting and
//! both values; what the dispatcher says goes out and comes back the same.

use super::*;
use std::path::Path;

fn shipped() -> Settings {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
    Settings::load(&path, &qmarc_config::Names::any()).unwrap()
}

#[test]
fn a_robot_on_another_belt_is_refused_saying_why() {
    let camera = shipped();
    let belt = CellBelt::of("belt1", &camera, 7);
    let mut robot = shipped();
    robot.cell.belt_offset_mm = 600.0;
    assert_eq!(disagreement(&robot, &belt), None);
    let said = |r: &Settings| disagreement(r, &belt).unwrap_or_default();

    let mut turned = robot.clone();
    turned.conveyor.direction = [-1.0, 0.0, 0.0];
    let e = said(&turned);
    assert!(e.starts_with("conveyor.direction = [-1.0, 0.0, 0.0] in "), "{e}");
    assert!(e.contains("but [1.0, 0.0, 0.0] in cell belt1's belt"), "{e}");

    let mut scaled = robot.clone();
    scaled.conveyor.mm_per_count = 0.04;
    let e = said(&scaled);
    assert!(e.starts_with("conveyor.mm_per_count = 0.04 in "), "{e}");
    assert!(e.contains("but 0.05 in cell belt1's belt"), "{e}");

    let mut faster = robot.clone();
    faster.conveyor.speed_mm_s = 600.0;
    assert!(said(&faster).starts_with("conveyor.speed_mm_s, speed_steps and acceleration_mm_s2"));
    // A real belt's speed is not a setting: only the simulated robot's must agree.
    faster.hwserver.backend = qmarc_config::BackendKind::S626;
    assert_eq!(disagreement(&faster, &belt), None);

    let mut upstream = robot.clone();
    upstream.cell.belt_offset_mm = -250.0;
    let e = said(&upstream);
    assert!(e.contains("begins at 50 mm of cell belt1's belt"), "{e}");
    assert!(e.contains("before the camera's field ends (250 mm)"), "{e}");
}

#[test]
fn the_dispatchers_messages_go_out_and_come_back_the_same() {
    let mut claim = CellMsg::new(CellKind::Claim, 12, "west", 1_000);
    claim.grip_by_ns = 1_200;
    let wire = WireClaim::of(&claim).unwrap();
    let json = serde_json::to_string(&wire).unwrap();
    assert_eq!(json, r#"{"kind":"claim","part":12,"robot":"west","t_ns":1000,"grip_by_ns":1200}"#);
    let back: WireClaim = serde_json::from_str(&json).unwrap();
    assert_eq!(back.msg(), Some(claim));
    for kind in [CellKind::Picked, CellKind::Released, CellKind::Passed] {
        let m = CellMsg::new(kind, 3, "east", 5);
        assert_eq!(WireClaim::of(&m).and_then(|w| w.msg()), Some(m));
    }
    assert_eq!(WireClaim::of(&CellMsg::new(CellKind::Part, 1, "", 0)), None);
    assert_eq!(WireClaim { kind: "stolen".into(), ..wire }.msg(), None);
    let part = WirePart { id: 4, t_ns: 9, belt_mm: 120.5, across_mm: -3.0 };
    let m = part.msg();
    assert_eq!(
        (m.kind(), m.part, m.t_ns, m.belt_mm, m.across_mm),
        (Some(CellKind::Part), 4, 9, 120.5, -3.0)
    );
    let member = WireMember { robot: "east".into(), offset_mm: 600.0, window_mm: [300.0, 500.0] };
    let m = member.msg();
    assert_eq!((m.robot(), m.belt_mm, m.window_mm), ("east", 600.0, [300.0, 500.0]));
}
