//! What a robot says in a cell and what it does on the others' word: a part let pass is
//! said so (and only then taken downstream), a pick given up is said, a cut link leaves
//! each robot what it claimed, a robot cut off claims nothing, its own word back changes
//! nothing, and what it heard of parts long gone is forgotten.

use super::*;

/// The second robot's host cut off for 3 s (a cable pulled, back before the lease ends: no
/// one is said gone): what the upstream robot claims meanwhile, unheard, the downstream one
/// does not take, so no part is picked twice; picking goes on after.
#[test]
fn a_host_cut_off_silently_picks_no_part_twice() {
    let mut run = Run::new(&[("west", 0.0), ("east", 600.0)], 250);
    run.cut = 4_000..7_000;
    for k in 0..14_000 {
        if k == 11_000 {
            run.every_ms = u64::MAX;
        }
        run.step(k);
    }
    let (west, east) = (run.robots.remove(0), run.robots.remove(0));
    let twice: Vec<&u32> = west.picked.iter().filter(|id| east.picked.contains(id)).collect();
    assert!(
        twice.is_empty(),
        "picked twice: {twice:?} (west {:?}, east {:?})",
        west.picked,
        east.picked
    );
    let last = run.seen;
    for r in [&west, &east] {
        assert!(
            r.picked.iter().filter(|id| **id + 12 > last).count() >= 4,
            "{}: {:?}",
            r.name,
            r.picked
        );
    }
}

/// A part seen before this robot's loop first read the belt cannot be placed: it is let
/// pass at once (the robot downstream may take it), and so is one that leaves the window
/// unclaimed; one it claims is not.
#[test]
fn a_part_this_robot_will_not_take_is_said_to_pass() {
    let mut run = Run::new(&[("west", 0.0)], u64::MAX);
    for k in 0..50 {
        run.step(k);
    }
    let r = &mut run.robots[0];
    let side = r.d.cell.as_ref().unwrap();
    let before = side.realtime(run.t0.saturating_sub(10 * MS));
    r.d.cell_message(&CellMsg::new(CellKind::Part, 7, "", before));
    let said: Vec<_> = r.d.cell.as_mut().unwrap().outbox.drain(..).collect();
    assert_eq!(said.len(), 1, "{said:?}");
    assert_eq!(
        (said[0].kind(), said[0].part, said[0].robot()),
        (Some(CellKind::Passed), 7, "west")
    );
    // Said once, however often the part is heard of again.
    r.d.cell_message(&CellMsg::new(CellKind::Part, 7, "", before));
    assert!(r.d.cell.as_ref().unwrap().outbox.is_empty());
    // Not its turn (a robot downstream's home, which has not let it pass): left to the sweep,
    // which lets it pass once past the window; its own turns it picks.
    let east = CellMsg {
        belt_mm: 600.0,
        window_mm: [300.0, 500.0],
        ..CellMsg::new(CellKind::Member, 0, "east", 0)
    };
    let mut run = Run::new(&[("west", 0.0)], 250);
    run.robots[0].inbox.push((0, east));
    for k in 0..3_000 {
        run.step(k);
    }
    let said_passed: Vec<u32> = run
        .log
        .iter()
        .filter(|(_, _, m)| m.kind() == Some(CellKind::Passed))
        .map(|(_, _, m)| m.part)
        .collect();
    let r = run.robots.remove(0);
    let records = r.d.finish();
    let passed: Vec<u32> =
        records.parts.iter().filter(|p| p.state == "passed").map(|p| p.id).collect();
    assert!(passed.len() >= 4 && passed.iter().all(|id| id % 2 == 1), "east's turns: {passed:?}");
    assert_eq!(said_passed, passed, "each said once, as it left the window");
    assert!(r.picked.len() >= 4 && r.picked.iter().all(|id| id % 2 == 0), "{:?}", r.picked);
}

/// What becomes of a part past this robot's window, in its own belt coordinates shifted by
/// its offset: passed while a robot downstream can reach it, missed past them all.
#[test]
fn a_part_past_the_window_is_passed_while_one_downstream_can_reach_it() {
    let west = robot("west", 100.0, 0);
    let mut side = west.d.cell.unwrap();
    // West's window is [400, 600] mm of the cell's belt, east's [1000, 1200].
    let east = qmarc_conveyor::cell::Member {
        name: "east".into(),
        offset_mm: 700.0,
        window_mm: [300.0, 500.0],
    };
    side.cell.join(east);
    assert_eq!(side.fate(550.0), PartState::Elsewhere, "650 mm of the cell's belt");
    assert_eq!(side.fate(1_100.0), PartState::Elsewhere, "east's window ends at 1200 mm");
    assert_eq!(side.fate(1_150.0), PartState::Missed, "1250 mm: past east's reach");
}

/// A pick the picker gives up (out of reach) is said to the cell as given up, and this
/// robot lets the part pass: the robot downstream may take it.
#[test]
fn a_pick_given_up_is_said_to_the_cell() {
    let mut run = Run::new(&[("west", 0.0)], 250);
    let id = give_up_a_pick(&mut run, 0, 2_000);
    let said: Vec<_> =
        run.log.iter().filter(|(_, _, m)| m.part == id).map(|(_, _, m)| m.kind()).collect();
    assert_eq!(said, [Some(CellKind::Claim), Some(CellKind::Released)], "part {id}");
    let side = run.robots[0].d.cell.as_ref().unwrap();
    assert!(side.ledger.passed_by(id, "west") && side.ledger.claim_of(id).is_none());
}

/// The ids of the parts `robot` said `kind` of in `log`, each with the millisecond it did.
fn said(log: &[(u64, &'static str, CellMsg)], robot: &str, kind: CellKind) -> Vec<(u32, u64)> {
    log.iter()
        .filter(|(_, r, m)| *r == robot && m.kind() == Some(kind))
        .map(|(k, _, m)| (m.part, *k))
        .collect()
}

/// More parts than the upstream robot can take on its turns (one every 150 ms, a pick 400
/// ms): it lets some of its turns pass, and the downstream robot takes them — each only
/// after the upstream one said so. None is picked twice.
#[test]
fn a_turn_let_pass_is_taken_downstream_only_on_its_word() {
    let mut run = Run::new(&[("west", 0.0), ("east", 600.0)], 150);
    for k in 0..12_000 {
        if k == 9_000 {
            run.every_ms = u64::MAX;
        }
        run.step(k);
    }
    let passed = said(&run.log, "west", CellKind::Passed);
    let claims = said(&run.log, "east", CellKind::Claim);
    let (west, east) = (run.robots.remove(0), run.robots.remove(0));
    assert!(west.picked.iter().all(|id| !east.picked.contains(id)), "none twice");
    let taken: Vec<u32> = east.picked.iter().copied().filter(|id| id % 2 == 0).collect();
    assert!(taken.len() >= 3, "east took west's turns: {:?}", east.picked);
    for id in taken {
        let word = passed.iter().find(|(p, _)| *p == id).map(|(_, k)| *k);
        let claim = claims.iter().find(|(p, _)| *p == id).map(|(_, k)| *k);
        // Heard 3 ms after it was said.
        assert!(word.zip(claim).is_some_and(|(w, c)| c >= w + 3), "part {id}: {word:?} {claim:?}");
    }
}

/// A pick given up by the upstream robot 20 ms into it (out of reach): the part is the
/// downstream robot's then, and it picks it.
#[test]
fn a_pick_given_up_upstream_is_picked_downstream() {
    let mut run = Run::new(&[("west", 0.0), ("east", 600.0)], 500);
    let id = give_up_a_pick(&mut run, 1_000, 6_000);
    let (west, east) = (run.robots.remove(0), run.robots.remove(0));
    assert!(!west.picked.contains(&id) && east.picked.contains(&id), "{id}: {:?}", east.picked);
}

/// Its companion echoing its own word back changes nothing: every part picked once, no
/// conflict; and the records say when each part's claim was seen, and every part heard of.
#[test]
fn a_robots_own_word_back_changes_nothing() {
    let mut run = Run::new(&[("west", 0.0), ("east", 600.0)], 250);
    run.echo = true;
    for k in 0..8_000 {
        if k == 6_000 {
            run.every_ms = u64::MAX;
        }
        run.step(k);
    }
    let seen = run.seen;
    let (west, east) = (run.robots.remove(0), run.robots.remove(0));
    let mut all: Vec<u32> = west.picked.iter().chain(&east.picked).copied().collect();
    all.sort_unstable();
    assert_eq!(
        all,
        (1..=seen).collect::<Vec<_>>(),
        "west {:?} east {:?}",
        west.picked,
        east.picked
    );
    for r in [west, east] {
        let d = r.d.finish();
        assert_eq!(d.cell.unwrap().conflicts, 0, "{}", r.name);
        assert_eq!(d.detections, u64::from(seen), "{}: every part heard of, once", r.name);
        for p in &d.parts {
            assert!(p.claimed_after_ns.is_some(), "{}: part {}: its claim seen", r.name, p.id);
        }
    }
}

/// Another robot's claim said again (after an outage) is not a new one: the time its claim
/// was seen stays the first.
#[test]
fn a_claim_said_again_is_seen_once() {
    let mut run = Run::new(&[("east", 600.0)], 500);
    let t = run.robots[0].d.cell.as_ref().unwrap().realtime(run.t0 + 300 * MS);
    let m = CellMsg::new(CellKind::Claim, 1, "west", t);
    let claim = CellMsg { grip_by_ns: t + 400 * MS, ..m };
    let mut first = None;
    for k in 0..1_000 {
        if k == 300 || k == 400 {
            // The clock past the part's exposure (100 ms), and on between the two.
            while qmarc_timer::clock::monotonic_now_ns() < run.t0 + (k - 150) * MS {
                std::thread::sleep(std::time::Duration::from_millis(1));
            }
            run.robots[0].inbox.push((k, claim));
        }
        run.step(k);
        if k == 300 {
            first = run.robots[0].d.record(1).and_then(|r| r.claimed_after_ns);
        }
    }
    let d = run.robots.remove(0).d.finish();
    let part = d.parts.iter().find(|p| p.id == 1).unwrap();
    assert!(first.is_some_and(|ns| ns >= 50 * MS), "{first:?}");
    assert_eq!(part.claimed_after_ns, first);
    assert_eq!(part.state, "passed");
}

/// Another's claim that comes once this robot's gripper was told to close does not end its
/// pick (it goes on: a conflict counted); one before it does (above).
#[test]
fn a_claim_after_the_grip_does_not_end_the_pick() {
    let mut run = Run::new(&[("east", 600.0)], 500);
    let mut crossed = None;
    for k in 0..3_000 {
        if let (None, Some((id, from))) = (crossed, run.robots[0].busy)
            && k == from + 175
        {
            let side = run.robots[0].d.cell.as_ref().unwrap();
            let earlier = side.ledger.claim_of(id).unwrap().at_ns - 1;
            let m = CellMsg::new(CellKind::Claim, id, "west", earlier);
            run.robots[0].inbox.push((k, CellMsg { grip_by_ns: earlier + 200 * MS, ..m }));
            crossed = Some(id);
        }
        run.step(k);
    }
    let id = crossed.expect("a pick under way");
    let east = run.robots.remove(0);
    assert_ne!(east.shared.cancel.load(Ordering::Acquire), id, "not cancelled");
    assert!(east.picked.contains(&id));
    assert_eq!(east.d.finish().cell.unwrap().conflicts, 1);
}

/// Cut off, a robot claims nothing new; back, it claims no part seen before it was back
/// (the others may have taken it, unheard), and takes the parts after.
#[test]
fn a_robot_cut_off_claims_nothing_and_back_only_what_came_after() {
    let mut run = Run::new(&[("west", 0.0)], 250);
    let (off, back) = (2_000, 4_000);
    let mut seen_back = 0;
    for k in 0..6_000 {
        if k == off {
            run.robots[0].inbox.push((k, CellMsg::new(CellKind::CutOff, 0, "west", 0)));
        }
        if k == back {
            run.robots[0].inbox.push((k, CellMsg::new(CellKind::Rejoined, 0, "west", 0)));
            seen_back = run.seen;
        }
        run.step(k);
    }
    let claims = said(&run.log, "west", CellKind::Claim);
    assert!(claims.iter().any(|(_, k)| *k < off), "{claims:?}");
    assert!(claims.iter().all(|(_, k)| *k <= off || *k > back), "none while cut off: {claims:?}");
    let after: Vec<u32> = claims.iter().filter(|(_, k)| *k > back).map(|(id, _)| *id).collect();
    assert!(after.len() >= 3 && after.iter().all(|id| *id > seen_back), "{after:?} ({seen_back})");
}

/// What a robot heard of parts a queue's length behind the newest is forgotten: the ledger
/// stays bounded on a long run.
#[test]
fn what_was_heard_of_parts_long_gone_is_forgotten() {
    let mut run = Run::new(&[("west", 0.0)], u64::MAX);
    run.step(0);
    let r = &mut run.robots[0];
    let before = r.d.cell.as_ref().unwrap().realtime(run.t0.saturating_sub(MS));
    let n = QUEUE_CAPACITY as u32 + 2;
    for id in 1..=n {
        // Seen before its first read: let pass at once, so heard of.
        r.d.cell_message(&CellMsg::new(CellKind::Part, id, "", before));
    }
    let side = r.d.cell.as_ref().unwrap();
    let heard: Vec<bool> = [1, 2, n].iter().map(|id| side.ledger.passed_by(*id, "west")).collect();
    assert_eq!(heard, [false, true, true]);
}

/// Parts numbered between the newest a robot had and the one it hears of now were lost on
/// their way: it lets them pass at once and never claims them, even if they come later.
#[test]
fn parts_never_heard_of_are_let_pass_and_never_claimed() {
    let mut run = Run::new(&[("west", 0.0)], u64::MAX);
    let part = |run: &Run, id: u32, k: u64| {
        let side = run.robots[0].d.cell.as_ref().unwrap();
        CellMsg {
            belt_mm: 100.0,
            ..CellMsg::new(CellKind::Part, id, "", side.realtime(run.t0 + k * MS))
        }
    };
    for k in 0..3_000 {
        if k == 200 || k == 1_200 || k == 1_300 {
            let id = [1, 5, 3][usize::from(k > 200) + usize::from(k > 1_200)];
            let m = part(&run, id, k - 20);
            run.robots[0].inbox.push((k, m));
        }
        run.step(k);
    }
    let passed: Vec<u32> = said(&run.log, "west", CellKind::Passed).iter().map(|p| p.0).collect();
    assert_eq!(passed, [4, 3, 2], "the gap before part 5, at once, and once: {passed:?}");
    let claimed: Vec<u32> = said(&run.log, "west", CellKind::Claim).iter().map(|p| p.0).collect();
    assert_eq!(claimed, [1, 5], "part 3, let pass, came later: not claimed");
}

/// A claim older than its robot's word that it let the part pass (a ledger answer that came
/// late) is stale: it takes nothing from the robot that may claim the part now.
#[test]
fn a_claim_after_its_robots_pass_is_stale() {
    let mut run = Run::new(&[("east", 600.0)], u64::MAX);
    run.step(0);
    let r = &mut run.robots[0];
    r.d.cell_message(&CellMsg::new(CellKind::Passed, 9, "west", 10));
    r.d.cell_message(&CellMsg::new(CellKind::Claim, 9, "west", 5));
    let side = r.d.cell.as_ref().unwrap();
    assert!(side.ledger.claim_of(9).is_none() && side.ledger.passed_by(9, "west"));
}

/// As its session ends, a robot lets pass every part it had not claimed (once: one it had
/// said passed already is not said again) and gives up the one it was going for if its
/// gripper was not yet told to close: the robots downstream may take them at once. One on
/// its gripper is not given up.
#[test]
fn a_session_ending_lets_its_parts_go() {
    for into_pick_ms in [10, 160] {
        let mut run = Run::new(&[("west", 0.0)], 250);
        let mut going_for = None;
        for k in 0..3_000 {
            run.step(k);
            if let Some((id, from)) = run.robots[0].busy
                && k == from + into_pick_ms
                && k > 1_000
            {
                going_for = Some(id);
                break;
            }
        }
        let id = going_for.expect("a pick under way");
        let r = &mut run.robots[0];
        // The loop's events of this millisecond (the gripper told to close).
        r.d.look();
        let pending: Vec<u32> =
            r.d.queue
                .parts()
                .iter()
                .filter(|p| p.state == PartState::Pending)
                .map(|p| p.id)
                .collect();
        assert!(pending.len() >= 2, "{pending:?}");
        let side = r.d.cell.as_mut().unwrap();
        side.passed(pending[0], 0);
        side.outbox.clear();
        r.d.end_cell();
        let side = r.d.cell.as_mut().unwrap();
        let mut got: Vec<(Option<CellKind>, u32)> =
            side.outbox.drain(..).map(|m| (m.kind(), m.part)).collect();
        let mut want: Vec<(Option<CellKind>, u32)> =
            pending[1..].iter().map(|p| (Some(CellKind::Passed), *p)).collect();
        if into_pick_ms < 150 {
            want.push((Some(CellKind::Released), id));
        }
        want.sort_by_key(|(_, p)| *p);
        got.sort_by_key(|(_, p)| *p);
        assert_eq!(got, want, "{into_pick_ms} ms into the pick of {id}");
    }
}

/// Runs `run` for `ms` milliseconds, the first robot's picker giving up (out of reach) the
/// first pick it begins after `after_ms`, 20 ms into it: that part.
fn give_up_a_pick(run: &mut Run, after_ms: u64, ms: u64) -> u32 {
    let mut given_up = None;
    for k in 0..ms {
        if given_up.is_none()
            && k > after_ms
            && let Some((id, from)) = run.robots[0].busy
            && k == from + 20
        {
            let r = &mut run.robots[0];
            let _ = r.events.push(PickEvent::GaveUp { id, why: GaveUp::OutOfReach });
            r.busy = None;
            given_up = Some(id);
        }
        run.step(k);
    }
    given_up.expect("a pick under way")
}
