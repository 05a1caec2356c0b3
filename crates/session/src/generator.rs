//! `qmarc-starter serve`: the generator of a controller that takes commands while the robot
//! holds. [`ServeMove`] holds the command where it is until an [`Order`] arrives through a
//! wait-free queue from the command thread (`qmarc/command`, in the controller process): a
//! new target or a stop takes over from the command's position, velocity and acceleration in
//! the cycle it arrives ([`OnlineMove::retarget`]); a straight line, planned by the command
//! thread from rest, is sampled from its queue. What became of the orders goes back through
//! atomics ([`ServeShared`]; where the robot is, the loop says itself: its
//! [`LoopStatus`]); a line's spent queue goes back through a second queue, so the servo
//! thread never frees memory.

use qmarc_config::Settings;
use qmarc_controller::status::LoopStatus;
use qmarc_controller::traj::{Sample, TrajStartError, TrajectoryGenerator};
use qmarc_plugins::motion::{MotionLimits, MotionState};
use qmarc_plugins::online::{OnlineMove, RetargetError};
use qmarc_proto::{Gripper, MAX_MOTORS};
use rtrb::{Consumer, Producer, RingBuffer};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, AtomicU64, Ordering};

/// Orders queued for the loop at most (the command thread refuses more as busy).
pub const ORDER_QUEUE: usize = 16;

/// How far a line's first sample may be from where the command rests, counts (the line is
/// planned from the command's rest, through the kinematics and back).
pub const LINE_START_COUNTS: f64 = 0.5;

/// A command line's samples, one per servo period.
pub type LineQueue = Box<[[f64; MAX_MOTORS]]>;

/// Each motor's soft limits, counts: (lowest, highest); a motor the robot has not, unbounded.
pub type SoftLimits = [(f64, f64); MAX_MOTORS];

/// The limits a serving session moves under, derived from its settings once: the command
/// thread checks and plans every order by them, and they bound every profile the loop takes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ServeLimits {
    /// The motors' velocity, acceleration and jerk limits at full speed (`[[safety]]`).
    pub motion: MotionLimits,
    /// Each motor's soft limits, counts, while they hold (the frame homed); `None` when the
    /// session runs `--unhomed`.
    pub soft: Option<SoftLimits>,
    /// The fraction of `motion` an approach runs at (`trajectory.approach_speed`).
    pub approach_speed: f64,
}

impl ServeLimits {
    /// The limits of `settings`; without soft limits if `unhomed`.
    pub fn of(settings: &Settings, unhomed: bool) -> ServeLimits {
        let mut soft = [(f64::NEG_INFINITY, f64::INFINITY); MAX_MOTORS];
        for (m, s) in settings.safety.iter().enumerate().take(settings.n_motors) {
            soft[m] = (s.soft_limits[0], s.soft_limits[1]);
        }
        ServeLimits {
            motion: MotionLimits::of(settings),
            soft: (!unhomed).then_some(soft),
            approach_speed: settings.trajectory.approach_speed,
        }
    }
}

/// What the command thread asks of the loop.
pub enum Order {
    /// To `target` (counts) under `limits`.
    Move {
        /// The move's id.
        id: u64,
        /// Where to, counts.
        target: [f64; MAX_MOTORS],
        /// Its limits (the speed applied).
        limits: MotionLimits,
    },
    /// Along `queue` from where the robot rests (its first sample).
    Line {
        /// The move's id.
        id: u64,
        /// Its samples.
        queue: LineQueue,
    },
    /// To rest, jerk-limited, under `limits`.
    Stop {
        /// The stop's id.
        id: u64,
        /// Its limits.
        limits: MotionLimits,
    },
    /// Close the gripper (`close`) or open it; settled once it is there and the command at
    /// rest.
    Grip {
        /// The order's id.
        id: u64,
        /// Close it.
        close: bool,
    },
    /// Stop, then end the move (the session).
    Quit {
        /// The stop's limits.
        limits: MotionLimits,
    },
}

/// Why the loop did not take an order it was given: the state the robot was in when it
/// arrived is the command thread's to guess, not to know.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NotTaken {
    /// No jerk-limited profile from the command's state to the target.
    NoProfile,
    /// The way there would carry motor `.0` (1-based) outside its soft limits.
    SoftLimits(u32),
    /// A line or path starts from rest where the command rests: the robot moved, or rested
    /// elsewhere, when it arrived.
    NotFromRest,
    /// The session picks from the belt by itself (`conveyor`): it takes no moves, lines or
    /// grips; a stop or a quit ends its picking.
    Picking,
}

impl NotTaken {
    /// Its number on the wire ([`ServeShared::not_taken_why`], a command's answer).
    pub fn wire(self) -> u32 {
        match self {
            NotTaken::NoProfile => 1,
            NotTaken::SoftLimits(m) => 2 | m << 8,
            NotTaken::NotFromRest => 3,
            NotTaken::Picking => 4,
        }
    }

    /// The reason of wire number `wire`, if it is one.
    pub fn from_wire(wire: u32) -> Option<NotTaken> {
        match wire & 0xff {
            1 => Some(NotTaken::NoProfile),
            2 => Some(NotTaken::SoftLimits(wire >> 8)),
            3 => Some(NotTaken::NotFromRest),
            4 => Some(NotTaken::Picking),
            _ => None,
        }
    }

    /// What it says to the user.
    pub fn words(self) -> String {
        match self {
            NotTaken::NoProfile => {
                "there was no jerk-limited profile from the command's state to the target".into()
            }
            NotTaken::SoftLimits(m) => format!(
                "from the state the robot was in, its way would have carried motor {m} outside \
                 its soft limits"
            ),
            NotTaken::NotFromRest => {
                "it starts from rest where the command rests, and the robot was moving or \
                 elsewhere when it arrived"
                    .into()
            }
            NotTaken::Picking => "the session picks from the belt by itself: it takes no \
                                  moves, lines or grips (stop or quit end its picking)"
                .into(),
        }
    }
}

/// What became of the orders, for the command thread: written by the servo thread with
/// atomic stores only.
#[derive(Debug, Default)]
pub struct ServeShared {
    /// The last order whose end the command has come to rest at.
    pub settled: AtomicU64,
    /// The last order the loop took.
    pub taken: AtomicU64,
    /// When it took it (in the cycle whose command is the new one's first), ns of
    /// `CLOCK_MONOTONIC` (read through the vDSO: no system call).
    pub taken_ns: AtomicU64,
    /// The cycles executed when it took it, that cycle included.
    pub taken_cycle: AtomicU64,
    /// The last move the loop could not take (no profile, or one leaving the soft limits).
    pub not_taken: AtomicU64,
    /// Why it could not ([`NotTaken::wire`]).
    pub not_taken_why: AtomicU32,
    /// The last motion order the loop took (a move, a line, a stop; not a grip).
    pub motion: AtomicU64,
    /// The command moves.
    pub moving: AtomicBool,
}

/// The command thread's end of a [`ServeMove`].
pub struct ServeHandle {
    /// Orders to the loop.
    pub orders: Producer<Order>,
    /// Lines the loop is done with, to be freed here.
    pub spent: Consumer<LineQueue>,
    /// What became of the orders.
    pub shared: Arc<ServeShared>,
    /// What the loop is doing, as it says it.
    pub status: Arc<LoopStatus>,
    /// A conveyor session's belt and parts, as its dispatcher counts them.
    pub conveyor: Option<Arc<crate::wire::ConveyorTally>>,
}

struct Line {
    queue: LineQueue,
    from_n: u64,
}

/// The serving generator: holds, moves to targets, stops, follows lines, never ends until a
/// quit has brought it to rest.
pub struct ServeMove {
    online: OnlineMove,
    orders: Consumer<Order>,
    spent: Producer<LineQueue>,
    shared: Arc<ServeShared>,
    /// The loop's status: its cycles, when an order is taken.
    status: Arc<LoopStatus>,
    line: Option<Line>,
    current: u64,
    quitting: bool,
    /// A quit's stop has come to rest: the next sample ends the move.
    ended: bool,
    /// What the gripper was last told (`None`: nothing yet, it stays as it is).
    grip: Option<bool>,
    /// The gripper is where it was last told to be (or was told nothing).
    grip_arrived: bool,
    period_s: f64,
    n_motors: usize,
}

impl ServeMove {
    /// A serving generator for `settings` and its command thread's handle, in the loop whose
    /// status is `status`; `limits.soft`, when the frame is homed and the soft limits hold,
    /// bounds every profile it takes.
    pub fn new(
        settings: &Settings,
        limits: &ServeLimits,
        status: Arc<LoopStatus>,
    ) -> (ServeMove, ServeHandle) {
        let mut online = OnlineMove::new(
            [0.0; MAX_MOTORS],
            settings.n_motors,
            settings.period_s(),
            limits.motion,
        );
        if let Some(soft) = limits.soft {
            online = online.with_soft_limits(soft);
        }
        let (orders_tx, orders) = RingBuffer::new(ORDER_QUEUE);
        let (spent, spent_rx) = RingBuffer::new(ORDER_QUEUE + 1);
        let shared = Arc::new(ServeShared::default());
        let serve = ServeMove {
            online,
            orders,
            spent,
            shared: shared.clone(),
            status: status.clone(),
            line: None,
            current: 0,
            quitting: false,
            ended: false,
            grip: None,
            grip_arrived: true,
            period_s: settings.period_s(),
            n_motors: settings.n_motors,
        };
        (serve, ServeHandle { orders: orders_tx, spent: spent_rx, shared, status, conveyor: None })
    }

    /// The state of the last sample commanded: the line's or the online profile's. A line's
    /// velocity and acceleration come from its last four samples' backward differences, exact
    /// for a cubic — which a jerk-limited motion is, segment by segment (the samples before
    /// the line are its first: at rest).
    fn state_now(&self) -> (u64, MotionState) {
        let (n, mut state) = self.online.last();
        let Some(line) = &self.line else { return (n, state) };
        let k = n.saturating_sub(line.from_n) as usize;
        // A line is left at its last sample, so k is never past it; the bound only keeps the
        // loop from ever panicking.
        let last = line.queue.len().saturating_sub(1);
        let q = |back: usize| line.queue[k.saturating_sub(back).min(last)];
        let t = self.period_s;
        let (q0, q1, q2, q3) = (q(0), q(1), q(2), q(3));
        for m in 0..self.n_motors {
            state.p[m] = q0[m];
            state.v[m] = (11.0 * q0[m] - 18.0 * q1[m] + 9.0 * q2[m] - 2.0 * q3[m]) / (6.0 * t);
            state.a[m] = (2.0 * q0[m] - 5.0 * q1[m] + 4.0 * q2[m] - q3[m]) / (t * t);
        }
        (n, state)
    }

    /// Leaves the line (if one runs) for the online profile, from its last sample's state.
    fn leave_line(&mut self) {
        if self.line.is_some() {
            let (n, state) = self.state_now();
            self.online.continue_from(n, state);
            if let Some(line) = self.line.take() {
                // Freed by the command thread; its queue has room for every line in flight.
                let _ = self.spent.push(line.queue);
            }
        }
    }

    /// Takes the orders that have arrived, the last of each kind winning in turn.
    fn take_orders(&mut self, n: u64) {
        while let Ok(order) = self.orders.pop() {
            match order {
                Order::Move { id, target, limits } => {
                    let line = self.line.is_some();
                    self.leave_line();
                    match self.online.retarget(&target, &limits) {
                        Ok(()) => self.current = id,
                        Err(e) => {
                            let why = match e {
                                RetargetError::SoftLimits { motor, .. } => {
                                    NotTaken::SoftLimits(motor as u32)
                                }
                                RetargetError::NoProfile(_) => NotTaken::NoProfile,
                                // A reason the plug-ins add later: no profile the loop took.
                                _ => NotTaken::NoProfile,
                            };
                            self.shared.not_taken_why.store(why.wire(), Ordering::Release);
                            self.shared.not_taken.store(id, Ordering::Release);
                            if line {
                                let _ = self.online.stop(&limits);
                            }
                        }
                    }
                    self.shared.motion.store(id, Ordering::Release);
                    self.took(id);
                }
                Order::Stop { id, limits } => {
                    self.leave_line();
                    let _ = self.online.stop(&limits);
                    self.current = id;
                    self.shared.motion.store(id, Ordering::Release);
                    self.took(id);
                }
                Order::Line { id, queue } => {
                    self.leave_line();
                    // A line starts where the command rests (the command thread planned it
                    // from there); one that does not would jump: not taken.
                    let (_, now) = self.online.last();
                    let off = queue.first().is_none_or(|q| {
                        (0..self.n_motors).any(|m| (q[m] - now.p[m]).abs() > LINE_START_COUNTS)
                    });
                    if off || self.online.moving() {
                        let why = NotTaken::NotFromRest.wire();
                        self.shared.not_taken_why.store(why, Ordering::Release);
                        self.shared.not_taken.store(id, Ordering::Release);
                        let _ = self.spent.push(queue);
                    } else {
                        // Its first sample (where the robot rests) is this cycle's.
                        self.line = Some(Line { queue, from_n: n });
                        self.current = id;
                        self.shared.motion.store(id, Ordering::Release);
                    }
                    self.took(id);
                }
                Order::Grip { id, close } => {
                    self.grip = Some(close);
                    self.grip_arrived = false;
                    self.current = id;
                    self.took(id);
                }
                Order::Quit { limits } => {
                    self.leave_line();
                    let _ = self.online.stop(&limits);
                    self.quitting = true;
                }
            }
        }
    }

    /// Order `id` taken now, in this cycle.
    fn took(&self, id: u64) {
        self.shared.taken_ns.store(qmarc_timer::clock::monotonic_now_ns(), Ordering::Release);
        let cycle = self.status.cycles() + 1;
        self.shared.taken_cycle.store(cycle, Ordering::Release);
        self.shared.taken.store(id, Ordering::Release);
    }

    fn publish(&self, moving: bool) {
        self.shared.moving.store(moving, Ordering::Release);
        if !moving && self.grip_arrived {
            self.shared.settled.store(self.current, Ordering::Release);
        }
    }
}

impl TrajectoryGenerator for ServeMove {
    fn name(&self) -> &'static str {
        "serve"
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        self.online.continue_from(0, MotionState::at_rest(*start));
        self.publish(false);
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        None
    }

    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        Some([0.0; MAX_MOTORS])
    }

    #[inline]
    fn gripper(&mut self, state: Gripper) -> Option<bool> {
        // Told and there: the order settles with the next sample at rest.
        self.grip_arrived |= self.grip.is_some_and(|c| state.reached(c));
        self.grip
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if self.ended {
            return Sample::Done;
        }
        self.take_orders(n);
        if let Some(line) = &self.line {
            let k = n.saturating_sub(line.from_n) as usize;
            if k + 1 < line.queue.len() {
                *cmd = line.queue[k];
                self.online.continue_from(n, MotionState::at_rest(*cmd));
                self.publish(true);
                return Sample::Ready;
            }
            *cmd = line.queue[line.queue.len() - 1];
            self.online.continue_from(n, MotionState::at_rest(*cmd));
            if let Some(line) = self.line.take() {
                let _ = self.spent.push(line.queue);
            }
            self.publish(false);
            return Sample::Ready;
        }
        let moving = match self.online.sample(n, cmd) {
            Sample::Ready => self.online.moving(),
            _ => {
                // At rest on the target: hold it, from this sample on.
                *cmd = *self.online.target();
                self.online.continue_from(n, MotionState::at_rest(*cmd));
                false
            }
        };
        self.publish(moving);
        // The rest a quit's stop comes to is commanded once; the sample after it ends.
        if self.quitting && !moving {
            self.ended = true;
        }
        Sample::Ready
    }
}

#[cfg(test)]
mod tests;
