//! A pick another robot of the cell has (its claim was the earlier): the picker gives it up
//! while its gripper has not been told to close — on to the place, smoothly, the gripper
//! left open — and not once it has been.

use super::*;

#[test]
fn a_pick_another_robot_has_is_given_up_before_the_grip_only() {
    let s = settings();
    let (mut p, _serve, mut h) = picker(&s);
    let mut r = rig();
    let speed = 4;
    let (rest, _, _) = r.run(&mut p, &mut h, 40, speed);
    let pick = Pick { id: 7, belt_mm: 250.0, across_mm: 0.0, latched_counts: r.belt };
    h.picks.push(pick).unwrap();
    let (mut cmds, _, _) = r.run(&mut p, &mut h, 20, speed);
    assert_eq!(r.intercepting.first().map(|(id, _)| *id), Some(7), "intercepting");
    // Another's: a cancel for another part changes nothing; this one's ends the pick.
    h.shared.cancel.store(8, Ordering::Release);
    let (c, events, _) = r.run(&mut p, &mut h, 5, speed);
    cmds.extend(c);
    assert!(events.is_empty(), "{events:?}");
    h.shared.cancel.store(7, Ordering::Release);
    let (c, events, _) = r.run(&mut p, &mut h, 1_500, speed);
    cmds.extend(c);
    assert_eq!(events.first(), Some(&PickEvent::GaveUp { id: 7, why: GaveUp::Elsewhere }));
    assert!(!events.iter().any(|e| matches!(e, PickEvent::Gripping { .. })), "{events:?}");
    assert_eq!(r.told, Some(false), "the gripper told to open");
    let mut all = vec![rest[rest.len() - 1]];
    all.extend(cmds);
    smooth(&s, &all);
    // Once the gripper is told to close, a cancel comes too late: the pick goes on.
    let next = Pick { id: 9, belt_mm: 250.0, across_mm: 0.0, latched_counts: r.belt };
    h.picks.push(next).unwrap();
    let mut told_close = false;
    for _ in 0..4_000 {
        let (_, e, _) = r.run(&mut p, &mut h, 1, speed);
        if e.iter().any(|e| matches!(e, PickEvent::Gripping { id: 9, .. })) {
            told_close = true;
            h.shared.cancel.store(9, Ordering::Release);
        }
        if e.iter().any(|e| matches!(e, PickEvent::Lifted { id: 9 })) {
            assert!(told_close);
            return;
        }
        assert!(!e.iter().any(|e| matches!(e, PickEvent::GaveUp { .. })), "{e:?}");
    }
    panic!("part 9 was not lifted");
}
