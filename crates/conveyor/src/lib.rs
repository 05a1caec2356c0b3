//! Conveyor tracking's bookkeeping (issue 44, thesis 6.2.1's object queue): how the belt
//! moves ([`BeltMotion`]), where a part the camera saw is now ([`Belt`]), and the
//! [`PartQueue`] — detections in, the frames of one part merged into one, each part claimed
//! once for a pick, a part that leaves the window unpicked missed. Plain data and arithmetic: no I/O, no clock of its own, no allocation
//! once the queue has its capacity, so that the serving session may ask it every cycle.
//!
//! ```
//! use qmarc_conveyor::{Belt, Detection, PartQueue};
//! let belt = Belt { mm_per_count: 0.05 };
//! let mut q = PartQueue::new([300.0, 500.0], 2.0, 64);
//! let seen = Detection { t_ns: 0, latched_counts: 1_000, belt_mm: 120.0, across_mm: -10.0 };
//! let id = q.detect(seen, &belt).unwrap();
//! // 4000 counts later (200 mm of belt) the part is at 320 mm: inside the window.
//! assert_eq!(q.claim_next(5_000, &belt, |_, _| true), Some(id));
//! ```
#![deny(missing_docs)]

mod belt;
pub mod cell;
pub mod world;
pub use belt::BeltMotion;

/// The belt's encoder: how belt coordinates follow its counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Belt {
    /// mm of belt travel per encoder count (`conveyor.mm_per_count`).
    pub mm_per_count: f64,
}

impl Belt {
    /// Where a point seen at `belt_mm` when the encoder read `then` is when it reads `now`.
    pub fn carried(&self, belt_mm: f64, then: i64, now: i64) -> f64 {
        belt_mm + (now - then) as f64 * self.mm_per_count
    }
}

/// One detection of a part: where it lay on the belt when the frame was exposed, and the
/// belt's encoder then.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Detection {
    /// When the frame was exposed, ns of `CLOCK_MONOTONIC`.
    pub t_ns: u64,
    /// The belt encoder at the exposure, counts.
    pub latched_counts: i64,
    /// Along the belt, mm (belt coordinates).
    pub belt_mm: f64,
    /// Across the belt, mm.
    pub across_mm: f64,
}

/// What became of a part.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PartState {
    /// Seen, not yet claimed.
    Pending,
    /// Claimed for a pick, not yet done.
    Claimed,
    /// Picked and placed.
    Picked,
    /// Left the window unpicked (or could not be reached inside it).
    Missed,
    /// Another robot of the cell's (issue 47): claimed or picked by it, or handed on past
    /// this robot's window to the robots downstream.
    Elsewhere,
}

/// What [`PartQueue::claim_next_by`] is told of a pending part.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Take {
    /// Claim it.
    Claim,
    /// It cannot be picked inside the window: inside the window, it is missed.
    OutOfReach,
    /// Not this robot's to take now (another's share in a cell): left as it is.
    Leave,
}

impl PartState {
    /// Its name in `parts.csv`: `pending`, `picked`, `missed` or `passed` (a claimed part
    /// is pending; another robot's in a cell, passed).
    pub fn name(self) -> &'static str {
        match self {
            PartState::Pending | PartState::Claimed => "pending",
            PartState::Picked => "picked",
            PartState::Missed => "missed",
            PartState::Elsewhere => "passed",
        }
    }

    /// Done with here: picked, missed, or another's.
    pub fn done(self) -> bool {
        matches!(self, PartState::Picked | PartState::Missed | PartState::Elsewhere)
    }
}

/// A part the camera saw.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Part {
    /// Its number, 1 up, in the order first seen.
    pub id: u32,
    /// Its first detection.
    pub seen: Detection,
    /// What became of it.
    pub state: PartState,
}

impl Part {
    /// Its belt coordinate when the encoder reads `now`, mm.
    pub fn belt_mm(&self, now: i64, belt: &Belt) -> f64 {
        belt.carried(self.seen.belt_mm, self.seen.latched_counts, now)
    }
}

/// The parts seen, in the order seen.
#[derive(Debug, Clone)]
pub struct PartQueue {
    parts: Vec<Part>,
    window_mm: [f64; 2],
    merge_mm: f64,
    capacity: usize,
    /// The id the next new part gets.
    next_id: u32,
}

impl PartQueue {
    /// A queue for the window `window_mm` (belt coordinates where a part may be picked),
    /// merging detections within `merge_mm` of a known part (the same part in another frame),
    /// holding at most `capacity` parts (the oldest done ones make room).
    pub fn new(window_mm: [f64; 2], merge_mm: f64, capacity: usize) -> PartQueue {
        PartQueue { parts: Vec::with_capacity(capacity), window_mm, merge_mm, capacity, next_id: 1 }
    }

    /// The parts, in the order seen.
    pub fn parts(&self) -> &[Part] {
        &self.parts
    }

    /// The part `id`, if the queue holds it.
    pub fn part(&self, id: u32) -> Option<&Part> {
        self.parts.iter().find(|p| p.id == id)
    }

    /// A detection: the id of a new part, or `None` when it is a part already known (within
    /// `merge_mm` of where that part is at this detection's encoder count), its numbers are
    /// not finite, or the queue is full of parts not done.
    pub fn detect(&mut self, d: Detection, belt: &Belt) -> Option<u32> {
        if !(d.belt_mm.is_finite() && d.across_mm.is_finite()) {
            return None;
        }
        let known = self.parts.iter().any(|p| {
            let along = p.belt_mm(d.latched_counts, belt) - d.belt_mm;
            let across = p.seen.across_mm - d.across_mm;
            along.hypot(across) <= self.merge_mm
        });
        if known {
            return None;
        }
        let id = self.next_id;
        self.add(id, d).then(|| {
            self.next_id += 1;
            id
        })
    }

    /// A part another process numbered (a cell's camera, which merged its frames): false
    /// when the queue holds `id` already, the numbers are not finite, or the queue is full of
    /// parts not done.
    pub fn insert(&mut self, id: u32, d: Detection) -> bool {
        let finite = d.belt_mm.is_finite() && d.across_mm.is_finite();
        finite && self.part(id).is_none() && self.add(id, d)
    }

    /// Adds part `id`, making room if the queue is full: false if it is full of parts not
    /// done.
    fn add(&mut self, id: u32, seen: Detection) -> bool {
        if self.parts.len() == self.capacity {
            let Some(done) = self.parts.iter().position(|p| p.state.done()) else {
                return false;
            };
            self.parts.remove(done);
        }
        self.parts.push(Part { id, seen, state: PartState::Pending });
        true
    }

    /// Claims the part to pick next at encoder count `now`: the most downstream pending part
    /// that has not left the window and that `reachable(part, its belt coordinate now)` says
    /// can still be picked inside it. A pending part that has left the window, or that is
    /// downstream of the one claimed and cannot be reached, is missed.
    pub fn claim_next(
        &mut self,
        now: i64,
        belt: &Belt,
        mut reachable: impl FnMut(&Part, f64) -> bool,
    ) -> Option<u32> {
        self.sweep(now, belt);
        self.claim_next_by(
            now,
            belt,
            |p, at| if reachable(p, at) { Take::Claim } else { Take::OutOfReach },
        )
    }

    /// [`PartQueue::claim_next`] told by `take` what to do with each pending part, downstream
    /// first: claim it, miss it (out of reach inside the window), or leave it (another
    /// robot's share). Sweeps nothing: the caller has.
    pub fn claim_next_by(
        &mut self,
        now: i64,
        belt: &Belt,
        mut take: impl FnMut(&Part, f64) -> Take,
    ) -> Option<u32> {
        // Downstream first — the part nearest the window's end is the one about to be lost —
        // without sorting into a new list: each pass takes the most downstream pending part
        // upstream of the last one looked at (ties: the one seen first).
        let key = |p: &Part| (p.belt_mm(now, belt), -i64::from(p.id));
        let mut after: Option<(f64, i64)> = None;
        loop {
            let next = (0..self.parts.len())
                .filter(|&i| self.parts[i].state == PartState::Pending)
                .filter(|&i| after.is_none_or(|a| key(&self.parts[i]) < a))
                .max_by(|&a, &b| {
                    let (a, b) = (key(&self.parts[a]), key(&self.parts[b]));
                    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
                })?;
            let at = self.parts[next].belt_mm(now, belt);
            after = Some(key(&self.parts[next]));
            match take(&self.parts[next], at) {
                Take::Claim => {
                    self.parts[next].state = PartState::Claimed;
                    return Some(self.parts[next].id);
                }
                // Inside the window and out of reach: it will not come back.
                Take::OutOfReach if at >= self.window_mm[0] => {
                    self.parts[next].state = PartState::Missed;
                }
                Take::OutOfReach | Take::Leave => {}
            }
        }
    }

    /// Every part not done that the belt has carried past the window's end at `now` is
    /// missed (a claimed one too: the pick did not happen inside the window).
    pub fn sweep(&mut self, now: i64, belt: &Belt) {
        self.sweep_by(now, belt, |_| PartState::Missed);
    }

    /// [`PartQueue::sweep`] with the fate of each part past the window's end told by
    /// `fate` (in a cell: missed, or handed on to the robots downstream).
    pub fn sweep_by(&mut self, now: i64, belt: &Belt, mut fate: impl FnMut(&Part) -> PartState) {
        let end = self.window_mm[1];
        for p in &mut self.parts {
            if matches!(p.state, PartState::Pending | PartState::Claimed)
                && p.belt_mm(now, belt) > end
            {
                p.state = fate(p);
            }
        }
    }

    /// Part `id`, pending, is another robot's (its claim was seen): false if it was not
    /// pending here.
    pub fn elsewhere(&mut self, id: u32) -> bool {
        self.set(id, PartState::Pending, PartState::Elsewhere)
    }

    /// Part `id`, another's, is pending again (its claimant was lost before it gripped):
    /// false if it was not another's.
    pub fn release(&mut self, id: u32) -> bool {
        self.set(id, PartState::Elsewhere, PartState::Pending)
    }

    /// Part `id` goes from `from` to `to`; false if it was not in `from`.
    fn set(&mut self, id: u32, from: PartState, to: PartState) -> bool {
        match self.parts.iter_mut().find(|p| p.id == id && p.state == from) {
            Some(p) => {
                p.state = to;
                true
            }
            None => false,
        }
    }

    /// Part `id` was picked and placed. False if it was not the claimed one (never picked
    /// twice).
    pub fn picked(&mut self, id: u32) -> bool {
        self.set(id, PartState::Claimed, PartState::Picked)
    }

    /// Part `id`, claimed, cannot be picked after all (its pick was given up): missed. False
    /// if it was not the claimed one.
    pub fn missed(&mut self, id: u32) -> bool {
        self.set(id, PartState::Claimed, PartState::Missed)
    }

    /// Part `id`, claimed, is left to the robots downstream (its pick was given up in a
    /// cell, or another robot has it): passed. False if it was not the claimed one.
    pub fn pass_on(&mut self, id: u32) -> bool {
        self.set(id, PartState::Claimed, PartState::Elsewhere)
    }

    /// Parts picked and missed so far.
    pub fn counts(&self) -> (usize, usize) {
        let [_, _, picked, missed, _] = self.tally();
        (picked, missed)
    }

    /// Parts by state: pending, claimed, picked, missed, another's.
    pub fn tally(&self) -> [usize; 5] {
        let mut n = [0; 5];
        for p in &self.parts {
            n[match p.state {
                PartState::Pending => 0,
                PartState::Claimed => 1,
                PartState::Picked => 2,
                PartState::Missed => 3,
                PartState::Elsewhere => 4,
            }] += 1;
        }
        n
    }
}

#[cfg(test)]
mod tests;
