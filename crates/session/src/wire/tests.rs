//! The wire's tests: its numbers, its sizes and layout, its words.

use super::*;

#[test]
fn the_wire_numbers_are_those_of_v2() {
    let kinds: Vec<u32> = CommandKind::ALL.iter().map(|k| *k as u32).collect();
    assert_eq!(kinds, [1, 2, 3, 4, 5]);
    let refusals: Vec<u32> = Refusal::ALL.iter().map(|r| *r as u32).collect();
    assert_eq!(refusals, [1, 2, 3, 4, 5, 6, 7, 8]);
    assert_eq!(CommandKind::from_wire(3), Some(CommandKind::Status));
    assert_eq!((CommandKind::from_wire(0), Refusal::from_wire(9)), (None, None));
    let grip = CommandRequest::grip(true);
    assert_eq!((grip.kind, grip.flags), (5, CommandRequest::CLOSE));
    assert_eq!(CommandRequest::grip(false).flags, 0);
    assert_eq!(Refusal::NoGripper.name(), "no_gripper");
}

#[test]
fn the_messages_are_fixed_size_plain_data() {
    assert_eq!(std::mem::size_of::<CommandRequest>(), 56);
    assert_eq!(std::mem::size_of::<CommandResponse>(), 440);
    assert_eq!(std::mem::align_of::<CommandResponse>(), 8);
    // Its parts, each free of padding.
    assert_eq!(std::mem::size_of::<Answer>(), 16 + REASON_BYTES);
    assert_eq!(std::mem::size_of::<Orders>(), 48);
    assert_eq!(std::mem::size_of::<RobotStatus>(), 16 + 16 * MAX_MOTORS + 24);
    assert_eq!(std::mem::size_of::<Timing>(), 32);
    assert_eq!(std::mem::size_of::<ConveyorStatus>(), 6 * 4 + 2 * 8);
}

#[test]
fn a_conveyor_status_says_the_belt_and_the_parts() {
    assert_eq!(ConveyorStatus::default().describe(), "");
    let mut c = ConveyorStatus {
        active: 1,
        seen: 20,
        queued: 2,
        picked: 15,
        missed: 1,
        picking: 0,
        belt_mm: 1234.56,
        belt_mm_s: 499.7,
    };
    assert_eq!(c.picking(), None);
    assert_eq!(c.describe(), "belt 1234.6 mm at 500 mm/s · 2 queued · 15 picked · 1 missed");
    c.picking = 18;
    assert_eq!(c.picking(), Some(17));
    assert!(c.describe().contains("2 queued · picking 17 · 15 picked"), "{}", c.describe());
}

#[test]
fn a_reason_is_cut_at_a_character_boundary() {
    let mut r = Answer::default();
    r.set_reason("motor 2 would go to 12000 counts");
    assert_eq!(r.reason(), "motor 2 would go to 12000 counts");
    let long = "é".repeat(REASON_BYTES);
    r.set_reason(&long);
    assert_eq!(r.reason().len(), REASON_BYTES);
    assert!(r.reason().chars().all(|c| c == 'é'));
    assert_eq!(r.refused(), Some(Refusal::BadRequest));
}

#[test]
fn a_request_carries_its_knots_and_no_more() {
    let k = PathKnot { t_s: 0.5, pos: [1.0, 2.0, 3.0, 0.0], vel: [0.0; MAX_MOTORS] };
    let r = PathRequest::new(&[k, k], true).unwrap();
    assert_eq!((r.knots().len(), r.has_velocities()), (2, true));
    assert!(!PathRequest::new(&[k], false).unwrap().has_velocities());
    assert!(PathRequest::new(&vec![k; MAX_PATH_KNOTS + 1], false).is_none());
    let lying = PathRequest { n_knots: u32::MAX, ..PathRequest::default() };
    assert_eq!(lying.knots().len(), MAX_PATH_KNOTS, "a count past the array is cut");
    assert_eq!(std::mem::size_of::<PathRequest>(), 16 + MAX_PATH_KNOTS * 72);
}
