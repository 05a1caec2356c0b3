//! The command thread of a serving controller. It serves `qmarc/command` and `qmarc/path`
//! ([`crate::wire`]) beside the servo thread: it checks each command — the target
//! reachable, inside the soft limits, the frame homed, the loop still serving — and answers
//! at once, then hands what it accepted to the loop's [`ServeMove`] through a wait-free queue.
//! It plans straight lines itself (from rest; [`LinearMove`]) and frees the loop's spent ones.
//! It is a SCHED_OTHER thread: nothing in it is on the loop's time.

use crate::generator::{
    LineQueue, NotTaken, Order, ServeHandle, ServeLimits, ServeMove, ServeShared,
};
use crate::path::{outside_soft_limits, path_queue};
use crate::wire::{
    Answer, COMMAND_SERVICE, CommandKind, CommandRequest, CommandResponse, Orders, PATH_SERVICE,
    PathRequest, Refusal, Refused, RobotStatus, Services, Timing,
};
use iceoryx2::prelude::ipc;
use qmarc_config::{Settings, TargetError};
use qmarc_controller::status::LoopStatus;
use qmarc_controller::traj::TrajectoryGenerator;
use qmarc_plugins::linear::LinearMove;
use qmarc_plugins::motion::{MotionLimits, MotionState, Profile};
use qmarc_plugins::moveto::approach_queue;
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::service::{IpcLocation, ServiceError, create_node};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::time::Duration;

/// How often the command thread looks whether it is to end, at the latest.
const POLL: Duration = Duration::from_millis(20);

/// How the session ended, for the answers after it: set by the controller's main thread.
#[derive(Debug, Default)]
pub struct Ended {
    /// The loop has ended.
    pub ended: AtomicBool,
    /// Its fault ([`qmarc_proto::state::FaultKind::wire`]), 0 for none.
    pub fault: AtomicU32,
    /// The command thread is to end.
    pub stop: AtomicBool,
}

/// The serving generator for `settings` (soft limits on its profiles unless `unhomed`) in the
/// loop whose status is `status`, and the command thread's end of it.
pub fn generator(
    settings: &Settings,
    unhomed: bool,
    status: Arc<LoopStatus>,
) -> (Box<dyn TrajectoryGenerator>, ServeHandle) {
    let (serve, handle) = ServeMove::new(settings, &ServeLimits::of(settings, unhomed), status);
    (Box::new(serve), handle)
}

/// The command thread's state.
struct Commands {
    settings: Settings,
    /// The limits every order is checked and planned by.
    limits: ServeLimits,
    unhomed: bool,
    handle: ServeHandle,
    ended: Arc<Ended>,
    /// The last order id given.
    seq: u64,
    /// The last move accepted.
    accepted: u64,
    /// The loop's executed cycles right after the last order was queued.
    queued_at: u64,
}

/// The command thread: it serves from [`CommandThread::spawn`] until dropped.
pub struct CommandThread {
    ended: Arc<Ended>,
    thread: Option<std::thread::JoinHandle<()>>,
}

impl CommandThread {
    /// Starts the command thread of the run at `location`: its service exists when this
    /// returns.
    pub fn spawn(
        location: &IpcLocation,
        settings: &Settings,
        unhomed: bool,
        handle: ServeHandle,
    ) -> Result<CommandThread, ServiceError> {
        let ended = Arc::new(Ended::default());
        let mut commands = Commands {
            settings: settings.clone(),
            limits: ServeLimits::of(settings, unhomed),
            unhomed,
            handle,
            ended: ended.clone(),
            seq: 0,
            accepted: 0,
            queued_at: 0,
        };
        let location = location.clone();
        // iceoryx2's ports stay on the thread that made them: made there, reported back.
        let (ready, opened) = std::sync::mpsc::channel();
        let thread = std::thread::Builder::new()
            .name("qmarc-commands".into())
            .spawn(move || {
                let ports = (|| {
                    let node = create_node::<ipc::Service>("qmarc-commands", &location)?;
                    let services = Services::open(&node, true)?;
                    let port = |what: &str, e: &dyn std::fmt::Debug| {
                        ServiceError::new(what, COMMAND_SERVICE, e)
                    };
                    let server = services
                        .command
                        .server_builder()
                        .create()
                        .map_err(|e| port("server", &e))?;
                    let path_server = services
                        .path
                        .server_builder()
                        .create()
                        .map_err(|e| ServiceError::new("server", PATH_SERVICE, e))?;
                    let listener = services
                        .wake
                        .listener_builder()
                        .create()
                        .map_err(|e| port("listener", &e))?;
                    Ok((node, server, path_server, listener))
                })();
                let (_node, server, path_server, listener) = match ports {
                    Ok(p) => {
                        let _ = ready.send(Ok(()));
                        p
                    }
                    Err(e) => {
                        let _ = ready.send(Err(e));
                        return;
                    }
                };
                while !commands.ended.stop.load(Ordering::Acquire) {
                    let _ = listener.timed_wait(|_| {}, POLL);
                    while let Ok(Some(active)) = server.receive() {
                        let answer = commands.guarded(|c| c.answer(active.payload()));
                        let _ = active.send_copy(answer);
                    }
                    while let Ok(Some(active)) = path_server.receive() {
                        let answer = commands.guarded(|c| c.answer_path(active.payload()));
                        let _ = active.send_copy(answer);
                    }
                    // The loop's spent lines are freed here, not on the servo thread.
                    while commands.handle.spent.pop().is_ok() {}
                }
            })
            .map_err(|e| ServiceError::new("thread", "qmarc-commands", e))?;
        let opened = opened.recv().unwrap_or_else(|_| {
            Err(ServiceError::new("thread", "qmarc-commands", "ended before serving"))
        });
        if let Err(e) = opened {
            let _ = thread.join();
            return Err(e);
        }
        Ok(CommandThread { ended, thread: Some(thread) })
    }

    /// The loop has ended, with the fault `fault` ([`qmarc_proto::state::FaultKind::wire`]):
    /// every command from now on is refused as not serving.
    pub fn ended(&self, fault: u32) {
        self.ended.fault.store(fault, Ordering::Release);
        self.ended.ended.store(true, Ordering::Release);
    }
}

impl Drop for CommandThread {
    fn drop(&mut self) {
        self.ended.ended.store(true, Ordering::Release);
        self.ended.stop.store(true, Ordering::Release);
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

impl Commands {
    fn shared(&self) -> &ServeShared {
        &self.handle.shared
    }

    /// What the loop is doing, as it says it.
    fn status(&self) -> &LoopStatus {
        &self.handle.status
    }

    /// `answer(self)`, or — should a check panic on a request no one foresaw — a refusal that
    /// says so: the thread, and with it every client's way to stop the robot, goes on.
    fn guarded(
        &mut self,
        answer: impl FnOnce(&mut Commands) -> CommandResponse,
    ) -> CommandResponse {
        std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| answer(self))).unwrap_or_else(
            |_| {
                let mut r = self.report();
                let why = "the controller could not check this request (an internal error)";
                r.answer.refuse(&Refused::new(Refusal::BadRequest, why));
                r
            },
        )
    }

    /// Whether the loop serves orders: not ended, and begun.
    fn serving(&self) -> Result<(), Refused> {
        if self.ended.ended.load(Ordering::Acquire) {
            return Err(Refused::new(Refusal::NotServing, "the session has ended"));
        }
        if !self.status().begun() {
            return Err(Refused::new(
                Refusal::Busy,
                "the session is starting: its loop has not begun (qmarc cmd status says when)",
            ));
        }
        Ok(())
    }

    /// The answer to `req`.
    fn answer(&mut self, req: &CommandRequest) -> CommandResponse {
        let received_ns = qmarc_timer::clock::monotonic_now_ns();
        let kind = CommandKind::from_wire(req.kind);
        let outcome = match kind {
            None => Err(Refused::new(Refusal::BadRequest, format!("unknown command {}", req.kind))),
            Some(CommandKind::Status) => Ok(()),
            Some(k) => self.serving().and_then(|()| self.order(k, req)),
        };
        self.respond(req.id, received_ns, kind != Some(CommandKind::Status), outcome)
    }

    /// The answer to the path `req`: checked, sampled, queued.
    fn answer_path(&mut self, req: &PathRequest) -> CommandResponse {
        let received_ns = qmarc_timer::clock::monotonic_now_ns();
        let outcome = self.serving().and_then(|()| self.path(req));
        self.respond(req.id, received_ns, true, outcome)
    }

    /// The response to request `id`, read at `received_ns`, with `outcome` (`order`: it was
    /// one, and the response says when it was queued).
    fn respond(
        &self,
        id: u64,
        received_ns: u64,
        order: bool,
        outcome: Result<(), Refused>,
    ) -> CommandResponse {
        let mut r = self.report();
        r.timing.received_ns = received_ns;
        r.answer.id = id;
        match outcome {
            Ok(()) => {
                r.answer.ok = 1;
                r.orders.accepted = self.accepted;
                if order {
                    r.timing.received_cycle = self.queued_at;
                }
            }
            Err(refused) => r.answer.refuse(&refused),
        }
        r
    }

    /// An order of `kind` (not a status) to the serving loop.
    fn order(&mut self, kind: CommandKind, req: &CommandRequest) -> Result<(), Refused> {
        match kind {
            CommandKind::Status => Ok(()),
            CommandKind::Move => self.move_to(req),
            CommandKind::Stop => {
                let limits = self.limits.motion;
                self.give(|id| Order::Stop { id, limits }).map(|id| self.accepted = id)
            }
            CommandKind::Quit => {
                let limits = self.limits.motion;
                self.give(|_| Order::Quit { limits }).map(|_| ())
            }
            CommandKind::Grip if self.settings.s626.gripper_dio.is_none() => Err(Refused::new(
                Refusal::NoGripper,
                "no gripper is wired: set [s626] gripper_dio to its output",
            )),
            CommandKind::Grip => {
                let close = req.flags & CommandRequest::CLOSE != 0;
                self.give(|id| Order::Grip { id, close }).map(|id| self.accepted = id)
            }
        }
    }

    /// A path: from rest, in the homed frame (unless `--unhomed`), checked as a knot file is.
    fn path(&mut self, req: &PathRequest) -> Result<(), Refused> {
        if !self.unhomed {
            self.homed()?;
        }
        self.at_rest("a path")?;
        let start = self.status().command();
        let (mut queue, from) = match req.knots().first().filter(|_| req.approached()) {
            // `--approach`: first to the path's first knot, as `run --approach` goes.
            Some(first) => {
                let s = &self.settings;
                let mut to = start;
                to[..s.n_motors].copy_from_slice(&first.pos[..s.n_motors]);
                let limits = self.limits.motion.at_speed(self.limits.approach_speed);
                let way = approach_queue(&start, &to, s.n_motors, &limits, s.period_s())
                    .map_err(|e| Refused::new(Refusal::BadRequest, format!("the approach: {e}")))?;
                if let Some((m, k, [lo, hi])) =
                    self.limits.soft.and_then(|soft| outside_soft_limits(&way, &soft[..s.n_motors]))
                {
                    return Err(Refused::new(
                        Refusal::SoftLimits,
                        format!(
                            "the approach takes motor {} to {:.0} counts, outside its soft \
                             limits [{lo}, {hi}]",
                            m + 1,
                            way[k][m]
                        ),
                    ));
                }
                (way, to)
            }
            None => (Vec::new(), start),
        };
        queue.extend(path_queue(req, &from, &self.settings, self.limits.soft)?);
        let id = self.give(|id| Order::Line { id, queue: queue.into_boxed_slice() })?;
        self.accepted = id;
        Ok(())
    }

    /// Every motor's frame is homed.
    fn homed(&self) -> Result<(), Refused> {
        let homed = self.status().homed();
        match (0..self.settings.n_motors).find(|m| homed & (1 << m) == 0) {
            None => Ok(()),
            Some(m) => Err(Refused::new(
                Refusal::NotHomed,
                format!("motor {} is not homed: home the robot first (qmarc-starter home)", m + 1),
            )),
        }
    }

    /// The robot rests at the end of every order given: `what` starts from rest.
    fn at_rest(&self, what: &str) -> Result<(), Refused> {
        let shared = self.shared();
        let at_rest = !shared.moving.load(Ordering::Acquire)
            && shared.settled.load(Ordering::Acquire) >= self.accepted
            && shared.taken.load(Ordering::Acquire) >= self.seq;
        if at_rest {
            return Ok(());
        }
        Err(Refused::new(
            Refusal::Moving,
            format!("{what} starts from rest: wait for the move to end (qmarc cmd wait)"),
        ))
    }

    /// Queues the order `make(id)` for the loop under a new id.
    fn give(&mut self, make: impl FnOnce(u64) -> Order) -> Result<u64, Refused> {
        let id = self.seq + 1;
        self.handle.orders.push(make(id)).map_err(|_| {
            Refused::new(Refusal::Busy, "the loop has not taken the last commands yet")
        })?;
        self.queued_at = self.status().cycles();
        self.seq = id;
        Ok(id)
    }

    /// Where the robot is, and what became of the orders.
    fn report(&self) -> CommandResponse {
        let shared = self.shared();
        let orders = Orders {
            accepted: self.accepted,
            settled: shared.settled.load(Ordering::Acquire),
            taken: shared.taken.load(Ordering::Acquire),
            not_taken: shared.not_taken.load(Ordering::Acquire),
            motion: shared.motion.load(Ordering::Acquire),
            moving: u32::from(shared.moving.load(Ordering::Acquire)),
            reserved: 0,
        };
        let status = self.status();
        let command = status.command();
        let robot = RobotStatus {
            phase: status.phase().wire(),
            fault: self.ended.fault.load(Ordering::Acquire),
            homed: status.homed(),
            gripper: status.gripper().0,
            command,
            actual: status.actual(),
            effector_mm: self
                .settings
                .robot()
                .and_then(|robot| robot.mm_of(&[command[0], command[1], command[2]]).ok())
                .unwrap_or([f64::NAN; 3]),
        };
        let timing = Timing {
            received_ns: 0,
            received_cycle: status.cycles(),
            taken_ns: shared.taken_ns.load(Ordering::Acquire),
            taken_cycle: shared.taken_cycle.load(Ordering::Acquire),
        };
        let mut answer = Answer::default();
        if self.ended.ended.load(Ordering::Acquire) {
            answer.refusal = Refusal::NotServing as u32;
        }
        // The last order not taken, and why (`qmarc cmd wait` says it).
        if orders.not_taken >= orders.accepted && orders.accepted > 0 {
            let why = NotTaken::from_wire(shared.not_taken_why.load(Ordering::Acquire));
            answer.set_reason(
                &why.map_or_else(|| "the loop did not take it".to_string(), NotTaken::words),
            );
        }
        let conveyor = self.handle.conveyor.as_ref().map(|t| t.get()).unwrap_or_default();
        CommandResponse { answer, orders, robot, timing, conveyor }
    }

    /// A move: checked, then queued.
    fn move_to(&mut self, req: &CommandRequest) -> Result<(), Refused> {
        let s = &self.settings;
        let n = s.n_motors;
        let bad = |why: String| Refused::new(Refusal::BadRequest, why);
        if !(req.speed.is_finite() && req.speed > 0.0 && req.speed <= 1.0) {
            return Err(bad(format!("speed must be > 0 and ≤ 1, found {}", req.speed)));
        }
        let xyz = req.flags & CommandRequest::XYZ != 0;
        let linear = req.flags & CommandRequest::LINEAR != 0;
        let used = if xyz { 3 } else { n };
        if let Some(v) = req.target[..used].iter().find(|v| !v.is_finite()) {
            return Err(bad(format!("the target must be finite numbers, found {v}")));
        }
        if linear && !xyz {
            return Err(bad("a straight line needs a Cartesian target (xyz)".into()));
        }
        // A point needs the homed frame the kinematics count from, --unhomed or not.
        if xyz || !self.unhomed {
            self.homed()?;
        }
        let mut target = [0.0; MAX_MOTORS];
        if xyz {
            let counts = s.counts_of_point([req.target[0], req.target[1], req.target[2]]);
            target[..3].copy_from_slice(&counts.map_err(refusal_of)?);
        } else {
            target[..n].copy_from_slice(&req.target[..n]);
            s.check_target(&target[..n]).map_err(refusal_of)?;
        }
        let limits = self.limits.motion.at_speed(req.speed);
        if !linear {
            // What the loop will plan, planned from where the command is now (at rest there, if
            // it moves): a move with no profile (a speed so small that its limits vanish) is
            // refused now, in the words the starter's move gives, not accepted and never taken.
            let start = self.status().command();
            let mut profile = Profile::new(n, start);
            profile
                .plan(&MotionState::at_rest(start), &target, &limits)
                .map_err(|e| bad(e.to_string()))?;
        }
        let id = if linear {
            let queue = self.line_to([req.target[0], req.target[1], req.target[2]], &limits)?;
            self.give(|id| Order::Line { id, queue })?
        } else {
            self.give(|id| Order::Move { id, target, limits })?
        };
        self.accepted = id;
        Ok(())
    }

    /// The straight line from where the robot rests to `mm`, sampled.
    fn line_to(&self, mm: [f64; 3], limits: &MotionLimits) -> Result<LineQueue, Refused> {
        self.at_rest("a straight line")?;
        let robot = self.settings.robot().ok_or(Refused::new(
            Refusal::BadRequest,
            "no [robot] table for 3 motors: a line needs the Delta's geometry",
        ))?;
        let mut line = LinearMove::new(robot, mm, self.settings.period_s(), *limits);
        let start = self.status().command();
        line.start(&start).map_err(|e| Refused::new(Refusal::Unreachable, e.to_string()))?;
        let queue = line.into_queue();
        if let Some((m, k, [lo, hi])) = self
            .limits
            .soft
            .and_then(|soft| outside_soft_limits(&queue, &soft[..self.settings.n_motors]))
        {
            return Err(Refused::new(
                Refusal::SoftLimits,
                format!(
                    "the line takes motor {} to {:.0} counts, outside its soft limits [{lo}, {hi}]",
                    m + 1,
                    queue[k][m]
                ),
            ));
        }
        Ok(queue.into_boxed_slice())
    }
}

/// The refusal a target's error stands for, with its words.
fn refusal_of(e: TargetError) -> Refused {
    let kind = match e {
        TargetError::Unreachable { .. } => Refusal::Unreachable,
        TargetError::SoftLimits { .. } => Refusal::SoftLimits,
        _ => Refusal::BadRequest,
    };
    Refused::new(kind, e.to_string())
}
