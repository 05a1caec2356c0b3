//! The wire of a serving session (`qmarc-starter serve`): two iceoryx2 request/response
//! services and one event, all opened by [`Services::open`] with the QoS both sides use.
//!
//! - `qmarc/command`: a fixed-size [`CommandRequest`] (a move, a stop, a grip, a status, a
//!   quit), answered with a [`CommandResponse`];
//! - `qmarc/path`: a whole timed path, [`PathRequest`] (up to [`MAX_PATH_KNOTS`] knots of time,
//!   position and optionally velocity per motor — what a ROS 2 `JointTrajectory` is), answered
//!   the same way. The request is fixed-size (74 KiB): one copy into shared memory, no
//!   allocation on either side's wire;
//! - `qmarc/command/request`: the event a client notifies after each request of either, so
//!   the server (the controller's command thread, [`crate::server`]) sleeps between them.
//!
//! Every request is answered at once: accepted, or refused with the reason. A move's end is
//! not waited for on the wire; the response's [`Orders`] (`accepted`, `settled`, … ids) say
//! where the robot is in the commands it was given ([`crate::client::OrderLedger`] reads them).

use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, request_response};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::service::ServiceError;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// Name of the request/response service.
pub const COMMAND_SERVICE: &str = "qmarc/command";
/// Name of the event a client notifies after each request.
pub const COMMAND_EVENT: &str = "qmarc/command/request";
/// Most clients at once (the console, a bridge, a cycle and a few `qmarc cmd`).
pub const MAX_COMMAND_CLIENTS: usize = 16;
/// Bytes of a refusal's reason (UTF-8, NUL-padded).
pub const REASON_BYTES: usize = 200;

/// What a request asks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum CommandKind {
    /// A move to `target` (counts, or mm with [`CommandRequest::XYZ`]).
    Move = 1,
    /// A jerk-limited stop to rest where the motors can.
    Stop = 2,
    /// Where the robot is; nothing else.
    Status = 3,
    /// Stop, then end the session as a move ends (its data files written).
    Quit = 4,
    /// Close the gripper ([`CommandRequest::CLOSE`]) or open it, now.
    Grip = 5,
}

impl CommandKind {
    /// Every kind, by wire number.
    pub const ALL: [CommandKind; 5] = [
        CommandKind::Move,
        CommandKind::Stop,
        CommandKind::Status,
        CommandKind::Quit,
        CommandKind::Grip,
    ];

    /// The kind of wire number `raw`.
    pub fn from_wire(raw: u32) -> Option<CommandKind> {
        CommandKind::ALL.into_iter().find(|k| *k as u32 == raw)
    }
}

/// Why a command was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Refusal {
    /// The request is not one this server reads (unknown kind, numbers that are not finite,
    /// a speed out of (0, 1]).
    BadRequest = 1,
    /// No arm angles put the effector at the point.
    Unreachable = 2,
    /// A motor's target is outside its soft limits.
    SoftLimits = 3,
    /// A motor's frame is not homed.
    NotHomed = 4,
    /// The loop has ended (a fault, a stop signal, a quit).
    NotServing = 5,
    /// What is asked needs the robot at rest (a straight line starts from rest).
    Moving = 6,
    /// The loop has not taken the last commands yet (its queue is full).
    Busy = 7,
    /// No gripper is wired (`s626.gripper_dio`).
    NoGripper = 8,
}

impl Refusal {
    /// Every refusal, by wire number.
    pub const ALL: [Refusal; 8] = [
        Refusal::BadRequest,
        Refusal::Unreachable,
        Refusal::SoftLimits,
        Refusal::NotHomed,
        Refusal::NotServing,
        Refusal::Moving,
        Refusal::Busy,
        Refusal::NoGripper,
    ];

    /// The refusal of wire number `raw`.
    pub fn from_wire(raw: u32) -> Option<Refusal> {
        Refusal::ALL.into_iter().find(|k| *k as u32 == raw)
    }

    /// Its name, as `qmarc cmd` prints it.
    pub fn name(self) -> &'static str {
        match self {
            Refusal::BadRequest => "bad_request",
            Refusal::Unreachable => "unreachable",
            Refusal::SoftLimits => "soft_limits",
            Refusal::NotHomed => "not_homed",
            Refusal::NotServing => "not_serving",
            Refusal::Moving => "moving",
            Refusal::Busy => "busy",
            Refusal::NoGripper => "no_gripper",
        }
    }
}

/// A request refused: its [`Refusal`] on the wire and why, in the words the client prints.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{} ({})", .why, .kind.name())]
pub struct Refused {
    /// What kind of refusal.
    pub kind: Refusal,
    /// Why, for the user (cut to [`REASON_BYTES`] on the wire).
    pub why: String,
}

impl Refused {
    /// A refusal of `kind` for `why`.
    pub fn new(kind: Refusal, why: impl Into<String>) -> Refused {
        Refused { kind, why: why.into() }
    }
}

/// A command.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("qmarc.CommandRequest.v2")]
#[repr(C)]
pub struct CommandRequest {
    /// [`CommandKind`] as its wire number.
    pub kind: u32,
    /// [`CommandRequest::XYZ`], [`CommandRequest::LINEAR`], [`CommandRequest::CLOSE`].
    pub flags: u32,
    /// The client's number for it, echoed in the response.
    pub id: u64,
    /// A move's speed: a fraction of the motors' limits, 0 < speed ≤ 1.
    pub speed: f64,
    /// A move's target: joint counts per motor, or x, y, z in mm with [`CommandRequest::XYZ`].
    pub target: [f64; MAX_MOTORS],
}

impl CommandRequest {
    /// The target is an effector point in mm (x, y, z), not joint counts.
    pub const XYZ: u32 = 1;
    /// A straight line in Cartesian space (with [`CommandRequest::XYZ`]).
    pub const LINEAR: u32 = 2;
    /// A grip closes the gripper (else it opens it).
    pub const CLOSE: u32 = 4;

    /// Close the gripper (`close`) or open it.
    pub fn grip(close: bool) -> CommandRequest {
        let flags = if close { CommandRequest::CLOSE } else { 0 };
        CommandRequest { flags, ..CommandRequest::of(CommandKind::Grip) }
    }

    /// A request of `kind` and nothing else.
    pub fn of(kind: CommandKind) -> CommandRequest {
        CommandRequest { kind: kind as u32, speed: 1.0, ..CommandRequest::default() }
    }

    /// A move to joint counts `counts` at `speed`.
    pub fn move_to(counts: &[f64], speed: f64) -> CommandRequest {
        let mut r = CommandRequest { speed, ..CommandRequest::of(CommandKind::Move) };
        for (t, c) in r.target.iter_mut().zip(counts) {
            *t = *c;
        }
        r
    }

    /// A move to the effector point `mm`, a straight line if `linear`, at `speed`.
    pub fn move_xyz(mm: [f64; 3], linear: bool, speed: f64) -> CommandRequest {
        let mut r = CommandRequest::move_to(&mm, speed);
        r.flags = CommandRequest::XYZ | if linear { CommandRequest::LINEAR } else { 0 };
        r
    }
}

/// The answer to a command or a path, in five parts: the [`Answer`] to the request, the
/// [`Orders`] ledger (what became of the orders given), the [`RobotStatus`] (where the loop
/// has the robot), the [`Timing`] of the request and the last order taken, and a conveyor
/// session's belt and parts ([`ConveyorStatus`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("qmarc.CommandResponse.v5")]
#[repr(C)]
pub struct CommandResponse {
    /// The request's answer.
    pub answer: Answer,
    /// The orders' ledger.
    pub orders: Orders,
    /// Where the robot is.
    pub robot: RobotStatus,
    /// When.
    pub timing: Timing,
    /// The belt and its parts (all zero outside a conveyor session).
    pub conveyor: ConveyorStatus,
}

/// A conveyor session's belt and parts, as its dispatcher last counted them (within a
/// millisecond); all zero outside a conveyor session.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct ConveyorStatus {
    /// 1 in a conveyor session (then the rest counts).
    pub active: u32,
    /// Parts the camera has seen (every part of the queue, whatever became of it).
    pub seen: u32,
    /// Parts waiting in the queue: seen, not yet handed to the robot.
    pub queued: u32,
    /// Parts picked (the gripper closed on them inside the window).
    pub picked: u32,
    /// Parts missed (past the window unpicked, or not reachable inside it).
    pub missed: u32,
    /// The part the robot is going for or carrying: its id + 1 (0: none).
    pub picking: u32,
    /// The belt's encoder in mm (counts × `conveyor.mm_per_count`).
    pub belt_mm: f64,
    /// The belt's speed over the loop's last 50 ms of reads, mm/s.
    pub belt_mm_s: f64,
}

impl ConveyorStatus {
    /// The part being picked, if one is.
    pub fn picking(&self) -> Option<u32> {
        self.picking.checked_sub(1)
    }

    /// As the console and `qmarc cmd status` say it: `belt 1234.5 mm at 500 mm/s · 2 queued
    /// · picking 17 · 15 picked · 0 missed`; empty outside a conveyor session.
    pub fn describe(&self) -> String {
        if self.active == 0 {
            return String::new();
        }
        let picking = self.picking().map_or(String::new(), |id| format!(" · picking {id}"));
        format!(
            "belt {:.1} mm at {:.0} mm/s · {} queued{picking} · {} picked · {} missed",
            self.belt_mm, self.belt_mm_s, self.queued, self.picked, self.missed
        )
    }
}

/// The answer to one request: accepted, or refused and why.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct Answer {
    /// The request's id.
    pub id: u64,
    /// 1: accepted; 0: refused.
    pub ok: u32,
    /// [`Refusal`] as its wire number (0 when accepted; [`Refusal::NotServing`] in a status
    /// once the session has ended).
    pub refusal: u32,
    /// Why it was refused (or, in a status, why the last order was not taken): UTF-8,
    /// NUL-padded.
    pub reason: [u8; REASON_BYTES],
}

impl Default for Answer {
    fn default() -> Answer {
        Answer { id: 0, ok: 0, refusal: 0, reason: [0; REASON_BYTES] }
    }
}

/// What became of the orders a session was given, by id ([`crate::client::OrderLedger`]
/// reads it).
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct Orders {
    /// The last order accepted (0: none yet).
    pub accepted: u64,
    /// The last order the robot has come to rest at the end of (equal to `accepted` once the
    /// robot is at rest where it was last sent).
    pub settled: u64,
    /// The last order the loop took (a move, a stop).
    pub taken: u64,
    /// The last order the loop could not take (its profile from the state the command was in
    /// would leave the soft limits, or there was none): the command went on as it was.
    pub not_taken: u64,
    /// The last motion order the loop took — a move, a line (a path), a stop: what the robot
    /// follows now (a grip is no motion: a path goes on through it).
    pub motion: u64,
    /// 1 while the command moves.
    pub moving: u32,
    /// Zero (keeps the layout free of padding).
    pub reserved: u32,
}

/// Where the loop has the robot.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct RobotStatus {
    /// The loop's [`qmarc_proto::state::Phase`] as its wire number.
    pub phase: u32,
    /// [`qmarc_proto::state::FaultKind::wire`]: 0, or the fault's wire number.
    pub fault: u32,
    /// Bit m: motor m's frame is homed.
    pub homed: u32,
    /// The gripper as the loop's last read found it ([`qmarc_proto::Gripper`] bits).
    pub gripper: u32,
    /// The command, counts.
    pub command: [f64; MAX_MOTORS],
    /// The motors' positions, counts.
    pub actual: [f64; MAX_MOTORS],
    /// The effector's commanded point, mm (NaN without the robot's geometry).
    pub effector_mm: [f64; 3],
}

impl Default for RobotStatus {
    fn default() -> RobotStatus {
        RobotStatus {
            phase: 0,
            fault: 0,
            homed: 0,
            gripper: qmarc_proto::Gripper::ABSENT,
            command: [0.0; MAX_MOTORS],
            actual: [0.0; MAX_MOTORS],
            effector_mm: [f64::NAN; 3],
        }
    }
}

/// When the request was read and the last order taken.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct Timing {
    /// When the command thread read this request, ns of `CLOCK_MONOTONIC`.
    pub received_ns: u64,
    /// The cycles the loop had executed when the command thread had queued this request's
    /// order (for an order; else when it read it).
    pub received_cycle: u64,
    /// When the loop took the last order it took, ns of `CLOCK_MONOTONIC`: in the cycle whose
    /// command is the new profile's first, as that cycle computed it.
    pub taken_ns: u64,
    /// The cycles the loop had executed when it took it, that cycle included: one more than
    /// `received_cycle` when the first cycle after the order was queued took it.
    pub taken_cycle: u64,
}

impl Answer {
    /// Sets the reason, cut at a character boundary to fit.
    pub fn set_reason(&mut self, text: &str) {
        let mut end = text.len().min(REASON_BYTES);
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        self.reason = [0; REASON_BYTES];
        self.reason[..end].copy_from_slice(&text.as_bytes()[..end]);
    }

    /// The reason's text.
    pub fn reason(&self) -> String {
        let end = self.reason.iter().position(|&b| b == 0).unwrap_or(REASON_BYTES);
        String::from_utf8_lossy(&self.reason[..end]).into_owned()
    }

    /// Refuses: `refused`'s kind and words.
    pub fn refuse(&mut self, refused: &Refused) {
        self.ok = 0;
        self.refusal = refused.kind as u32;
        self.set_reason(&refused.why);
    }

    /// The refusal, if refused.
    pub fn refused(&self) -> Option<Refusal> {
        (self.ok == 0).then(|| Refusal::from_wire(self.refusal).unwrap_or(Refusal::BadRequest))
    }
}

impl CommandResponse {
    /// The refusal, if refused ([`Answer::refused`]).
    pub fn refused(&self) -> Option<Refusal> {
        self.answer.refused()
    }

    /// The reason's text ([`Answer::reason`]).
    pub fn reason(&self) -> String {
        self.answer.reason()
    }
}

/// The belt and the part queue as the dispatcher last counted them, for the command thread
/// to answer with ([`ConveyorStatus`]): written by one thread, read by any,
/// field by field (a reader may see one field a millisecond newer than another).
#[derive(Debug, Default)]
pub struct ConveyorTally {
    seen: AtomicU32,
    queued: AtomicU32,
    picked: AtomicU32,
    missed: AtomicU32,
    picking: AtomicU32,
    belt_mm: AtomicU64,
    belt_mm_s: AtomicU64,
}

impl ConveyorTally {
    /// Says `s` (its `active` is implied: a tally is a conveyor session's).
    pub fn set(&self, s: &ConveyorStatus) {
        self.seen.store(s.seen, Ordering::Relaxed);
        self.queued.store(s.queued, Ordering::Relaxed);
        self.picked.store(s.picked, Ordering::Relaxed);
        self.missed.store(s.missed, Ordering::Relaxed);
        self.picking.store(s.picking, Ordering::Relaxed);
        self.belt_mm.store(s.belt_mm.to_bits(), Ordering::Relaxed);
        self.belt_mm_s.store(s.belt_mm_s.to_bits(), Ordering::Relaxed);
    }

    /// What was last said.
    pub fn get(&self) -> ConveyorStatus {
        ConveyorStatus {
            active: 1,
            seen: self.seen.load(Ordering::Relaxed),
            queued: self.queued.load(Ordering::Relaxed),
            picked: self.picked.load(Ordering::Relaxed),
            missed: self.missed.load(Ordering::Relaxed),
            picking: self.picking.load(Ordering::Relaxed),
            belt_mm: f64::from_bits(self.belt_mm.load(Ordering::Relaxed)),
            belt_mm_s: f64::from_bits(self.belt_mm_s.load(Ordering::Relaxed)),
        }
    }
}

/// Name of the request/response service.
pub const PATH_SERVICE: &str = "qmarc/path";
/// Most knots a path request carries.
pub const MAX_PATH_KNOTS: usize = 1024;

/// One knot of a path.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct PathKnot {
    /// Time from the path's start (where the robot rests, at rest), s.
    pub t_s: f64,
    /// Position per motor, counts.
    pub pos: [f64; MAX_MOTORS],
    /// Velocity per motor, counts/s (with [`PathRequest::VELOCITIES`]; else ignored).
    pub vel: [f64; MAX_MOTORS],
}

/// A timed path for the loop to follow from where the robot rests.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("qmarc.PathRequest.v1")]
#[repr(C)]
pub struct PathRequest {
    /// The client's number for it, echoed in the response.
    pub id: u64,
    /// Knots used, 1‥[`MAX_PATH_KNOTS`].
    pub n_knots: u32,
    /// [`PathRequest::VELOCITIES`].
    pub flags: u32,
    /// The knots; those past `n_knots` are ignored.
    pub knots: [PathKnot; MAX_PATH_KNOTS],
}

impl Default for PathRequest {
    fn default() -> PathRequest {
        PathRequest { id: 0, n_knots: 0, flags: 0, knots: [PathKnot::default(); MAX_PATH_KNOTS] }
    }
}

impl PathRequest {
    /// The knots' velocities are given (else the controller chooses them: see
    /// [`crate::path`]).
    pub const VELOCITIES: u32 = 1;

    /// First a jerk-limited move from where the robot rests to the first knot (the run's
    /// `--approach`), then the path from there: its first knot need not be where the robot
    /// rests.
    pub const APPROACH: u32 = 2;

    /// The request of `knots`, with their velocities if `velocities`; `None` for more than
    /// [`MAX_PATH_KNOTS`].
    pub fn new(knots: &[PathKnot], velocities: bool) -> Option<Box<PathRequest>> {
        if knots.len() > MAX_PATH_KNOTS {
            return None;
        }
        let mut r = Box::<PathRequest>::default();
        r.knots[..knots.len()].copy_from_slice(knots);
        r.n_knots = knots.len() as u32;
        r.flags = if velocities { PathRequest::VELOCITIES } else { 0 };
        Some(r)
    }

    /// The knots used (at most [`MAX_PATH_KNOTS`], whatever `n_knots` says).
    pub fn knots(&self) -> &[PathKnot] {
        &self.knots[..(self.n_knots as usize).min(MAX_PATH_KNOTS)]
    }

    /// The knots' velocities are given.
    pub fn has_velocities(&self) -> bool {
        self.flags & PathRequest::VELOCITIES != 0
    }

    /// The path is approached from where the robot rests ([`PathRequest::APPROACH`]).
    pub fn approached(&self) -> bool {
        self.flags & PathRequest::APPROACH != 0
    }
}

/// The command service.
pub type CommandService =
    request_response::PortFactory<ipc::Service, CommandRequest, (), CommandResponse, ()>;

/// The path service.
pub type PathService =
    request_response::PortFactory<ipc::Service, PathRequest, (), CommandResponse, ()>;

/// A serving session's services: created by the server, only opened by a client (a client
/// never leaves a service behind that nothing serves).
pub struct Services {
    /// `qmarc/command`.
    pub command: CommandService,
    /// `qmarc/path`.
    pub path: PathService,
    /// `qmarc/command/request`: a client notifies it after each request of either service.
    pub wake: event::PortFactory<ipc::Service>,
}

impl Services {
    /// The three services under `node`, created if `create` (the server), else opened.
    pub fn open(node: &Node<ipc::Service>, create: bool) -> Result<Services, ServiceError> {
        let command = order_service::<CommandRequest>(node, COMMAND_SERVICE, create)?;
        let path = order_service::<PathRequest>(node, PATH_SERVICE, create)?;
        let events =
            node.service_builder(&service_name(COMMAND_EVENT)?).event().event_id_max_value(0);
        let err = |e: &dyn std::fmt::Debug| ServiceError::new("service", COMMAND_EVENT, e);
        let wake = if create {
            events.open_or_create().map_err(|e| err(&e))?
        } else {
            events.open().map_err(|e| err(&e))?
        };
        Ok(Services { command, path, wake })
    }
}

/// `name` as an iceoryx2 service name.
fn service_name(name: &str) -> Result<ServiceName, ServiceError> {
    ServiceName::new(name).map_err(|e| ServiceError::new("service name", name, e))
}

/// The request/response service `name` of `Request`s answered by a [`CommandResponse`], with
/// the one QoS of both: ≤ [`MAX_COMMAND_CLIENTS`] clients, one server, one request in flight
/// per client, one response buffered. Created if `create`, else opened.
fn order_service<Request: std::fmt::Debug + ZeroCopySend>(
    node: &Node<ipc::Service>,
    name: &str,
    create: bool,
) -> Result<
    request_response::PortFactory<ipc::Service, Request, (), CommandResponse, ()>,
    ServiceError,
> {
    let builder = node
        .service_builder(&service_name(name)?)
        .request_response::<Request, CommandResponse>()
        .max_clients(MAX_COMMAND_CLIENTS)
        .max_servers(1)
        .max_active_requests_per_client(1)
        .max_response_buffer_size(1);
    let err = |e: &dyn std::fmt::Debug| ServiceError::new("service", name, e);
    if create {
        builder.open_or_create().map_err(|e| err(&e))
    } else {
        builder.open().map_err(|e| err(&e))
    }
}

#[cfg(test)]
mod tests;
