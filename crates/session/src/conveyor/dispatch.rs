//! [`Dispatcher`]: the conveyor session's thread between the camera and the loop. Every
//! millisecond it takes the camera's detections into the part queue (a detection whose belt
//! count the camera did not latch gets one interpolated from the loop's own samples of the
//! encoder at the exposure), sweeps the parts the belt has carried past the window, hands the
//! picker the next part it can intercept inside the window, and notes what the picker did.
//! At the end it says what became of every part ([`PartRecord`]).

mod cell;
pub use cell::CellTally;

use super::picker::{CLOSE_MARGIN_MM, PickerHandle, relative_limits_of};
use super::{BeltFrame, GaveUp, Pick, PickEvent};
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{Node, ipc};
use qmarc_config::Settings;
use qmarc_controller::status::LoopStatus;
use qmarc_conveyor::{Belt, Detection, Part, PartQueue, PartState, Take};
use qmarc_plugins::motion::{MotionLimits, MotionState, Profile};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::camera::{PartDetection, open_camera_service};
use qmarc_proto::cell::{CELL_IN, CELL_OUT, CellMsg, open_cell_service};
use qmarc_proto::service::{IpcLocation, ServiceError, create_node};
use std::collections::VecDeque;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// How often the dispatcher looks.
const POLL: Duration = Duration::from_millis(1);
/// The loop's belt samples kept for interpolation: seconds of them.
const HISTORY: usize = 4096;
/// Most parts the queue holds.
const QUEUE_CAPACITY: usize = 4096;

/// What became of one part the camera saw (a row of `parts.csv`).
#[derive(Debug, Clone, PartialEq)]
pub struct PartRecord {
    /// The queue's id.
    pub id: u32,
    /// Its first detection's exposure, s since the run's world began.
    pub t_seen_s: f64,
    /// The belt encoder at that exposure, counts.
    pub latched_counts: i64,
    /// Along the belt then, mm.
    pub belt_mm: f64,
    /// Across the belt, mm.
    pub across_mm: f64,
    /// `picked`, `missed` or `pending`.
    pub state: &'static str,
    /// The cycle the gripper was told to close on it, if it was.
    pub grip_cycle: Option<u64>,
    /// The cycle the gripper was told to open at the place, if it was.
    pub place_cycle: Option<u64>,
    /// Why its pick was given up, if it was.
    pub gave_up: Option<GaveUp>,
    /// Its first detection's exposure to the part in the queue, ns (a paced session's: the
    /// camera's latency, the transport and the dispatcher's poll).
    pub queued_after_ns: Option<u64>,
    /// When it was handed to the loop, ns of `CLOCK_MONOTONIC`.
    pub handed_ns: Option<u64>,
    /// In a cell: the robot that picked it, if one did.
    pub by: Option<String>,
    /// In a cell: from its first detection's exposure to its claim as seen here (this
    /// robot's: when made; another's: when heard), ns.
    pub claimed_after_ns: Option<u64>,
    /// From then to the tick of the cycle whose command began its intercept, ns (0 when
    /// that cycle had woken before the hand-over: its command came within its compute).
    pub commanded_after_ns: Option<u64>,
}

/// What the dispatcher saw, at its end.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Dispatched {
    /// Every part, in the order seen.
    pub parts: Vec<PartRecord>,
    /// Detections received (in a cell: parts from the cell's camera taken into its queue).
    pub detections: u64,
    /// In a cell: which, and what the cell counted.
    pub cell: Option<CellTally>,
}

/// The dispatcher thread: it runs from [`Dispatcher::spawn`] until [`Dispatcher::finish`].
pub struct Dispatcher {
    stop: Arc<AtomicBool>,
    thread: std::thread::JoinHandle<Dispatched>,
}

/// The dispatcher's state, on its thread.
struct Dispatch {
    queue: PartQueue,
    belt: Belt,
    frame: BeltFrame,
    relative: MotionLimits,
    close_s: f64,
    period_s: f64,
    n_motors: usize,
    status: Arc<LoopStatus>,
    handle: PickerHandle,
    epoch_ns: u64,
    /// Latencies are measured (a paced session: the exposures are `CLOCK_MONOTONIC`'s).
    measure: bool,
    /// The loop's reads of the belt, oldest first.
    history: VecDeque<BeltRead>,
    /// The pick the picker has and has not finished.
    given: Option<u32>,
    records: Vec<PartRecord>,
    detections: u64,
    profile: Profile,
    /// In a cell: the others, the claims, what to tell them.
    cell: Option<cell::CellSide>,
}

impl Dispatcher {
    /// Starts the dispatcher of the run at `location` (its world began at `epoch_ns`; `paced`:
    /// it runs on the clock, so its latencies are measured) for the picker behind `handle`, in
    /// the loop whose status is `status`; `None` when the settings describe no robot. The
    /// camera's service exists when this returns.
    pub fn spawn(
        location: &IpcLocation,
        s: &Settings,
        (epoch_ns, paced): (u64, bool),
        handle: PickerHandle,
        status: Arc<LoopStatus>,
    ) -> Result<Dispatcher, ServiceError> {
        let mut d = Dispatch::new(s, (epoch_ns, paced), handle, status)?;
        let stop = Arc::new(AtomicBool::new(false));
        let (location, stopping) = (location.clone(), stop.clone());
        let in_cell = d.cell.is_some();
        let (ready, opened) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("qmarc-dispatch".into())
            .spawn(move || {
                let ports = (|| {
                    let node = create_node::<iceoryx2::prelude::ipc::Service>(
                        "qmarc-dispatch",
                        &location,
                    )?;
                    Ports::open(node, in_cell)
                })();
                let ports = match ports {
                    Ok(p) => {
                        let _ = ready.send(Ok(()));
                        p
                    }
                    Err(e) => {
                        let _ = ready.send(Err(e));
                        return Dispatched::default();
                    }
                };
                while !stopping.load(Ordering::Acquire) {
                    ports.receive(&mut d);
                    d.look();
                    ports.send(&mut d);
                    std::thread::sleep(POLL);
                }
                ports.receive(&mut d);
                d.look();
                d.end_cell();
                ports.send(&mut d);
                d.finish()
            })
            .map_err(|e| ServiceError::new("thread", "qmarc-dispatch", e))?;
        let opened = opened.recv().unwrap_or_else(|_| {
            Err(ServiceError::new("thread", "qmarc-dispatch", "ended before serving"))
        });
        if let Err(e) = opened {
            let _ = thread.join();
            return Err(e);
        }
        Ok(Dispatcher { stop, thread })
    }

    /// The loop has ended: what became of every part.
    pub fn finish(self) -> Dispatched {
        self.stop.store(true, Ordering::Release);
        self.thread.join().unwrap_or_default()
    }
}

impl Dispatch {
    /// The dispatcher's state for the picker behind `handle` in the loop whose status is
    /// `status` ([`Dispatcher::spawn`]'s arguments); an error when the settings describe no
    /// robot.
    fn new(
        s: &Settings,
        (epoch_ns, paced): (u64, bool),
        handle: PickerHandle,
        status: Arc<LoopStatus>,
    ) -> Result<Dispatch, ServiceError> {
        let frame = BeltFrame::of(s).ok_or_else(|| {
            ServiceError::new("settings", "conveyor", "[robot] describes no Delta")
        })?;
        let c = &s.conveyor;
        let merge_mm = (4.0 * s.camera.noise_mm).max(5.0);
        Ok(Dispatch {
            queue: PartQueue::new(c.window_mm, merge_mm, QUEUE_CAPACITY),
            belt: Belt { mm_per_count: c.mm_per_count },
            relative: relative_limits_of(s, &frame),
            frame,
            close_s: s.s626.gripper_close_s,
            period_s: s.period_s(),
            n_motors: s.n_motors,
            status,
            handle,
            epoch_ns,
            measure: paced,
            history: VecDeque::with_capacity(HISTORY),
            given: None,
            records: Vec::new(),
            detections: 0,
            profile: Profile::new(s.n_motors, [0.0; MAX_MOTORS]),
            cell: cell::CellSide::of(s),
        })
    }
}

/// The dispatcher's iceoryx2 ports: the camera's detections, or in a cell the cell's
/// messages in and this robot's out.
enum Ports {
    Camera {
        _node: Node<ipc::Service>,
        detections: Subscriber<ipc::Service, PartDetection, ()>,
    },
    Cell {
        _node: Node<ipc::Service>,
        from_cell: Subscriber<ipc::Service, CellMsg, ()>,
        to_cell: Publisher<ipc::Service, CellMsg, ()>,
    },
}

impl Ports {
    /// The ports on `node`: the cell's (`in_cell`) or the camera's.
    fn open(node: Node<ipc::Service>, in_cell: bool) -> Result<Ports, ServiceError> {
        if !in_cell {
            let service = open_camera_service(&node)?;
            let detections = service.subscriber_builder().create().map_err(|e| {
                ServiceError::new("subscriber", qmarc_proto::camera::CAMERA_SERVICE, e)
            })?;
            return Ok(Ports::Camera { _node: node, detections });
        }
        let from_cell = open_cell_service(&node, CELL_IN)?
            .subscriber_builder()
            .create()
            .map_err(|e| ServiceError::new("subscriber", CELL_IN, e))?;
        let to_cell = open_cell_service(&node, CELL_OUT)?
            .publisher_builder()
            .create()
            .map_err(|e| ServiceError::new("publisher", CELL_OUT, e))?;
        Ok(Ports::Cell { _node: node, from_cell, to_cell })
    }

    /// Takes in what has arrived.
    fn receive(&self, d: &mut Dispatch) {
        match self {
            Ports::Camera { detections, .. } => {
                while let Ok(Some(sample)) = detections.receive() {
                    d.detected(sample.payload());
                }
            }
            Ports::Cell { from_cell, .. } => {
                while let Ok(Some(sample)) = from_cell.receive() {
                    d.cell_message(sample.payload());
                }
            }
        }
    }

    /// Sends what the dispatcher has to tell the cell (a message that cannot be sent is
    /// dropped: the cell's companion is gone, and with it the cell).
    fn send(&self, d: &mut Dispatch) {
        if let (Ports::Cell { to_cell, .. }, Some(side)) = (self, d.cell.as_mut()) {
            for m in side.outbox.drain(..) {
                let _ = to_cell.send_copy(m);
            }
        }
    }
}

/// One read of the belt by the loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct BeltRead {
    /// The encoder, counts.
    pub counts: i64,
    /// When the loop woke for it, ns of `CLOCK_MONOTONIC` (the simulated clock's in
    /// lock-step).
    pub ns: u64,
    /// The sample (cycle) it was read in.
    pub sample: u64,
}

/// The belt encoder at `t_ns`, interpolated between the loop's reads `history` (oldest
/// first) around it; `None` outside them.
pub(crate) fn counts_at(history: &VecDeque<BeltRead>, t_ns: u64) -> Option<i64> {
    let after = history.iter().position(|r| r.ns >= t_ns)?;
    let (c1, t1) = (history[after].counts, history[after].ns);
    let Some(r0) = after.checked_sub(1).and_then(|k| history.get(k)) else {
        return (t1 == t_ns).then_some(c1);
    };
    let (c0, t0) = (r0.counts, r0.ns);
    let f = (t_ns - t0) as f64 / (t1 - t0).max(1) as f64;
    Some(c0 + ((c1 - c0) as f64 * f).round() as i64)
}

impl Dispatch {
    /// A detection from the camera.
    fn detected(&mut self, d: &PartDetection) {
        self.detections += 1;
        let counts = if d.latched() {
            Some(d.latched_counts)
        } else {
            counts_at(&self.history, d.exposure_ns)
        };
        let Some(latched_counts) = counts else { return };
        let seen = Detection {
            t_ns: d.exposure_ns,
            latched_counts,
            belt_mm: d.belt_mm,
            across_mm: d.across_mm,
        };
        if let Some(id) = self.queue.detect(seen, &self.belt) {
            let record = self.new_record(id, &seen);
            self.records.push(record);
        }
    }

    /// The record of new part `id`, first seen as `seen`.
    fn new_record(&self, id: u32, seen: &Detection) -> PartRecord {
        let queued_after_ns =
            self.measure.then(|| qmarc_timer::clock::monotonic_now_ns().saturating_sub(seen.t_ns));
        PartRecord {
            id,
            t_seen_s: seen.t_ns.saturating_sub(self.epoch_ns) as f64 * 1e-9,
            latched_counts: seen.latched_counts,
            belt_mm: seen.belt_mm,
            across_mm: seen.across_mm,
            state: "pending",
            grip_cycle: None,
            place_cycle: None,
            gave_up: None,
            queued_after_ns,
            handed_ns: None,
            commanded_after_ns: None,
            by: None,
            claimed_after_ns: None,
        }
    }

    /// The tick of cycle `n`, ns: from the loop's read nearest to it, a period a cycle.
    fn tick_of(&self, n: u64) -> Option<u64> {
        let r = self.history.iter().min_by_key(|r| r.sample.abs_diff(n))?;
        let periods = n as f64 - r.sample as f64;
        Some((r.ns as f64 + periods * self.period_s * 1e9).max(0.0) as u64)
    }

    fn record(&mut self, id: u32) -> Option<&mut PartRecord> {
        self.records.iter_mut().rev().find(|r| r.id == id)
    }

    /// The loop's belt, the picker's events, the parts past the window, the next pick.
    fn look(&mut self) {
        let (now, ns, sample) = self.status.belt_read();
        if ns != 0 && self.history.back().is_none_or(|r| r.ns < ns) {
            if self.history.len() == HISTORY {
                self.history.pop_front();
            }
            self.history.push_back(BeltRead { counts: now, ns, sample });
        }
        while let Ok(event) = self.handle.events.pop() {
            match event {
                PickEvent::Intercepting { id, cycle } => {
                    let tick = self.tick_of(cycle).filter(|_| self.measure);
                    if let Some(r) = self.record(id) {
                        r.commanded_after_ns =
                            r.handed_ns.zip(tick).map(|(h, t)| t.saturating_sub(h));
                    }
                }
                PickEvent::Gripping { id, cycle } => {
                    self.record(id).into_iter().for_each(|r| r.grip_cycle = Some(cycle));
                }
                PickEvent::Lifted { id } => {
                    self.queue.picked(id);
                    let at = self.loop_now_ns();
                    self.cell.iter_mut().for_each(|c| c.picked(id, at));
                }
                PickEvent::Placed { id, cycle } => {
                    self.record(id).into_iter().for_each(|r| r.place_cycle = Some(cycle));
                    self.given = None;
                }
                PickEvent::GaveUp { id, why } => {
                    self.record(id).into_iter().for_each(|r| r.gave_up = Some(why));
                    // Out of reach or no profile: it will not be picked here (in a cell, a
                    // robot downstream may still). One the session stopped for stays as it is;
                    // one another robot has is its.
                    match why {
                        GaveUp::Stopped => {}
                        GaveUp::Elsewhere => {
                            self.queue.pass_on(id);
                        }
                        _ => self.gave_up(id, now),
                    }
                    self.given = None;
                }
            }
        }
        if self.status.begun() {
            self.sweep(now);
        }
        let shared = &self.handle.shared;
        let ready = shared.ready.load(Ordering::Acquire) && !shared.ending.load(Ordering::Acquire);
        if ready && self.given.is_none() && self.history.len() > 1 {
            let speed = self.belt_speed_mm_s();
            let command = self.status.command();
            // The gripper's read says it has closed two cycles after its travel.
            let closing_s = self.close_s + 2.0 * self.period_s;
            let (frame, relative, n) = (self.frame, self.relative, self.n_motors);
            let profile = &mut self.profile;
            let cell = self.cell.as_ref();
            let claimed = self.queue.claim_next_by(now, &self.belt, |part, at| {
                // In a cell a part not this robot's to take now, or out of its reach, is left
                // to the sweep: passed on, or missed by the last robot that could reach it.
                let (mine, miss) = cell.map_or((true, Take::OutOfReach), |c| {
                    (c.may_claim(part.id, part.seen.t_ns), Take::Leave)
                });
                if !mine {
                    Take::Leave
                } else if intercepts(
                    &frame, &relative, profile, n, &command, part, at, speed, closing_s,
                ) {
                    Take::Claim
                } else {
                    miss
                }
            });
            if let (Some(id), Some(side)) = (claimed, self.cell.as_mut()) {
                // Said to the cell before the loop is given it.
                let grip_in = (self.profile.duration() + closing_s) * 1e9;
                side.claim(id, ns, grip_in as u64);
                self.claim_seen(id);
            }
            if let Some(part) = claimed.and_then(|id| self.queue.part(id)) {
                let pick = Pick {
                    id: part.id,
                    belt_mm: part.seen.belt_mm,
                    across_mm: part.seen.across_mm,
                    latched_counts: part.seen.latched_counts,
                };
                // Before the push: the loop may take it at once.
                let handed = qmarc_timer::clock::monotonic_now_ns();
                if self.handle.picks.push(pick).is_ok() {
                    self.given = Some(pick.id);
                    self.record(pick.id).into_iter().for_each(|r| r.handed_ns = Some(handed));
                }
            }
        }
        self.tell(now);
    }

    /// Says the belt (at `now` counts) and the queue to the command thread.
    fn tell(&self, now: i64) {
        let [pending, claimed, picked, missed, elsewhere] = self.queue.tally();
        let count = |n: usize| u32::try_from(n).unwrap_or(u32::MAX);
        self.handle.tally.set(&crate::wire::ConveyorStatus {
            active: 1,
            seen: count(pending + claimed + picked + missed + elsewhere),
            queued: count(pending),
            picked: count(picked),
            missed: count(missed),
            picking: self.given.map_or(0, |id| id.saturating_add(1)),
            belt_mm: now as f64 * self.belt.mm_per_count,
            belt_mm_s: self.belt_speed_mm_s(),
        });
    }

    /// The belt's speed over the loop's last samples (up to 50 ms of them), mm/s.
    fn belt_speed_mm_s(&self) -> f64 {
        let Some(&BeltRead { counts: c1, ns: t1, .. }) = self.history.back() else { return 0.0 };
        let Some(&BeltRead { counts: c0, ns: t0, .. }) =
            self.history.iter().rev().find(|r| t1 - r.ns >= 50_000_000).or(self.history.front())
        else {
            return 0.0;
        };
        if t1 <= t0 {
            return 0.0;
        }
        (c1 - c0) as f64 * self.belt.mm_per_count / ((t1 - t0) as f64 * 1e-9)
    }

    /// The loop's time of its last read of the belt, ns of `CLOCK_MONOTONIC` (simulated in
    /// lock-step): the dispatcher's "now" for what it tells the cell.
    fn loop_now_ns(&self) -> u64 {
        self.history.back().map_or(0, |r| r.ns)
    }

    /// Every part the belt has carried past the window at `now` counts: missed, or in a cell
    /// passed on while a robot downstream can reach it — and said to the cell to be let pass
    /// when this robot had not claimed it (one it had is said given up when the picker does).
    fn sweep(&mut self, now: i64) {
        let (belt, cell) = (self.belt, self.cell.as_ref());
        let mut unclaimed = Vec::new();
        self.queue.sweep_by(now, &belt, |p| {
            if p.state == PartState::Pending {
                unclaimed.push(p.id);
            }
            cell.map_or(PartState::Missed, |c| c.fate(p.belt_mm(now, &belt)))
        });
        let at_ns = self.loop_now_ns();
        if let Some(side) = self.cell.as_mut() {
            for id in unclaimed {
                // Once: a part it let pass at once (not placed in time) is swept later too.
                if !side.ledger.passed_by(id, side.me()) {
                    side.passed(id, at_ns);
                }
            }
        }
    }

    /// The picker gave part `id` up (not for a stop) with the belt at `now` counts: missed, or
    /// in a cell given back to the cell — passed on while a robot downstream can reach it.
    fn gave_up(&mut self, id: u32, now: i64) {
        let at_ns = self.loop_now_ns();
        let Some(side) = self.cell.as_mut() else {
            self.queue.missed(id);
            return;
        };
        let at = self.queue.part(id).map_or(f64::INFINITY, |p| p.belt_mm(now, &self.belt));
        side.released(id, at_ns);
        if side.fate(at) == PartState::Elsewhere {
            self.queue.pass_on(id);
        } else {
            self.queue.missed(id);
        }
    }

    fn finish(mut self) -> Dispatched {
        let (now, _) = self.status.belt();
        self.sweep(now);
        let mut records = std::mem::take(&mut self.records);
        for r in &mut records {
            if let Some(p) = self.queue.part(r.id) {
                r.state = p.state.name();
            }
        }
        self.cell_records(&mut records);
        let cell = self.cell.as_ref().map(cell::CellSide::tally);
        Dispatched { parts: records, detections: self.detections, cell }
    }
}

/// Whether the picker, at rest at `command`, can intercept `part` (now `at` mm along the belt
/// at `speed` mm/s) so that the gripper closes on it inside the window: the intercept's
/// duration planned as the picker will plan it, the grip point within reach and the window
/// where the gripper is told to close and where its read says it has closed (`closing_s`
/// later, [`CLOSE_MARGIN_MM`] to spare).
#[allow(clippy::too_many_arguments)]
pub(crate) fn intercepts(
    frame: &BeltFrame,
    relative: &MotionLimits,
    profile: &mut Profile,
    n_motors: usize,
    command: &[f64; MAX_MOTORS],
    part: &Part,
    at: f64,
    speed: f64,
    closing_s: f64,
) -> bool {
    let across = part.seen.across_mm;
    let (Ok(q), Ok(ahead)) = (frame.counts(at, across), frame.counts(at + speed * 1e-3, across))
    else {
        return false;
    };
    let from = MotionState {
        p: std::array::from_fn(|m| command[m] - q[m]),
        v: std::array::from_fn(|m| if m < n_motors { -(ahead[m] - q[m]) / 1e-3 } else { 0.0 }),
        a: [0.0; MAX_MOTORS],
    };
    if profile.plan(&from, &[0.0; MAX_MOTORS], relative).is_err() {
        return false;
    }
    let grip = at + speed * profile.duration();
    let closed = grip + speed * closing_s + CLOSE_MARGIN_MM;
    let [start, end] = frame.window_mm;
    grip >= start
        && closed <= end
        && frame.counts(grip, across).is_ok()
        && frame.counts(closed, across).is_ok()
}

#[cfg(test)]
mod tests;
