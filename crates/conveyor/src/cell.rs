//! A cell of robots on one belt (issue 47): which robot takes which part, as each robot
//! decides it alone from what it knows of the others — the members alive and their windows
//! ([`Cell`]) and what they said of the parts ([`Ledger`]: their claims, picks and the parts
//! they let pass). Plain data and arithmetic; unlike the queue it allocates (names, the
//! claims seen): the dispatcher uses it, never the loop.
//!
//! The sharing rule, in belt coordinates of the cell (a robot's own plus its
//! `[cell] belt_offset_mm`):
//!
//! - **Every part has a home**: the robots alive, ordered downstream first (by where their
//!   windows end), take the parts in turn by the camera's part number — part 1 the most
//!   downstream robot's, part 2 the next one's… Two robots each get every other part: the
//!   work splits evenly whatever the rate, and an upstream robot leaves the downstream one its
//!   share instead of taking all it can reach.
//! - **The hand-off is said, never assumed**: a part is its home robot's until that robot
//!   says it let the part pass (it left its window unclaimed, it gave its pick up, or it
//!   could not place the part at all); then the next robot downstream's, until that one says
//!   so too; and so on ([`Cell::holder`]). A robot claims a part not of its turn only when
//!   every robot from the part's home to it has said it let it pass: a claim unheard (a
//!   network cut silently) leaves the part with the robot that claimed it, never with two.
//!   A robot says a part passed only once it will not claim it, and says its claims in the
//!   same stream before, so a pass heard is never followed by that robot's claim.
//! - **A robot claims only what it can grip inside its window** (the dispatcher's intercept
//!   check), and a part that leaves its window unclaimed is handed on to a robot downstream
//!   that can still reach it ([`Cell::handed_on`]) — missed only by the last robot that
//!   could.
//! - **A robot lost releases its claims**: those whose grip was still to come when it was
//!   seen gone ([`Ledger::lost`]), and its share goes to the others (the turn is among the
//!   robots alive: the parts whose home it was have a new home). A robot cut off from the
//!   cell (it sees no camera) is not lost to itself: it goes on with what it claimed and
//!   claims nothing new (what the others claim meanwhile it cannot know, nor they its
//!   claims); the others see it gone only after the session's lease, which must outlast a
//!   claim (claim to grip), so that none of its claims is released while it may still grip.

use std::collections::BTreeMap;

/// A robot of the cell, as the sharing rule sees it.
#[derive(Debug, Clone, PartialEq)]
pub struct Member {
    /// Its name, `[cell] robot`.
    pub name: String,
    /// Where its belt coordinate 0 lies on the cell's belt, mm (`[cell] belt_offset_mm`).
    pub offset_mm: f64,
    /// Its pick window in its own belt coordinates, mm (`conveyor.window_mm`).
    pub window_mm: [f64; 2],
}

impl Member {
    /// Its window on the cell's belt, mm.
    pub fn reach_mm(&self) -> [f64; 2] {
        [self.window_mm[0] + self.offset_mm, self.window_mm[1] + self.offset_mm]
    }

    /// The order of the cell, downstream first: the window that ends farther along, then
    /// the name.
    fn downstream_of(&self, other: &Member) -> std::cmp::Ordering {
        other.reach_mm()[1].total_cmp(&self.reach_mm()[1]).then_with(|| self.name.cmp(&other.name))
    }
}

/// The cell as one robot (`me`) sees it: the robots alive, downstream first.
#[derive(Debug, Clone, PartialEq)]
pub struct Cell {
    me: String,
    members: Vec<Member>,
}

impl Cell {
    /// The cell of `me` alone.
    pub fn new(me: Member) -> Cell {
        Cell { me: me.name.clone(), members: vec![me] }
    }

    /// The robots alive, downstream first.
    pub fn members(&self) -> &[Member] {
        &self.members
    }

    /// This robot.
    pub fn me(&self) -> &Member {
        self.member(&self.me).unwrap_or(&self.members[0])
    }

    /// The robot named `name`, if alive.
    pub fn member(&self, name: &str) -> Option<&Member> {
        self.members.iter().find(|m| m.name == name)
    }

    /// `m` is alive (joined, or its window said anew).
    pub fn join(&mut self, m: Member) {
        self.members.retain(|o| o.name != m.name);
        self.members.push(m);
        self.members.sort_by(Member::downstream_of);
    }

    /// The robot `name` is gone; false if it was not alive (or is this robot).
    pub fn leave(&mut self, name: &str) -> bool {
        let before = self.members.len();
        self.members.retain(|m| m.name != name || m.name == self.me);
        self.members.len() != before
    }

    /// Part `id`'s home robot: the robots alive take turns, the most downstream first.
    pub fn home_of(&self, id: u32) -> &Member {
        let n = self.members.len() as u64;
        &self.members[((u64::from(id) + n - 1) % n) as usize]
    }

    /// The robot whose part `id` is now, by what `said` holds: its home robot until that one
    /// has let it pass, then each robot downstream in turn until it has too; `None` once
    /// every one of them has.
    pub fn holder(&self, id: u32, said: &Ledger) -> Option<&Member> {
        let home = self.members.iter().position(|m| m.name == self.home_of(id).name)?;
        // Downstream first: the home robot and those downstream of it, from the home on.
        self.members[..=home].iter().rev().find(|m| !said.passed_by(id, &m.name))
    }

    /// Whether this robot may claim part `id`, by what `said` holds.
    pub fn may_claim(&self, id: u32, said: &Ledger) -> bool {
        self.holder(id, said).is_some_and(|m| m.name == self.me)
    }

    /// A part `at_mm` along the cell's belt, past this robot's window unpicked: whether a
    /// robot downstream can still reach it (it is handed on, not missed).
    pub fn handed_on(&self, at_mm: f64) -> bool {
        let mine = self.me().reach_mm()[1];
        // A window includes its end (the queue misses a part only past it).
        self.members.iter().any(|m| m.reach_mm()[1] > mine && m.reach_mm()[1] >= at_mm)
    }
}

/// A claim of a part, as published.
#[derive(Debug, Clone, PartialEq)]
pub struct Claim {
    /// The robot that claimed it.
    pub robot: String,
    /// When it claimed it, ns of the system clock.
    pub at_ns: u64,
    /// When its gripper is to close on it, ns of the system clock.
    pub grip_by_ns: u64,
    /// Its pick is done (off the belt): it is the robot's for good.
    pub picked: bool,
}

/// What a robot has heard of the parts, its own word among it: the claims (one per part, the
/// earliest kept) and which robots let which parts pass.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Ledger {
    claims: BTreeMap<u32, Claim>,
    passes: BTreeMap<u32, Vec<String>>,
}

impl Ledger {
    /// An empty ledger.
    pub fn new() -> Ledger {
        Ledger::default()
    }

    /// The claim of part `id`, if any.
    pub fn claim_of(&self, id: u32) -> Option<&Claim> {
        self.claims.get(&id)
    }

    /// `c` claims part `id`: true if it holds the part now — there was no other claim, or
    /// this one is earlier (then equal times: the name first in order) than one not yet
    /// picked. A robot that sees its own claim lose gives the part up.
    pub fn claim(&mut self, id: u32, c: Claim) -> bool {
        match self.claims.get_mut(&id) {
            None => {
                self.claims.insert(id, c);
                true
            }
            Some(held) if held.robot == c.robot => {
                *held = Claim { picked: held.picked || c.picked, ..c };
                true
            }
            Some(held) => {
                let earlier = (c.at_ns, &c.robot) < (held.at_ns, &held.robot);
                let wins = earlier && !held.picked;
                if wins {
                    *held = c;
                }
                wins
            }
        }
    }

    /// Robot `robot` picked part `id` (it is off the belt).
    pub fn picked(&mut self, id: u32, robot: &str, at_ns: u64) {
        let c = Claim { robot: robot.to_string(), at_ns, grip_by_ns: at_ns, picked: true };
        self.claims.insert(id, c);
    }

    /// Robot `robot` let part `id` pass: it will not claim it.
    pub fn passed(&mut self, id: u32, robot: &str) {
        let by = self.passes.entry(id).or_default();
        if !by.iter().any(|r| r == robot) {
            by.push(robot.to_string());
        }
    }

    /// Whether robot `robot` has let part `id` pass.
    pub fn passed_by(&self, id: u32, robot: &str) -> bool {
        self.passes.get(&id).is_some_and(|by| by.iter().any(|r| r == robot))
    }

    /// Robot `robot` gave part `id` up: its claim is gone, and it lets the part pass. False
    /// if it held none.
    pub fn release(&mut self, id: u32, robot: &str) -> bool {
        self.passed(id, robot);
        let held = self.claims.get(&id).is_some_and(|c| c.robot == robot && !c.picked);
        if held {
            self.claims.remove(&id);
        }
        held
    }

    /// Robot `robot` was seen gone at `gone_ns`: its claims not picked whose grip was still
    /// to come are released; their parts, in order.
    pub fn lost(&mut self, robot: &str, gone_ns: u64) -> Vec<u32> {
        let mut released = Vec::new();
        self.claims.retain(|id, c| {
            let free = c.robot == robot && !c.picked && c.grip_by_ns > gone_ns;
            if free {
                released.push(*id);
            }
            !free
        });
        released
    }

    /// Forgets the parts `done` says are done with everywhere (past the cell's last window).
    pub fn forget(&mut self, mut done: impl FnMut(u32) -> bool) {
        self.claims.retain(|id, _| !done(*id));
        self.passes.retain(|id, _| !done(*id));
    }
}

#[cfg(test)]
mod tests;
