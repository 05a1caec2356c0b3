//! The dispatcher in a cell (issue 47, docs/cell.md): the parts come from the cell's camera
//! (numbered there, the same numbers on every robot), a part is claimed only when the sharing
//! rule ([`qmarc_conveyor::cell`]) says it is this robot's to take, every claim, pick and
//! give-up is said to the cell before the loop acts on it, every part it will not take is
//! said to pass, and the others' word is taken in.
//! The messages come and go through the companion that holds the cell's Zenoh session
//! ([`qmarc_proto::cell`]); the dispatcher never waits for them.

use super::{Dispatch, PartRecord};
use qmarc_config::Settings;
use qmarc_conveyor::Detection;
use qmarc_conveyor::PartState;
use qmarc_conveyor::cell::{Cell, Claim, Ledger, Member};
use qmarc_proto::cell::{CellKind, CellMsg};

/// Most parts let pass at once for a gap in the camera's numbers (a message lost): a robot
/// that missed more than that missed the cell.
const MAX_SKIPPED: usize = 64;

/// The dispatcher's side of the cell.
pub(crate) struct CellSide {
    /// The cell's name.
    pub name: String,
    /// The robots alive as this one sees them.
    pub cell: Cell,
    /// The claims and passes heard, this robot's among them.
    pub ledger: Ledger,
    /// This robot's belt coordinate 0 on the cell's belt, mm.
    pub offset_mm: f64,
    /// The system clock minus the monotonic one, ns.
    pub realtime_offset_ns: i64,
    /// What to tell the cell, sent after each look.
    pub outbox: Vec<CellMsg>,
    /// Claims of this robot that an earlier claim of another's beat (its pick went on).
    pub conflicts: u64,
    /// How this robot stands in the cell: it claims nothing until its companion says it is
    /// in (the others and their claims had), nor while it is cut off (it goes on with what it
    /// claimed).
    pub link: Link,
    /// The highest part number heard of, 0: none yet.
    pub newest: u32,
    /// After an outage (cut off, then back): parts seen before it ended, ns of
    /// `CLOCK_MONOTONIC` (the loop's time), are no longer claimed — the others may have
    /// claimed or picked them meanwhile, unheard. 0: none.
    pub fresh_after_ns: u64,
}

/// How a robot stands in its cell.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Link {
    /// Not yet told the others: it claims nothing (its turns would be wrong).
    Waiting,
    /// In the cell: the sharing rule, hand-offs and all.
    In,
    /// Cut off from it: it goes on with what it claimed, and claims nothing.
    CutOff,
}

/// What a cell session counts, for its summary.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct CellTally {
    /// The cell's name.
    pub name: String,
    /// This robot's.
    pub robot: String,
    /// Claims of this robot that an earlier claim beat.
    pub conflicts: u64,
}

impl CellSide {
    /// The cell side of settings `s`, if they join a cell (`--cell`).
    pub fn of(s: &Settings) -> Option<CellSide> {
        let name = s.cell.name.clone()?;
        let me = Member {
            name: s.cell.robot.clone(),
            offset_mm: s.cell.belt_offset_mm,
            window_mm: s.conveyor.window_mm,
        };
        // Said first: this robot takes its turns from now (before, it could not let pass
        // what it would not take, so the others did not count it in).
        let mut ready = CellMsg::new(CellKind::Member, 0, &me.name, 0);
        (ready.belt_mm, ready.window_mm) = (me.offset_mm, me.window_mm);
        Some(CellSide {
            name,
            cell: Cell::new(me),
            ledger: Ledger::new(),
            offset_mm: s.cell.belt_offset_mm,
            realtime_offset_ns: qmarc_timer::clock::realtime_offset_ns(),
            outbox: vec![ready],
            conflicts: 0,
            link: Link::Waiting,
            newest: 0,
            fresh_after_ns: 0,
        })
    }

    /// This robot's name.
    pub fn me(&self) -> &str {
        &self.cell.me().name
    }

    /// Monotonic `ns` on the system clock.
    pub fn realtime(&self, ns: u64) -> u64 {
        (ns as i64).saturating_add(self.realtime_offset_ns).max(0) as u64
    }

    /// System-clock `ns` on this host's monotonic clock.
    pub fn monotonic(&self, ns: u64) -> u64 {
        (ns as i64).saturating_sub(self.realtime_offset_ns).max(0) as u64
    }

    /// Whether this robot may claim part `id`, first seen at `seen_ns` (monotonic): in the
    /// cell, its turn by the sharing rule (its home, or let pass by every robot from its home
    /// to this one), not a part it said it let pass, and not a part from before an outage.
    pub fn may_claim(&self, id: u32, seen_ns: u64) -> bool {
        self.link == Link::In
            && seen_ns >= self.fresh_after_ns
            && !self.ledger.passed_by(id, self.me())
            && self.cell.may_claim(id, &self.ledger)
    }

    /// What becomes of a part past this robot's window, `at_mm` along its own belt: passed
    /// on while a robot downstream can reach it, else missed.
    pub fn fate(&self, at_mm: f64) -> PartState {
        if self.cell.handed_on(at_mm + self.offset_mm) {
            PartState::Elsewhere
        } else {
            PartState::Missed
        }
    }

    /// Tells the cell `kind` of part `id` at monotonic `now`.
    fn say(&mut self, kind: CellKind, id: u32, now: u64) -> &mut CellMsg {
        let m = CellMsg::new(kind, id, &self.cell.me().name, self.realtime(now));
        self.outbox.push(m);
        self.outbox.last_mut().expect("just pushed")
    }

    /// This robot claims part `id` at monotonic `now`, its gripper to close `grip_in_ns`
    /// later.
    pub fn claim(&mut self, id: u32, now: u64, grip_in_ns: u64) {
        let m = self.say(CellKind::Claim, id, now);
        m.grip_by_ns = m.t_ns.saturating_add(grip_in_ns);
        let c = claim_in(m);
        self.ledger.claim(id, c);
    }

    /// This robot picked part `id` (off the belt) at monotonic `now`.
    pub fn picked(&mut self, id: u32, now: u64) {
        let t = self.say(CellKind::Picked, id, now).t_ns;
        let me = self.me().to_string();
        self.ledger.picked(id, &me, t);
    }

    /// This robot lets part `id` pass (it will not claim it) at monotonic `now`.
    pub fn passed(&mut self, id: u32, now: u64) {
        self.say(CellKind::Passed, id, now);
        let me = self.me().to_string();
        self.ledger.passed(id, &me);
    }

    /// This robot gave part `id` up at monotonic `now` (and so lets it pass).
    pub fn released(&mut self, id: u32, now: u64) {
        self.say(CellKind::Released, id, now);
        let me = self.me().to_string();
        self.ledger.release(id, &me);
    }

    /// The robot that picked part `id`, if one did.
    pub fn picked_by(&self, id: u32) -> Option<&str> {
        self.ledger.claim_of(id).filter(|c| c.picked).map(|c| c.robot.as_str())
    }

    /// The tally for the summary.
    pub fn tally(&self) -> CellTally {
        CellTally {
            name: self.name.clone(),
            robot: self.me().to_string(),
            conflicts: self.conflicts,
        }
    }
}

/// The claim a [`CellKind::Claim`] message says.
fn claim_in(m: &CellMsg) -> Claim {
    Claim { robot: m.robot().to_string(), at_ns: m.t_ns, grip_by_ns: m.grip_by_ns, picked: false }
}

impl Dispatch {
    /// A message from the cell.
    pub(crate) fn cell_message(&mut self, m: &CellMsg) {
        let now_ns = self.loop_now_ns();
        let Some(side) = self.cell.as_mut() else { return };
        let robot = m.robot();
        let kind = m.kind();
        // Its own word back changes nothing (its companion's word on the link is its own).
        if robot == side.me() && !matches!(kind, Some(CellKind::CutOff | CellKind::Rejoined)) {
            return;
        }
        match kind {
            Some(CellKind::Part) => self.cell_part(m),
            Some(CellKind::Member) => side.cell.join(Member {
                name: robot.to_string(),
                offset_mm: m.belt_mm,
                window_mm: m.window_mm,
            }),
            Some(CellKind::Gone) => {
                side.cell.leave(robot);
                for id in side.ledger.lost(robot, m.t_ns) {
                    self.queue.release(id);
                }
            }
            // A claim older than that robot's word that it let the part pass (an answer to
            // a ledger question that came late) is stale.
            Some(CellKind::Claim) if !side.ledger.passed_by(m.part, robot) => {
                let c = claim_in(m);
                let held = side.ledger.claim_of(m.part).map(|c| c.robot == side.me());
                let was_mine = held == Some(true);
                // A claim said again (after an outage) is not a new one.
                let new_holder = side.ledger.claim_of(m.part).is_none_or(|c| c.robot != robot);
                if side.ledger.claim(m.part, c) {
                    if was_mine {
                        side.conflicts += 1;
                        self.cancel(m.part);
                    }
                    self.queue.elsewhere(m.part);
                    if new_holder {
                        self.claim_seen(m.part);
                    }
                }
            }
            Some(CellKind::Picked) => {
                side.ledger.picked(m.part, robot, m.t_ns);
                self.cancel(m.part);
                self.queue.elsewhere(m.part);
            }
            Some(CellKind::Released) if side.ledger.release(m.part, robot) => {
                self.queue.release(m.part);
            }
            Some(CellKind::Passed) => side.ledger.passed(m.part, robot),
            Some(CellKind::CutOff) => side.link = Link::CutOff,
            Some(CellKind::Rejoined) => {
                if side.link == Link::CutOff {
                    side.fresh_after_ns = now_ns;
                }
                side.link = Link::In;
            }
            // A kind this build does not know, a stale claim, a release of a claim not held.
            _ => {}
        }
    }

    /// Part `id`'s claim by a new holder is seen here now: from its exposure, into its
    /// record (a claim given up and taken by another robot: the later one's).
    pub(super) fn claim_seen(&mut self, id: u32) {
        let Some(exposure) = self.queue.part(id).map(|p| p.seen.t_ns) else { return };
        let now = qmarc_timer::clock::monotonic_now_ns();
        if let Some(r) = self.record(id) {
            r.claimed_after_ns = Some(now.saturating_sub(exposure));
        }
    }

    /// Another robot has part `id`: the picker gives it up if it is the one it has and its
    /// gripper has not been told to close on it (once told, the pick goes on: the two claims
    /// crossed too late, counted in `conflicts`).
    fn cancel(&mut self, id: u32) {
        let gripping = self.record(id).is_some_and(|r| r.grip_cycle.is_some());
        if self.given == Some(id) && !gripping {
            self.handle.shared.cancel.store(id, std::sync::atomic::Ordering::Release);
        }
    }

    /// A part the cell's camera saw: on this robot's belt, its encoder count at the exposure
    /// from the loop's own reads. One it cannot take is let pass at once: seen before this
    /// session could place it (no read yet that far back), or not taken into a full queue;
    /// and so are the parts numbered between the newest it had and this one, which it never
    /// heard of (a message lost) — the robots downstream may take them.
    fn cell_part(&mut self, m: &CellMsg) {
        let now = self.loop_now_ns();
        let Some(side) = self.cell.as_mut() else { return };
        // What it has heard of parts the queue no longer holds is done with.
        let old = m.part.saturating_sub(super::QUEUE_CAPACITY as u32);
        side.ledger.forget(|id| id < old);
        if side.newest > 0 {
            let skipped = side.newest.saturating_add(1)..m.part;
            for id in skipped.rev().take(MAX_SKIPPED).filter(|id| self.queue.part(*id).is_none()) {
                side.passed(id, now);
            }
        }
        side.newest = side.newest.max(m.part);
        let exposure = side.monotonic(m.t_ns);
        let counts = super::counts_at(&self.history, exposure);
        let Some(latched_counts) = counts else {
            if !side.ledger.passed_by(m.part, side.me()) {
                side.passed(m.part, now);
            }
            return;
        };
        let seen = Detection {
            t_ns: exposure,
            latched_counts,
            belt_mm: m.belt_mm - side.offset_mm,
            across_mm: m.across_mm,
        };
        if self.queue.part(m.part).is_some() {
            return;
        }
        if self.queue.insert(m.part, seen) {
            self.detections += 1;
            let record = self.new_record(m.part, &seen);
            self.records.push(record);
        } else {
            side.passed(m.part, now);
        }
    }

    /// The session ends: every part it had not claimed is let pass, and the one it had
    /// claimed and not begun to grip is given up — the robots downstream may take them now
    /// rather than once this robot is seen gone.
    pub(super) fn end_cell(&mut self) {
        let at = self.loop_now_ns();
        let Some(side) = self.cell.as_mut() else { return };
        for p in self.queue.parts() {
            let gripping =
                || self.records.iter().rev().any(|r| r.id == p.id && r.grip_cycle.is_some());
            match p.state {
                PartState::Pending if !side.ledger.passed_by(p.id, side.me()) => {
                    side.passed(p.id, at);
                }
                PartState::Claimed if !gripping() => side.released(p.id, at),
                _ => {}
            }
        }
    }

    /// The cell's side of the records at the end: who picked each part.
    pub(crate) fn cell_records(&self, records: &mut [PartRecord]) {
        if let Some(side) = &self.cell {
            for r in records {
                r.by = side.picked_by(r.id).map(str::to_string);
            }
        }
    }
}
