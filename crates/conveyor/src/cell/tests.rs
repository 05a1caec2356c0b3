//! The sharing rule: every part has one robot that may claim it at a time, the turns split
//! the parts evenly, what a robot says it lets pass goes on downstream (and only what it
//! says), and a lost robot's claims come back only when it could not have gripped them.

use super::*;

/// Robots along one belt, each window [300, 500] mm of its own belt, offset `offsets` mm
/// along the cell's.
fn cell_of(me: &str, robots: &[(&str, f64)]) -> Cell {
    let member = |(name, offset_mm): &(&str, f64)| Member {
        name: name.to_string(),
        offset_mm: *offset_mm,
        window_mm: [300.0, 500.0],
    };
    let mine = robots.iter().find(|(n, _)| *n == me).expect("me among them");
    let mut c = Cell::new(member(mine));
    for r in robots {
        c.join(member(r));
    }
    c
}

#[test]
fn the_members_are_ordered_downstream_first_and_take_turns() {
    let c = cell_of("a", &[("a", 0.0), ("b", 600.0), ("c", 1_200.0)]);
    assert_eq!(
        c.member("b").unwrap().reach_mm(),
        [900.0, 1_100.0],
        "its window on the cell's belt"
    );
    let names: Vec<&str> = c.members().iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["c", "b", "a"]);
    assert_eq!(c.me().name, "a");
    let homes: Vec<&str> = (1..=7).map(|id| c.home_of(id).name.as_str()).collect();
    assert_eq!(homes, ["c", "b", "a", "c", "b", "a", "c"]);
    // Equal windows: by name.
    let tie = cell_of("y", &[("y", 0.0), ("x", 0.0)]);
    assert_eq!(tie.members()[0].name, "x");
    // Alone, every part is its own.
    let alone = cell_of("a", &[("a", 0.0)]);
    assert!((1..50).all(|id| alone.home_of(id).name == "a"));
}

/// At most one robot may claim a part at a time: its home robot until it says it lets the
/// part pass, then each robot downstream in turn as every one before it has said so — and
/// a robot that has not heard a pass (a link cut silently) does not take the part.
#[test]
fn one_robot_at_a_time_may_claim_a_part_and_only_on_the_word() {
    let robots = [("a", 0.0), ("b", 600.0), ("c", 1_200.0)];
    let views: Vec<Cell> = robots.iter().map(|(n, _)| cell_of(n, &robots)).collect();
    let who = |id, said: &Ledger| -> Vec<String> {
        views.iter().filter(|v| v.may_claim(id, said)).map(|v| v.me.clone()).collect()
    };
    for id in 1..=6 {
        let home = views[0].home_of(id).name.clone();
        // Every robot hears every pass: the home robot, then each one downstream, then none.
        let mut said = Ledger::new();
        let mut holders = Vec::new();
        for m in views[0].members().iter().rev() {
            let now = who(id, &said);
            assert!(now.len() <= 1, "part {id}: {now:?}");
            holders.push(now.first().cloned().unwrap_or_else(|| "-".into()));
            said.passed(id, &m.name);
            assert_eq!(views[0].holder(id, &said).is_some(), m.name != "c", "part {id}");
        }
        holders.push(who(id, &said).first().cloned().unwrap_or_else(|| "-".into()));
        holders.dedup();
        let expected: Vec<&str> = match home.as_str() {
            "a" => vec!["a", "b", "c", "-"],
            "b" => vec!["b", "c", "-"],
            _ => vec!["c", "-"],
        };
        assert_eq!(holders, expected, "part {id}, home {home}");
    }
    let id = 3; // a's
    assert_eq!(views[0].home_of(id).name, "a");
    // b and c heard nothing from a (it claimed, or let pass, unheard): a's still.
    let mut said = Ledger::new();
    said.passed(id, "b");
    assert_eq!(who(id, &said), ["a"]);
    // c heard b let it pass but not a: not c's.
    assert!(!views[2].may_claim(id, &said));
    said.passed(id, "a");
    assert_eq!(who(id, &said), ["c"]);
    // A pick given up lets the part pass too.
    let mut given_up = Ledger::new();
    given_up.claim(id, claim("a", 10, 20));
    assert!(given_up.release(id, "a"));
    assert_eq!(who(id, &given_up), ["b"]);
    assert!(given_up.passed_by(id, "a") && !given_up.passed_by(id, "b"));
    assert!(!given_up.passed_by(id + 1, "a"), "that part only");
}

#[test]
fn a_part_let_pass_is_handed_on_while_a_robot_downstream_can_reach_it() {
    let robots = [("a", 0.0), ("b", 600.0)];
    let (a, b) = (cell_of("a", &robots), cell_of("b", &robots));
    // Past a's window (500) and inside b's (900–1100): handed on. Past b's: missed.
    assert!(a.handed_on(510.0));
    assert!(a.handed_on(1_100.0), "a window includes its end");
    assert!(!a.handed_on(1_100.5));
    assert!(!b.handed_on(1_000.0), "the last robot misses what it lets pass");
    // A robot whose window ends where this one's does is not downstream of it.
    let twins = cell_of("x", &[("x", 0.0), ("y", 0.0)]);
    assert!(!twins.handed_on(450.0));
}

#[test]
fn a_robot_lost_leaves_its_turns_to_the_others_and_one_back_rejoins() {
    let robots = [("a", 0.0), ("b", 600.0)];
    let mut b = cell_of("b", &robots);
    assert_eq!((b.home_of(1).name.as_str(), b.home_of(2).name.as_str()), ("b", "a"));
    assert!(b.leave("a"));
    assert!(!b.leave("a"), "gone already");
    assert!(!b.leave("b"), "never itself");
    let none = Ledger::new();
    assert!((1..20).all(|id| b.may_claim(id, &none)), "every part is b's now");
    b.join(Member { name: "a".into(), offset_mm: 0.0, window_mm: [300.0, 500.0] });
    assert_eq!(b.home_of(2).name, "a", "back: its turns again");
    assert!(!b.may_claim(2, &none) && b.may_claim(1, &none));
}

fn claim(robot: &str, at_ns: u64, grip_by_ns: u64) -> Claim {
    Claim { robot: robot.into(), at_ns, grip_by_ns, picked: false }
}

/// Should two claims of one part ever cross, every robot keeps the same one: the earlier,
/// then the name; a picked part is never taken back.
#[test]
fn two_claims_of_one_part_end_as_one_whatever_the_order_seen() {
    let (early, late) = (claim("b", 100, 900), claim("a", 200, 800));
    let mut one = Ledger::new();
    assert!(one.claim(7, early.clone()));
    assert!(!one.claim(7, late.clone()), "a later claim loses");
    let mut other = Ledger::new();
    assert!(other.claim(7, late.clone()));
    assert!(other.claim(7, early.clone()), "an earlier one wins");
    assert_eq!(one.claim_of(7), other.claim_of(7));
    assert_eq!(one.claim_of(7).unwrap().robot, "b");
    // Equal times: the name first in order.
    let mut tie = Ledger::new();
    tie.claim(8, claim("b", 100, 900));
    assert!(tie.claim(8, claim("a", 100, 900)));
    assert_eq!(tie.claim_of(8).unwrap().robot, "a");
    // A robot that claims anew (a later grip) holds it still, and a pick is not undone.
    assert!(one.claim(7, claim("b", 300, 950)));
    assert_eq!(one.claim_of(7).unwrap().grip_by_ns, 950);
    one.picked(7, "b", 960);
    assert!(one.claim(7, claim("b", 400, 990)));
    assert!(one.claim_of(7).unwrap().picked, "still picked");
    // Picked: its robot's for good.
    let mut done = Ledger::new();
    done.picked(9, "c", 500);
    assert!(!done.claim(9, claim("a", 1, 2)));
    assert!(done.claim_of(9).unwrap().picked);
}

#[test]
fn a_lost_robot_releases_only_the_claims_it_could_not_have_gripped() {
    let mut l = Ledger::new();
    l.claim(1, claim("a", 100, 1_000)); // to grip before a was seen gone: it may have
    l.claim(2, claim("a", 150, 3_000)); // after: it cannot have
    l.claim(3, claim("b", 160, 3_000)); // another robot's
    l.picked(4, "a", 1_200); // off the belt
    l.claim(5, claim("a", 170, 2_500));
    l.claim(6, claim("a", 180, 2_000)); // to grip as it was seen gone: it may have
    assert_eq!(l.lost("a", 2_000), [2, 5]);
    assert!(l.claim_of(6).is_some());
    assert!(l.claim_of(2).is_none() && l.claim_of(5).is_none());
    assert_eq!(l.claim_of(1).unwrap().robot, "a", "may have been gripped: kept");
    assert_eq!(l.claim_of(3).unwrap().robot, "b");
    assert!(l.claim_of(4).unwrap().picked);
    // A pick given up releases the claim; one picked stays.
    assert!(l.release(3, "b"));
    assert!(!l.release(3, "b"));
    assert!(!l.release(4, "a"));
    assert!(l.passed_by(3, "b"), "given up: let pass");
    l.passed(4, "b");
    l.passed(4, "b");
    l.forget(|id| id < 4);
    assert!(l.claim_of(1).is_none() && l.claim_of(4).is_some());
    assert!(!l.passed_by(3, "b") && l.passed_by(4, "b"), "forgotten with its part");
}
