//! [`Picker`]: the conveyor session's generator. It waits at rest for a [`Pick`], then:
//!
//! 1. **intercepts** the part in the belt's frame: the command is the joint counts of the
//!    part's grip point where the belt has carried it this cycle, plus a jerk-limited
//!    profile that takes the difference to zero — from the command's state (position,
//!    velocity, acceleration) at rest relative to the part. A belt that changes speed moves
//!    the part, and with it the command; the profile is not replanned;
//! 2. **tracks** the part, the command on its grip point every cycle: the gripper is told to
//!    close ([`PickEvent::Gripping`]) once the effector is on the part — the forward
//!    kinematics of the cycle's read within [`GRIP_WITHIN_MM`] of the part where the cycle's
//!    read of the belt has it (after a host's stall the robot settles first), or after
//!    [`SETTLE_MAX_S`] on it whatever the distance — and tracks it while the gripper closes;
//! 3. **places** it: a jerk-limited profile from the state it leaves the belt with to
//!    `conveyor.place_mm` at rest, where the gripper opens ([`PickEvent::Placed`]);
//! 4. waits there for the next pick.
//!
//! The profile relative to the part keeps what is left of each motor's limits once the
//! belt's own motion is served (the belt's joint speed at its fastest, over the window). A
//! part that leaves the window before the gripper has closed, or leaves the robot's reach, is
//! given up ([`PickEvent::GaveUp`]) and the command stops: never chased.

use super::tracker::BeltTracker;
use super::{BeltFrame, GaveUp, Pick, PickEvent};
use crate::generator::{NotTaken, Order, ServeHandle, ServeShared};
use qmarc_config::Settings;
use qmarc_controller::status::LoopStatus;
use qmarc_controller::traj::{Sample, TrajStartError, TrajectoryGenerator};
use qmarc_plugins::motion::{MotionLimits, MotionState, Profile};
use qmarc_proto::{Gripper, MAX_MOTORS, MotorFlags};
use rtrb::{Consumer, Producer, RingBuffer};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};

/// How high a gripped part is lifted off the belt, in the belt's frame, before it is carried
/// to the place, mm.
pub const LIFT_MM: f64 = 25.0;

/// What the gripper's closing must leave of the window besides its travel: the cycles before
/// its read says it has closed (two) and this much more, mm.
pub const CLOSE_MARGIN_MM: f64 = 2.0;

/// The effector's distance from the part's grip point within which the gripper is told to
/// close, mm: half the 1 mm the picking is held to at the grip (issue 44), the other half
/// for the closing.
pub const GRIP_WITHIN_MM: f64 = 0.5;

/// The longest the picker waits on the part for the effector to come within
/// [`GRIP_WITHIN_MM`] before the gripper is told to close anyway (gains that leave the robot
/// further off: it grips as well as they let it), s — 10 mm of a 500 mm/s belt.
pub const SETTLE_MAX_S: f64 = 0.02;

/// What the picker and the dispatcher share: written with atomic stores only.
#[derive(Debug, Default)]
pub struct PickerShared {
    /// The picker waits for a pick: the dispatcher may hand it one.
    pub ready: AtomicBool,
    /// The picker takes no more picks (its session ends, or it was told to stop).
    pub ending: AtomicBool,
    /// A part (its id) the picker is to give up if its gripper has not been told to close on
    /// it yet: another robot of the cell has it (0: none).
    pub cancel: AtomicU32,
}

/// The dispatcher's end of a [`Picker`].
pub struct PickerHandle {
    /// Picks to the loop, one at a time.
    pub picks: Producer<Pick>,
    /// What the loop did with them.
    pub events: Consumer<PickEvent>,
    /// The picker's state.
    pub shared: Arc<PickerShared>,
    /// The belt and the queue as the dispatcher counts them (the command thread says them).
    pub tally: Arc<crate::wire::ConveyorTally>,
}

/// Where the picker is.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Phase {
    /// At rest, waiting for a pick.
    Idle,
    /// The profile relative to the part runs.
    Intercept(Pick),
    /// On the part, the effector coming onto it: the gripper not told yet.
    Settle(Pick),
    /// On the part, the gripper closing.
    Track(Pick),
    /// The part held, rising [`LIFT_MM`] in the belt's frame.
    Lift(Pick),
    /// The fixed profile to the place runs (with the part, or after a pick given up).
    Place(Option<Pick>),
    /// At the place, the gripper opening.
    Release,
}

/// The conveyor session's generator ([module docs](self)).
pub struct Picker {
    belt_frame: BeltFrame,
    n_motors: usize,
    period_s: f64,
    limits: MotionLimits,
    /// What is left of `limits` in the part's frame.
    relative: MotionLimits,
    place: [f64; MAX_MOTORS],
    profile: Profile,
    /// The sample the profile's time 0 is.
    origin_n: u64,
    phase: Phase,
    /// The last sample commanded and its state.
    last: MotionState,
    /// Where the belt is: its encoder, followed smoothly.
    belt: BeltTracker,
    /// This cycle's read of the encoder, for the tracker at the cycle's sample.
    belt_read: i64,
    /// This cycle's read of the motors, counts.
    act: [f64; MAX_MOTORS],
    /// The sample the effector began settling on the part.
    settle_from: u64,
    /// [`SETTLE_MAX_S`] in samples.
    settle_samples: u64,
    grip: Option<bool>,
    gripper: Gripper,
    /// How long the gripper takes to close, s (`s626.gripper_close_s`).
    close_s: f64,
    picks: Consumer<Pick>,
    events: Producer<PickEvent>,
    shared: Arc<PickerShared>,
    orders: Consumer<Order>,
    spent: Producer<crate::generator::LineQueue>,
    serve: Arc<ServeShared>,
    /// The cycle the session ends at (`conveyor.run_s`).
    end_n: u64,
    ended: bool,
}

/// A pick could not be followed this cycle.
type Lost = GaveUp;

impl Picker {
    /// The picker of the settings `s` (`None`: they describe no robot to pick with), the
    /// command thread's handle and the dispatcher's.
    pub fn new(
        s: &Settings,
        status: Arc<LoopStatus>,
    ) -> Option<(Picker, ServeHandle, PickerHandle)> {
        let belt_frame = BeltFrame::of(s)?;
        let c = &s.conveyor;
        let place = belt_frame.counts_at_mm(c.place_mm).ok()?;
        let limits = MotionLimits::of(s);
        let relative = relative_limits_of(s, &belt_frame);
        let (orders_tx, orders) = RingBuffer::new(crate::generator::ORDER_QUEUE);
        let (spent, spent_rx) = RingBuffer::new(crate::generator::ORDER_QUEUE + 1);
        let (picks_tx, picks) = RingBuffer::new(2);
        let (events, events_rx) = RingBuffer::new(256);
        let shared = Arc::new(PickerShared::default());
        let serve = Arc::new(ServeShared::default());
        let picker = Picker {
            belt_frame,
            n_motors: s.n_motors,
            period_s: s.period_s(),
            limits,
            relative,
            place,
            profile: Profile::new(s.n_motors, [0.0; MAX_MOTORS]),
            origin_n: 0,
            phase: Phase::Idle,
            last: MotionState::default(),
            belt: BeltTracker::new(s.period_s()),
            belt_read: 0,
            act: [0.0; MAX_MOTORS],
            settle_from: 0,
            settle_samples: (SETTLE_MAX_S / s.period_s()).round() as u64,
            grip: None,
            gripper: Gripper(Gripper::ABSENT),
            close_s: s.s626.gripper_close_s,
            picks,
            events,
            shared: shared.clone(),
            orders,
            spent,
            serve: serve.clone(),
            end_n: (c.run_s / s.period_s()).round() as u64,
            ended: false,
        };
        let tally = Arc::new(crate::wire::ConveyorTally::default());
        let serve_handle = ServeHandle {
            orders: orders_tx,
            spent: spent_rx,
            shared: serve,
            status,
            conveyor: Some(tally.clone()),
        };
        let handle = PickerHandle { picks: picks_tx, events: events_rx, shared, tally };
        Some((picker, serve_handle, handle))
    }

    /// The belt's estimated counts this cycle (`back` 0) or the last (`back` 1).
    fn belt_at(&self, back: usize) -> f64 {
        if back == 0 { self.belt.position() } else { self.belt.position_before() }
    }

    /// The joint counts of the point `up_mm` above `pick`'s grip point at the belt's
    /// estimated `counts`, and their velocity at the belt's estimated speed; a part on the
    /// belt (not held) past the window's end is lost.
    fn on_part(
        &self,
        pick: &Pick,
        counts: f64,
        up_mm: f64,
    ) -> Result<([f64; MAX_MOTORS], [f64; MAX_MOTORS]), Lost> {
        let f = &self.belt_frame;
        let along = f.along_at(pick, counts);
        if up_mm == 0.0 && along > f.window_mm[1] {
            return Err(GaveUp::LeftWindow);
        }
        let q = f.counts_up(along, pick.across_mm, up_mm).map_err(|_| GaveUp::OutOfReach)?;
        let step_mm = self.belt.speed() * f.mm_per_count * self.period_s;
        let ahead =
            f.counts_up(along + step_mm, pick.across_mm, up_mm).map_err(|_| GaveUp::OutOfReach)?;
        Ok((q, std::array::from_fn(|m| (ahead[m] - q[m]) / self.period_s)))
    }

    /// Whether the gripper, told to close on `pick` now, has closed before the belt carries
    /// it past the window's end (its read comes two cycles after its travel).
    fn closes_in_window(&self, pick: &Pick) -> bool {
        let f = &self.belt_frame;
        let speed_mm_s = self.belt.speed() * f.mm_per_count;
        let closing_s = self.close_s + 2.0 * self.period_s;
        f.along_at(pick, self.belt_at(0)) + speed_mm_s * closing_s + CLOSE_MARGIN_MM
            <= f.window_mm[1]
    }

    /// Plans `plan` from the last sample (sample `n − 1`): the profile's time 0.
    fn replan(
        &mut self,
        n: u64,
        plan: impl FnOnce(&mut Profile) -> Result<(), qmarc_plugins::motion::NoProfile>,
    ) -> Result<(), Lost> {
        plan(&mut self.profile).map_err(|_| GaveUp::NoProfile)?;
        self.origin_n = n.saturating_sub(1);
        Ok(())
    }

    /// The profile's state at sample `n`.
    fn profiled(&mut self, n: u64) -> MotionState {
        self.profile.state_at(n.saturating_sub(self.origin_n) as f64 * self.period_s)
    }

    /// Starts a profile relative to the point `up_mm` above `pick`, its time 0 the last
    /// sample commanded (sample `n − 1`, read `back` reads ago): that sample's state relative
    /// to the point to rest on it.
    fn intercept(&mut self, n: u64, pick: Pick, up_mm: f64, back: usize) -> Result<(), Lost> {
        let (q, v) = self.on_part(&pick, self.belt_at(back), up_mm)?;
        let from = MotionState {
            p: std::array::from_fn(|m| self.last.p[m] - q[m]),
            v: std::array::from_fn(|m| self.last.v[m] - v[m]),
            a: self.last.a,
        };
        let relative = self.relative;
        self.replan(n, |p| p.plan(&from, &[0.0; MAX_MOTORS], &relative))
    }

    /// Leaves the belt at sample `n` for the place (`pick`: with the part; `None`: after a
    /// pick given up, the gripper open — the place is clear of the belt).
    fn leave(&mut self, n: u64, pick: Option<Pick>) {
        let (from, limits, place) = (self.last, self.limits, self.place);
        let planned = self.replan(n, |p| p.plan(&from, &place, &limits));
        if planned.is_err() {
            // No profile from a finite state within the limits is a bug, not a belt: hold.
            let hold = MotionState::at_rest(self.last.p);
            let _ = self.replan(n, |p| p.plan(&hold, &hold.p, &limits));
        }
        self.phase = Phase::Place(pick);
    }

    /// Whether the dispatcher said `pick` is another robot's (one atomic load).
    #[inline]
    fn cancelled(&self, pick: &Pick) -> bool {
        self.shared.cancel.load(Ordering::Acquire) == pick.id
    }

    /// Gives `pick` up at sample `n` (the last sample commanded is `n − 1`'s): the gripper
    /// opens and the command goes to the place, from sample `n` on.
    fn give_up(&mut self, n: u64, pick: &Pick, why: GaveUp) {
        let _ = self.events.push(PickEvent::GaveUp { id: pick.id, why });
        self.grip = Some(false);
        self.leave(n, None);
        self.last = self.profiled(n);
    }

    /// Sample `n` on `pick`'s grip point: the gripper told to close once the effector is
    /// there ([`Picker::in_position`]) or has had [`SETTLE_MAX_S`], if it still closes inside
    /// the window — else the pick is given up, the command on to the place from this sample.
    fn settle(&mut self, n: u64, pick: Pick) {
        if !self.ride(n, &pick) {
            return;
        }
        if !self.closes_in_window(&pick) {
            // Sample n is commanded: the place from it, the gripper left open.
            let why = GaveUp::LeftWindow;
            let _ = self.events.push(PickEvent::GaveUp { id: pick.id, why });
            self.grip = Some(false);
            return self.leave(n + 1, None);
        }
        let waited = n.saturating_sub(self.settle_from);
        if self.in_position(&pick) || waited >= self.settle_samples {
            self.phase = Phase::Track(pick);
            self.grip = Some(true);
            let _ = self.events.push(PickEvent::Gripping { id: pick.id, cycle: n });
        }
    }

    /// Sample `n` on `pick`'s grip point, moving with the belt; false when the part is lost
    /// (past the window or out of reach): then the pick is given up.
    fn ride(&mut self, n: u64, pick: &Pick) -> bool {
        match self.on_part(pick, self.belt_at(0), 0.0) {
            Ok((q, v)) => {
                self.last = MotionState { p: q, v, a: [0.0; MAX_MOTORS] };
                true
            }
            Err(why) => {
                self.give_up(n, pick, why);
                false
            }
        }
    }

    /// The effector — the forward kinematics of this cycle's read of the motors — within
    /// [`GRIP_WITHIN_MM`] of `pick`'s grip point where this cycle's read of the belt has it:
    /// the distance `parts.csv` gives the grip.
    fn in_position(&self, pick: &Pick) -> bool {
        let act = [self.act[0], self.act[1], self.act[2]];
        let part = (pick.belt_mm, pick.across_mm, pick.latched_counts as f64);
        let error = self.belt_frame.effector_error_mm(act, self.belt_read as f64, part);
        error.is_some_and(|e| e <= GRIP_WITHIN_MM)
    }

    /// One sample `n` of the profile relative to the point `up_mm` above `pick`: the command
    /// on that point plus the profile; `Ok(true)` once the profile has ended.
    fn relative(&mut self, n: u64, pick: &Pick, up_mm: f64) -> Result<bool, Lost> {
        let r = self.profiled(n);
        let (q, v) = self.on_part(pick, self.belt_at(0), up_mm)?;
        self.last = MotionState {
            p: std::array::from_fn(|m| q[m] + r.p[m]),
            v: std::array::from_fn(|m| v[m] + r.v[m]),
            a: r.a,
        };
        Ok(n.saturating_sub(self.origin_n) as f64 * self.period_s >= self.profile.duration())
    }

    /// The orders of the command thread: a stop or a quit ends the picking (a part in the
    /// gripper is still placed); moves, lines and grips are not taken — the session picks.
    fn take_orders(&mut self, n: u64) {
        while let Ok(order) = self.orders.pop() {
            let refused = match order {
                Order::Move { id, .. } | Order::Grip { id, .. } => Some(id),
                Order::Line { id, queue } => {
                    let _ = self.spent.push(queue);
                    Some(id)
                }
                Order::Stop { .. } | Order::Quit { .. } => {
                    self.end_n = self.end_n.min(n);
                    None
                }
            };
            if let Some(id) = refused {
                self.serve.not_taken_why.store(NotTaken::Picking.wire(), Ordering::Release);
                self.serve.not_taken.store(id, Ordering::Release);
                self.serve.taken.store(id, Ordering::Release);
            }
        }
    }

    /// One sample of the phase, its state in `self.last`.
    fn step(&mut self, n: u64) {
        let ending = n >= self.end_n;
        match self.phase {
            Phase::Idle => {
                self.last = MotionState::at_rest(self.last.p);
                if ending {
                    self.ended = true;
                } else if let Ok(pick) = self.picks.pop() {
                    self.shared.ready.store(false, Ordering::Release);
                    match self.intercept(n, pick, 0.0, 1) {
                        Ok(()) => {
                            let _ =
                                self.events.push(PickEvent::Intercepting { id: pick.id, cycle: n });
                            self.phase = Phase::Intercept(pick);
                            self.step(n);
                        }
                        Err(why) => self.give_up(n, &pick, why),
                    }
                }
            }
            Phase::Intercept(pick) => {
                if ending {
                    return self.give_up(n, &pick, GaveUp::Stopped);
                }
                if self.cancelled(&pick) {
                    return self.give_up(n, &pick, GaveUp::Elsewhere);
                }
                match self.relative(n, &pick, 0.0) {
                    // On the part: the gripper closes once the effector is there.
                    Ok(true) => {
                        (self.phase, self.settle_from) = (Phase::Settle(pick), n);
                        self.settle(n, pick);
                    }
                    Ok(false) => {}
                    Err(why) => self.give_up(n, &pick, why),
                }
            }
            Phase::Settle(pick) => {
                if ending {
                    return self.give_up(n, &pick, GaveUp::Stopped);
                }
                if self.cancelled(&pick) {
                    return self.give_up(n, &pick, GaveUp::Elsewhere);
                }
                self.settle(n, pick);
            }
            Phase::Track(pick) => {
                if self.ride(n, &pick) && self.gripper.reached(true) {
                    let _ = self.events.push(PickEvent::Lifted { id: pick.id });
                    // Off the belt, rising with it from the next sample; the place straight
                    // away if the point above is out of reach.
                    let next = n + 1;
                    match self.intercept(next, pick, LIFT_MM, 0) {
                        Ok(()) => self.phase = Phase::Lift(pick),
                        Err(_) => self.leave(next, Some(pick)),
                    }
                }
            }
            Phase::Lift(pick) => match self.relative(n, &pick, LIFT_MM) {
                Ok(false) => {}
                // Up: to the place, from this sample's state.
                Ok(true) => self.leave(n + 1, Some(pick)),
                Err(_) => {
                    // Held, so never given up: to the place from the last sample.
                    self.leave(n, Some(pick));
                    self.last = self.profiled(n);
                }
            },
            Phase::Place(pick) => {
                self.last = self.profiled(n);
                if n.saturating_sub(self.origin_n) as f64 * self.period_s >= self.profile.duration()
                {
                    self.last = MotionState::at_rest(self.last.p);
                    if let Some(pick) = pick {
                        self.grip = Some(false);
                        let _ = self.events.push(PickEvent::Placed { id: pick.id, cycle: n });
                    }
                    self.phase = Phase::Release;
                }
            }
            Phase::Release => {
                self.last = MotionState::at_rest(self.last.p);
                if self.grip != Some(true) && (self.grip.is_none() || self.gripper.reached(false)) {
                    self.phase = Phase::Idle;
                    self.shared.ready.store(!ending, Ordering::Release);
                }
            }
        }
    }
}

/// [`relative_limits`] of the settings `s` at the belt `frame`: the motors' limits, the
/// simulated belt at its fastest (`speed_mm_s` or any of its `speed_steps`), the parts'
/// spread — what the picker plans by and the dispatcher checks a part by.
pub fn relative_limits_of(s: &Settings, frame: &BeltFrame) -> MotionLimits {
    let c = &s.conveyor;
    let fastest = c.speed_steps.iter().map(|s| s[1].abs()).fold(c.speed_mm_s.abs(), f64::max);
    relative_limits(frame, &MotionLimits::of(s), s.n_motors, fastest, s.camera.spread_mm)
}

/// What is left of each motor's `limits` in a part's frame: the velocity less what the belt
/// itself asks of the motor at `fastest_mm_s` anywhere in the window (across ±`spread_mm`/2;
/// a tenth kept in reserve), at least a fifth of it; the acceleration and jerk at four
/// fifths (the belt's own changes of speed and of the arms' leverage take the rest).
pub fn relative_limits(
    f: &BeltFrame,
    limits: &MotionLimits,
    n_motors: usize,
    fastest_mm_s: f64,
    spread_mm: f64,
) -> MotionLimits {
    let mut belt = [0.0f64; MAX_MOTORS];
    for k in 0..=8 {
        let along = f.window_mm[0] + (f.window_mm[1] - f.window_mm[0]) * f64::from(k) / 8.0;
        for across in [-spread_mm / 2.0, 0.0, spread_mm / 2.0] {
            // The counts a mm of belt takes, centred on the point.
            let (a, b) = (f.counts(along - 0.5, across), f.counts(along + 0.5, across));
            if let (Ok(a), Ok(b)) = (a, b) {
                for m in 0..n_motors {
                    belt[m] = belt[m].max((b[m] - a[m]).abs() * fastest_mm_s);
                }
            }
        }
    }
    let mut r = *limits;
    for (m, b) in belt.iter().enumerate().take(n_motors) {
        r.velocity[m] = (limits.velocity[m] - 1.1 * b).max(0.2 * limits.velocity[m]);
        r.acceleration[m] = 0.8 * limits.acceleration[m];
        r.jerk[m] = 0.8 * limits.jerk[m];
    }
    r
}

impl TrajectoryGenerator for Picker {
    fn name(&self) -> &'static str {
        "conveyor"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        self.last = MotionState::at_rest(*start);
        self.profile = Profile::new(self.n_motors, *start);
        // The gripper open before the first pick, whatever state it was left in.
        self.grip = Some(false);
        self.phase = Phase::Release;
        self.shared.ready.store(false, Ordering::Release);
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        None
    }

    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        Some([0.0; MAX_MOTORS])
    }

    #[inline]
    fn observe(&mut self, act: &[f64; MAX_MOTORS], _flags: &[MotorFlags; MAX_MOTORS]) {
        self.act = *act;
    }

    #[inline]
    fn belt(&mut self, counts: i64) {
        self.belt_read = counts;
    }

    #[inline]
    fn gripper(&mut self, state: Gripper) -> Option<bool> {
        self.gripper = state;
        self.grip
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if self.ended {
            return Sample::Done;
        }
        self.belt.read(n, self.belt_read);
        self.take_orders(n);
        if n >= self.end_n {
            self.shared.ending.store(true, Ordering::Release);
            self.shared.ready.store(false, Ordering::Release);
        }
        self.step(n);
        *cmd = self.last.p;
        self.serve.moving.store(self.phase != Phase::Idle, Ordering::Release);
        Sample::Ready
    }
}
