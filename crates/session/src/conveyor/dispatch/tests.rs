//! Two robots' dispatchers on one belt, wired to each other as the cell wires them (each
//! one's messages reach the other a few milliseconds later), a stand-in loop picking what each
//! is handed: every part the camera saw is picked once, by one robot, the two splitting the
//! work; a robot lost leaves the survivor its share and the claims it could not have gripped.

use super::*;
use crate::conveyor::picker::PickerShared;
use qmarc_proto::cell::{CellKind, CellMsg};
use qmarc_proto::state::Phase;
use rtrb::{Consumer, Producer, RingBuffer};
use std::path::Path;

/// One millisecond, the dispatcher's poll.
const MS: u64 = 1_000_000;

/// A robot of the cell: its dispatcher, and the loop standing in for its picker.
struct Robot {
    name: &'static str,
    d: Dispatch,
    status: Arc<LoopStatus>,
    picks: Consumer<Pick>,
    events: Producer<PickEvent>,
    shared: Arc<PickerShared>,
    /// The pick under way and the millisecond it is done.
    busy: Option<(u32, u64)>,
    picked: Vec<u32>,
    /// Messages on their way to it: due at a millisecond.
    inbox: Vec<(u64, CellMsg)>,
    alive: bool,
}

/// The shipped settings for a robot `name` whose belt begins `offset_mm` along the cell's.
fn robot(name: &'static str, offset_mm: f64, t0: u64) -> Robot {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
    let mut s = Settings::load(&path, &qmarc_config::Names::any()).unwrap();
    s.cell.robot = name.into();
    s.cell.belt_offset_mm = offset_mm;
    s.set_cell("belt", None).unwrap();
    let status = Arc::new(LoopStatus::default());
    status.set_phase(Phase::Moving);
    let place = BeltFrame::of(&s).unwrap().counts_at_mm(s.conveyor.place_mm).unwrap();
    status.set_command(&place);
    let (picks_tx, picks) = RingBuffer::new(2);
    let (events, events_rx) = RingBuffer::new(256);
    let shared = Arc::new(PickerShared::default());
    shared.ready.store(true, Ordering::Release);
    let handle = PickerHandle {
        picks: picks_tx,
        events: events_rx,
        shared: shared.clone(),
        tally: Arc::default(),
    };
    let d = Dispatch::new(&s, (t0, false), handle, status.clone()).unwrap();
    let (busy, picked, inbox) = (None, vec![], vec![]);
    Robot { name, d, status, picks, events, shared, busy, picked, inbox, alive: true }
}

/// The belt: 500 mm/s, 0.05 mm a count: 10 counts a millisecond.
fn counts_at_ms(k: u64) -> i64 {
    k as i64 * 10
}

/// The cell: the robots, the camera upstream at 100 mm of the cell's belt seeing a part every
/// `every_ms`, across alternately ±30 mm. Runs `ms` milliseconds; `kill` takes a robot out
/// at a millisecond (its messages stop; the others hear it gone `gone_after_ms` later).
struct Run {
    robots: Vec<Robot>,
    every_ms: u64,
    t0: u64,
    seen: u32,
    /// Milliseconds in which the second robot's host is cut off (its link down, shorter than
    /// the lease: no token goes): nothing said reaches it or comes from it, nor the parts.
    cut: std::ops::Range<u64>,
    /// Everything the robots said: the millisecond, by whom, what.
    log: Vec<(u64, &'static str, CellMsg)>,
    /// Each robot hears its own word back too (a companion that would echo it).
    echo: bool,
}

impl Run {
    fn new(robots: &[(&'static str, f64)], every_ms: u64) -> Run {
        let t0 = qmarc_timer::clock::monotonic_now_ns();
        let mut robots: Vec<Robot> = robots.iter().map(|(n, o)| robot(n, *o, t0)).collect();
        // Each hears of the others as its companion tells it: their windows and offsets.
        let members: Vec<CellMsg> = robots
            .iter()
            .map(|r| {
                let side = r.d.cell.as_ref().unwrap();
                let me = side.cell.me();
                let mut m = CellMsg::new(CellKind::Member, 0, &me.name, 0);
                (m.belt_mm, m.window_mm) = (me.offset_mm, me.window_mm);
                m
            })
            .collect();
        for r in &mut robots {
            r.inbox.extend(members.iter().map(|m| (0, *m)));
            // Its companion says it is in the cell, the others had.
            r.inbox.push((0, CellMsg::new(CellKind::Rejoined, 0, r.name, 0)));
        }
        Run { robots, every_ms, t0, seen: 0, cut: 0..0, log: Vec::new(), echo: false }
    }

    /// Millisecond `k`: the loops read the belt, the camera says a part (20 ms after its
    /// exposure), the messages due arrive, each dispatcher looks, and what it says reaches
    /// the others 3 ms later.
    fn step(&mut self, k: u64) {
        let ns = self.t0 + k * MS;
        for r in self.robots.iter_mut().filter(|r| r.alive) {
            r.status.set_belt(counts_at_ms(k), ns, k);
        }
        // From 120 ms: a part exposed before a robot's first read of the belt is not placed.
        if k >= 120 && (k - 120).is_multiple_of(self.every_ms) {
            self.seen += 1;
            let exposure = ns - 20 * MS;
            let wall = self.robots[0].d.cell.as_ref().unwrap().realtime(exposure);
            let mut m = CellMsg::new(CellKind::Part, self.seen, "", wall);
            m.belt_mm = 100.0;
            m.across_mm = if self.seen.is_multiple_of(2) { 30.0 } else { -30.0 };
            let cut = self.cut.contains(&k);
            for (i, r) in self.robots.iter_mut().enumerate() {
                if !(cut && i == 1) {
                    r.inbox.push((k, m));
                }
            }
        }
        let mut said = Vec::new();
        for r in self.robots.iter_mut().filter(|r| r.alive) {
            let (due, later): (Vec<_>, Vec<_>) = r.inbox.drain(..).partition(|(at, _)| *at <= k);
            r.inbox = later;
            for (_, m) in due {
                r.d.cell_message(&m);
            }
            r.d.look();
            said.extend(r.d.cell.as_mut().unwrap().outbox.drain(..).map(|m| (r.name, m)));
            r.run_loop(k);
        }
        self.log.extend(said.iter().map(|(from, m)| (k, *from, *m)));
        if self.cut.contains(&k) {
            said.clear();
        }
        for (from, m) in said {
            for r in self.robots.iter_mut().filter(|r| self.echo || r.name != from) {
                r.inbox.push((k + 3, m));
            }
        }
    }

    /// Robot `name` dies at millisecond `k`; the others see its token go `after_ms` later.
    fn kill(&mut self, name: &str, k: u64, after_ms: u64) {
        let wall = self.robots[0].d.cell.as_ref().unwrap().realtime(self.t0 + k * MS);
        for r in &mut self.robots {
            if r.name == name {
                r.alive = false;
            } else {
                r.inbox.push((k + after_ms, CellMsg::new(CellKind::Gone, 0, name, wall)));
            }
        }
    }
}

impl Robot {
    /// The loop standing in for the picker: a pick takes 150 ms to the grip, 50 ms more to
    /// lift the part, and 200 ms more to the place and back.
    fn run_loop(&mut self, k: u64) {
        match self.busy {
            None => {
                if let Ok(p) = self.picks.pop() {
                    let _ = self.events.push(PickEvent::Intercepting { id: p.id, cycle: k });
                    self.busy = Some((p.id, k));
                }
            }
            // Another robot has it, before the gripper was told to close: given up.
            Some((id, from))
                if k < from + 150 && self.shared.cancel.load(Ordering::Acquire) == id =>
            {
                let _ = self.events.push(PickEvent::GaveUp { id, why: GaveUp::Elsewhere });
                self.busy = None;
            }
            Some((id, from)) if k == from + 150 => {
                let _ = self.events.push(PickEvent::Gripping { id, cycle: k });
            }
            Some((id, from)) if k == from + 200 => {
                let _ = self.events.push(PickEvent::Lifted { id });
                self.picked.push(id);
            }
            Some((id, from)) if k >= from + 400 => {
                let _ = self.events.push(PickEvent::Placed { id, cycle: k });
                self.busy = None;
            }
            Some(_) => {}
        }
    }

    /// The states its records end with, by part.
    fn states(self) -> Vec<(u32, &'static str, Option<String>)> {
        self.d.finish().parts.into_iter().map(|p| (p.id, p.state, p.by)).collect()
    }
}

/// Two robots, a part every 250 ms (240 a minute, one robot's most): each picks every other
/// part, none twice, none missed; each one's records list the other's picks as passed, with
/// the same ids.
#[test]
fn two_robots_split_a_belts_parts_and_none_is_picked_twice() {
    let mut run = Run::new(&[("west", 0.0), ("east", 600.0)], 250);
    // 12 s of parts, and 3 s for the last to pass both windows.
    for k in 0..15_000 {
        if k == 12_000 {
            run.every_ms = u64::MAX;
        }
        run.step(k);
    }
    let seen = run.seen;
    assert!(seen >= 47, "{seen} parts");
    let (west, east) = (run.robots.remove(0), run.robots.remove(0));
    let mut all: Vec<u32> = west.picked.iter().chain(&east.picked).copied().collect();
    all.sort_unstable();
    let expected: Vec<u32> = (1..=seen).collect();
    assert_eq!(
        all, expected,
        "every part picked once: west {:?} east {:?}",
        west.picked, east.picked
    );
    // The turns: east (downstream) the odd parts, west the even ones.
    assert!(east.picked.iter().all(|id| id % 2 == 1), "{:?}", east.picked);
    assert!(west.picked.iter().all(|id| id % 2 == 0), "{:?}", west.picked);
    let (west_picks, east_picks) = (west.picked.clone(), east.picked.clone());
    for (robot, mine, states) in
        [("west", west_picks, west.states()), ("east", east_picks, east.states())]
    {
        assert_eq!(states.len(), seen as usize, "{robot} lists every part");
        for (id, state, by) in states {
            let want = if mine.contains(&id) { "picked" } else { "passed" };
            assert_eq!(state, want, "{robot}: part {id}");
            let picker = if id % 2 == 1 { "east" } else { "west" };
            assert_eq!(by.as_deref(), Some(picker), "{robot}: part {id}");
        }
    }
}

/// The upstream robot killed mid-run: the survivor, seen it gone 50 ms later, takes every
/// part from then on, the claims the dead one could not have gripped among them; the parts
/// missed are only those that had passed the survivor's reach.
#[test]
fn a_robot_lost_leaves_its_share_and_its_ungripped_claims_to_the_other() {
    // A part every 500 ms: one robot alone picks them all.
    let mut run = Run::new(&[("west", 0.0), ("east", 600.0)], 500);
    let mut intercepting = None;
    for k in 0..16_000 {
        // Killed 10 ms into an intercept: a claim it cannot have gripped.
        if let (None, Some((id, from))) = (intercepting, run.robots[0].busy)
            && k >= 6_000
            && k == from + 10
        {
            run.kill("west", k, 50);
            intercepting = Some(id);
        }
        if k == 12_000 {
            run.every_ms = u64::MAX;
        }
        run.step(k);
    }
    let seen = run.seen;
    let (west, east) = (run.robots.remove(0), run.robots.remove(0));
    assert!(!west.picked.is_empty(), "west picked before it died");
    let released = intercepting.expect("west was killed");
    assert!(!west.picked.contains(&released));
    assert!(east.picked.contains(&released), "west's claim released to east: {released}");
    let mut all: Vec<u32> = west.picked.iter().chain(&east.picked).copied().collect();
    all.sort_unstable();
    all.dedup();
    assert_eq!(all.len(), west.picked.len() + east.picked.len(), "none twice");
    // After the death, every part is east's: all picked.
    let after: Vec<u32> = (1..=seen).filter(|id| !all.contains(id)).collect();
    assert!(after.len() <= 1, "lost: {after:?} (west {:?}, east {:?})", west.picked, east.picked);
    let states = east.states();
    let missed: Vec<u32> =
        states.iter().filter(|(_, s, _)| *s == "missed").map(|(id, _, _)| *id).collect();
    assert_eq!(missed, after, "east misses only what it could not reach");
}

/// Two claims of one part that crossed: the robot whose claim was the later gives the part
/// up if its gripper has not been told to close (it is the other's, passed here); so does a
/// robot that hears another picked the part it is going for.
#[test]
fn a_claim_that_loses_ends_the_pick_before_the_grip() {
    for kind in [CellKind::Claim, CellKind::Picked] {
        let mut run = Run::new(&[("east", 600.0)], 500);
        let mut crossed = None;
        for k in 0..6_000 {
            // 20 ms into its first intercept, word comes that west had claimed (or picked)
            // that part first.
            if let (None, Some((id, from))) = (crossed, run.robots[0].busy)
                && k == from + 20
            {
                let side = run.robots[0].d.cell.as_ref().unwrap();
                let earlier = side.ledger.claim_of(id).unwrap().at_ns - 1;
                let mut m = CellMsg::new(kind, id, "west", earlier);
                m.grip_by_ns = earlier + 200 * MS;
                run.robots[0].inbox.push((k, m));
                crossed = Some(id);
            }
            run.step(k);
        }
        let id = crossed.expect("an intercept");
        let east = run.robots.remove(0);
        assert!(!east.picked.contains(&id), "{kind:?}: given up");
        assert!(east.picked.len() >= 8, "{kind:?}: and the others picked: {:?}", east.picked);
        let records = east.d.finish();
        let r = records.parts.iter().find(|p| p.id == id).unwrap();
        assert_eq!((r.state, r.gave_up), ("passed", Some(GaveUp::Elsewhere)), "{kind:?}");
        if kind == CellKind::Claim {
            assert_eq!(records.cell.unwrap().conflicts, 1);
        }
    }
}

mod word;
