//! The part queue: one part per part however many frames saw it, claimed once, downstream
//! first, missed when it leaves the window or cannot be reached inside it.

use super::*;

const BELT: Belt = Belt { mm_per_count: 0.05 };

fn seen(counts: i64, belt_mm: f64, across_mm: f64) -> Detection {
    Detection { t_ns: 0, latched_counts: counts, belt_mm, across_mm }
}

#[test]
fn a_part_is_carried_by_the_belts_counts() {
    assert_eq!(BELT.carried(100.0, 1_000, 3_000), 200.0);
    assert_eq!(BELT.carried(100.0, 3_000, 1_000), 0.0, "a belt run backwards carries back");
    let p = Part { id: 1, seen: seen(10, 5.0, 0.0), state: PartState::Pending };
    assert_eq!(p.belt_mm(30, &BELT), 6.0);
}

/// The camera sees a part in several frames: each is the part where the belt has carried
/// it, merged into the one part; a part beside it (across) is another.
#[test]
fn frames_of_one_part_are_one_part() {
    let mut q = PartQueue::new([300.0, 500.0], 2.0, 8);
    assert_eq!(q.detect(seen(0, 100.0, 10.0), &BELT), Some(1));
    // 1000 counts later (50 mm) the same part, seen 0.5 mm off: merged.
    assert_eq!(q.detect(seen(1_000, 150.5, 10.0), &BELT), None);
    // 3 mm across: another part.
    assert_eq!(q.detect(seen(1_000, 150.0, 13.0), &BELT), Some(2));
    // Where part 1 was first seen, later: not part 1 (it has moved on).
    assert_eq!(q.detect(seen(1_000, 100.0, 10.0), &BELT), Some(3));
    assert_eq!(q.detect(seen(1_000, f64::NAN, 0.0), &BELT), None, "not a detection");
    assert_eq!(q.parts().len(), 3);
    assert!(q.parts().iter().all(|p| p.state.name() == "pending"));
}

/// The part about to leave the window is picked first; a claimed part is not claimed again,
/// and picked only once.
#[test]
fn the_most_downstream_reachable_part_is_claimed_once() {
    let mut q = PartQueue::new([300.0, 500.0], 2.0, 8);
    let a = q.detect(seen(0, 100.0, 0.0), &BELT).unwrap();
    let b = q.detect(seen(0, 140.0, 20.0), &BELT).unwrap();
    let c = q.detect(seen(0, 120.0, -20.0), &BELT).unwrap();
    // At 4000 counts (+200 mm): 300, 340, 320: b first, then c, then a.
    assert_eq!(q.claim_next(4_000, &BELT, |_, _| true), Some(b));
    assert_eq!(q.claim_next(4_000, &BELT, |_, _| true), Some(c));
    assert_eq!(q.claim_next(4_000, &BELT, |_, _| true), Some(a));
    assert_eq!(q.claim_next(4_000, &BELT, |_, _| true), None, "each claimed once");
    assert!(q.picked(b));
    assert!(!q.picked(b), "never picked twice");
    assert!(!q.picked(99));
    assert_eq!(q.part(b).unwrap().state, PartState::Picked);
    assert_eq!(q.counts(), (1, 0));
    // A claimed part whose pick was given up is missed, once; a picked one never is.
    assert!(q.missed(c));
    assert!(!q.missed(c) && !q.picked(c), "done");
    assert!(!q.missed(b), "picked already");
    assert_eq!(q.part(c).unwrap().state, PartState::Missed);
    assert_eq!(q.counts(), (1, 1));
    // Pending, claimed, picked, missed: a (claimed), b, c.
    assert_eq!(q.tally(), [0, 1, 1, 1, 0]);
    let d = q.detect(seen(0, 10.0, 0.0), &BELT).unwrap();
    assert_eq!(q.tally(), [1, 1, 1, 1, 0]);
    assert!(q.picked(a) && q.part(d).is_some());
    assert_eq!(q.tally(), [1, 0, 2, 1, 0]);
}

/// A part the robot cannot reach inside the window is missed, never chased; one not yet in
/// the window that cannot be reached yet waits.
#[test]
fn a_part_out_of_reach_in_the_window_is_missed_one_before_it_waits() {
    let mut q = PartQueue::new([300.0, 500.0], 2.0, 8);
    let far = q.detect(seen(0, 400.0, 900.0), &BELT).unwrap();
    let early = q.detect(seen(0, 200.0, 0.0), &BELT).unwrap();
    let reach = |p: &Part, at: f64| p.seen.across_mm.abs() < 100.0 && at >= 300.0;
    assert_eq!(q.claim_next(0, &BELT, reach), None);
    assert_eq!(q.part(far).unwrap().state, PartState::Missed, "in the window, out of reach");
    assert_eq!(q.part(early).unwrap().state, PartState::Pending, "not in the window yet");
    assert_eq!(q.claim_next(2_000, &BELT, reach), Some(early), "at 300 mm: in reach");
    assert_eq!(q.counts(), (0, 1));
}

/// A part the belt carries past the window's end unpicked is missed — a claimed one too.
#[test]
fn a_part_past_the_window_is_missed() {
    let mut q = PartQueue::new([300.0, 500.0], 2.0, 8);
    let a = q.detect(seen(0, 450.0, 0.0), &BELT).unwrap();
    let b = q.detect(seen(0, 350.0, 30.0), &BELT).unwrap();
    assert_eq!(q.claim_next(0, &BELT, |_, _| true), Some(a));
    q.sweep(1_000, &BELT); // +50 mm: a at 500 (the end, still in), b at 400.
    assert_eq!(q.counts(), (0, 0));
    q.sweep(1_001, &BELT);
    assert_eq!(q.part(a).unwrap().state, PartState::Missed, "claimed, not picked in time");
    assert!(!q.picked(a), "too late");
    assert_eq!(q.claim_next(3_001, &BELT, |_, _| true), None, "b left too");
    assert_eq!(q.part(b).unwrap().state.name(), "missed");
}

/// A full queue makes room with its oldest done part, never with one still to pick; the ids
/// go on rising.
#[test]
fn a_full_queue_drops_only_parts_that_are_done() {
    let mut q = PartQueue::new([300.0, 500.0], 2.0, 2);
    let a = q.detect(seen(0, 400.0, 0.0), &BELT).unwrap();
    let _b = q.detect(seen(0, 200.0, 0.0), &BELT).unwrap();
    assert_eq!(q.detect(seen(0, 100.0, 0.0), &BELT), None, "full of parts to pick");
    assert_eq!(q.claim_next(0, &BELT, |_, _| true), Some(a));
    assert!(q.picked(a));
    assert_eq!(q.detect(seen(0, 100.0, 0.0), &BELT), Some(3));
    assert!(q.part(a).is_none(), "the done part made room");
}

/// Past a part out of reach, the next one upstream is still looked at and claimed; of two
/// parts level on the belt, the one seen first goes first.
#[test]
fn an_unreachable_part_does_not_hide_the_next_and_a_tie_goes_to_the_first_seen() {
    let mut q = PartQueue::new([300.0, 500.0], 2.0, 8);
    let far = q.detect(seen(0, 450.0, 900.0), &BELT).unwrap();
    let near = q.detect(seen(0, 350.0, 0.0), &BELT).unwrap();
    let reach = |p: &Part, _: f64| p.seen.across_mm.abs() < 100.0;
    assert_eq!(q.claim_next(0, &BELT, reach), Some(near));
    assert_eq!(q.part(far).unwrap().state, PartState::Missed);
    let mut level = PartQueue::new([300.0, 500.0], 2.0, 8);
    let first = level.detect(seen(0, 350.0, -20.0), &BELT).unwrap();
    let second = level.detect(seen(0, 350.0, 20.0), &BELT).unwrap();
    assert_eq!(level.claim_next(0, &BELT, |_, _| true), Some(first));
    assert_eq!(level.claim_next(0, &BELT, |_, _| true), Some(second));
}

/// In a cell the camera numbers the parts: the queue takes its numbers, each once; a part
/// left to another robot is neither claimed nor missed here, another's claim makes it
/// passed, a released one is pending again, and one past the window goes where it is told.
#[test]
fn a_cells_parts_keep_the_cameras_numbers_and_another_robots_are_left() {
    let mut q = PartQueue::new([300.0, 500.0], 2.0, 8);
    assert!(q.insert(41, seen(0, 400.0, 0.0)));
    assert!(q.insert(42, seen(0, 450.0, 0.0)));
    assert!(q.insert(43, seen(0, 350.0, 0.0)));
    assert!(!q.insert(42, seen(0, 100.0, 0.0)), "known already");
    assert!(!q.insert(44, seen(0, f64::NAN, 0.0)), "not a detection");
    // 42 is another's to take: left as it is, not missed; 41 out of reach: missed.
    let claimed = q.claim_next_by(0, &BELT, |p, _| match p.id {
        42 => Take::Leave,
        41 => Take::OutOfReach,
        _ => Take::Claim,
    });
    assert_eq!(claimed, Some(43));
    assert_eq!(q.part(42).unwrap().state, PartState::Pending);
    assert_eq!(q.part(41).unwrap().state, PartState::Missed);
    // Another robot claimed 42: passed here; released when its claimant was lost.
    assert!(q.elsewhere(42));
    assert!(!q.elsewhere(42));
    assert_eq!(q.part(42).unwrap().state.name(), "passed");
    assert!(q.release(42));
    assert!(!q.release(42), "pending already");
    // 43 left to the robots downstream (its pick given up): passed, once.
    assert!(q.pass_on(43));
    assert!(!q.pass_on(43));
    assert_eq!(q.part(43).unwrap().state, PartState::Elsewhere);
    // Past the window (+200 mm: 4000 counts), each pending one goes where it is told.
    q.sweep_by(4_000, &BELT, |p| if p.id == 42 { PartState::Elsewhere } else { PartState::Missed });
    assert_eq!(q.part(42).unwrap().state, PartState::Elsewhere);
    assert_eq!(q.part(43).unwrap().state, PartState::Elsewhere);
    assert_eq!(q.tally(), [0, 0, 0, 1, 2]);
    assert!(q.parts().iter().all(|p| p.state.done()));
}
