//! The command service of a serving controller (`qmarc-starter serve`): `qmarc/command`, an
//! iceoryx2 request/response service of fixed-size [`CommandRequest`] and [`CommandResponse`],
//! and its client end, [`CommandClient`] (`qmarc cmd`, the console, a pick-and-place cycle, a
//! bridge).
//!
//! Every request is answered at once: accepted, or refused with the reason. A move's end is
//! not waited for on the wire; the response's `accepted` and `settled` move ids say where the
//! robot is in the commands it was given ([`CommandClient::wait`] polls them).
//!
//! The server (the controller's command thread) waits on the event `qmarc/command/request`,
//! which a client notifies after each request; the client polls for its response.

use crate::MAX_MOTORS;
use crate::path::{PathRequest, PathService, open_path_service};
use crate::service::{IpcLocation, ServiceError, create_node};
use iceoryx2::port::client::Client;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, request_response};
use std::time::{Duration, Instant};

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

/// The answer to a command: accepted or refused, and where the robot is.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("qmarc.CommandResponse.v3")]
#[repr(C)]
pub struct CommandResponse {
    /// The request's id.
    pub id: u64,
    /// The last move accepted (0: none yet).
    pub accepted: u64,
    /// The last move the robot has come to rest at the end of (equal to `accepted` once the
    /// robot is at rest where it was last sent).
    pub settled: u64,
    /// 1: accepted; 0: refused.
    pub ok: u32,
    /// [`Refusal`] as its wire number (0 when accepted).
    pub refusal: u32,
    /// The loop's [`crate::state::Phase`] as its wire number.
    pub phase: u32,
    /// [`crate::state::FaultKind::wire`]: 0, or the fault's code + 1.
    pub fault: u32,
    /// Bit m: motor m's frame is homed.
    pub homed: u32,
    /// 1 while the command moves.
    pub moving: u32,
    /// When the command thread read this request, ns of `CLOCK_MONOTONIC`.
    pub received_ns: u64,
    /// The cycles the loop had executed when the command thread had queued this request's
    /// order (for an order; else when it read it).
    pub received_cycle: u64,
    /// The last order the loop took (a move, a stop).
    pub taken: u64,
    /// When it took it, ns of `CLOCK_MONOTONIC`: in the cycle whose command is the new
    /// profile's first, as that cycle computed it.
    pub taken_ns: u64,
    /// The cycles the loop had executed when it took it, that cycle included: one more than
    /// `received_cycle` when the first cycle after the order was queued took it.
    pub taken_cycle: u64,
    /// The last move the loop could not take (its profile from the state the command was in
    /// would leave the soft limits, or there was none): the command went on as it was.
    pub not_taken: u64,
    /// The last motion order the loop took — a move, a line (a path), a stop: what the robot
    /// follows now (a grip is no motion: a path goes on through it).
    pub motion: u64,
    /// The command, counts.
    pub command: [f64; MAX_MOTORS],
    /// The motors' positions, counts.
    pub actual: [f64; MAX_MOTORS],
    /// The effector's commanded point, mm (NaN without the robot's geometry).
    pub effector_mm: [f64; 3],
    /// The gripper as the loop's last read found it ([`crate::Gripper`] bits).
    pub gripper: u32,
    /// Zero (keeps the layout free of padding).
    pub reserved: u32,
    /// Why it was refused: UTF-8, NUL-padded.
    pub reason: [u8; REASON_BYTES],
}

impl Default for CommandResponse {
    fn default() -> CommandResponse {
        CommandResponse {
            id: 0,
            accepted: 0,
            settled: 0,
            ok: 0,
            refusal: 0,
            phase: 0,
            fault: 0,
            homed: 0,
            moving: 0,
            received_ns: 0,
            received_cycle: 0,
            taken: 0,
            taken_ns: 0,
            taken_cycle: 0,
            not_taken: 0,
            motion: 0,
            command: [0.0; MAX_MOTORS],
            actual: [0.0; MAX_MOTORS],
            effector_mm: [f64::NAN; 3],
            gripper: crate::Gripper::ABSENT,
            reserved: 0,
            reason: [0; REASON_BYTES],
        }
    }
}

impl CommandResponse {
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

    /// The refusal, if refused.
    pub fn refused(&self) -> Option<Refusal> {
        (self.ok == 0).then(|| Refusal::from_wire(self.refusal).unwrap_or(Refusal::BadRequest))
    }
}

/// The command service.
pub type CommandService =
    request_response::PortFactory<ipc::Service, CommandRequest, (), CommandResponse, ()>;

/// The command service and its wake-up event with the QoS both sides use: created by the
/// server (`create`), only opened by a client (a client never leaves a service behind that
/// nothing serves).
pub fn open_command_service(
    node: &Node<ipc::Service>,
    create: bool,
) -> Result<(CommandService, event::PortFactory<ipc::Service>), ServiceError> {
    let name = |n: &str| ServiceName::new(n).map_err(|e| ServiceError::new("service name", n, e));
    let builder = node
        .service_builder(&name(COMMAND_SERVICE)?)
        .request_response::<CommandRequest, CommandResponse>()
        .max_clients(MAX_COMMAND_CLIENTS)
        .max_servers(1)
        .max_active_requests_per_client(1)
        .max_response_buffer_size(1);
    let err = |e: &dyn std::fmt::Debug| ServiceError::new("service", COMMAND_SERVICE, e);
    let service = if create {
        builder.open_or_create().map_err(|e| err(&e))?
    } else {
        builder.open().map_err(|e| err(&e))?
    };
    let events = node.service_builder(&name(COMMAND_EVENT)?).event().event_id_max_value(0);
    let err = |e: &dyn std::fmt::Debug| ServiceError::new("service", COMMAND_EVENT, e);
    let event = if create {
        events.open_or_create().map_err(|e| err(&e))?
    } else {
        events.open().map_err(|e| err(&e))?
    };
    Ok((service, event))
}

/// A command could not be sent or was not answered.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CommandError {
    /// The service could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// Nothing serves commands under the prefix.
    #[error(
        "no serving controller under iceoryx2 prefix `{prefix}` (is `qmarc-starter serve` running?)"
    )]
    NoServer {
        /// The prefix.
        prefix: String,
    },
    /// iceoryx2 failed.
    #[error("the command service: {0}")]
    Ipc(String),
    /// No answer in time.
    #[error("no answer from the serving controller within {0:?}")]
    Timeout(Duration),
}

/// A client port of the path service.
type PathClient = Client<ipc::Service, PathRequest, (), CommandResponse, ()>;

/// The client end of the command service.
pub struct CommandClient {
    node: Node<ipc::Service>,
    service: CommandService,
    client: Client<ipc::Service, CommandRequest, (), CommandResponse, ()>,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
    next_id: u64,
    /// The path service's client, opened by the first path sent.
    path: Option<(PathService, PathClient)>,
}

/// How long a command waits for its answer.
pub const ANSWER_WAIT: Duration = Duration::from_secs(2);

impl CommandClient {
    /// Connects to the serving controller at `location`.
    pub fn connect(location: &IpcLocation) -> Result<CommandClient, CommandError> {
        let node = create_node::<ipc::Service>("qmarc-cmd", location)?;
        node.try_cleanup_dead_nodes();
        let no_server = || CommandError::NoServer { prefix: location.prefix.clone() };
        let (service, event) = open_command_service(&node, false).map_err(|_| no_server())?;
        if service.dynamic_config().number_of_servers() == 0 {
            return Err(no_server());
        }
        let client = service.client_builder().create().map_err(|e| ipc(&e))?;
        let notifier = event.notifier_builder().create().map_err(|e| ipc(&e))?;
        Ok(CommandClient { node, service, client, notifier, next_id: 1, path: None })
    }

    /// Sends `request` (its id set here) and returns the answer.
    pub fn send(&mut self, mut request: CommandRequest) -> Result<CommandResponse, CommandError> {
        request.id = self.next_id;
        self.next_id += 1;
        let pending = self.client.send_copy(request).map_err(|e| ipc(&e))?;
        self.notifier.notify().map_err(|e| ipc(&e))?;
        answer_of(|| pending.receive().map(|r| r.map(|r| *r.payload())), &self.service)
    }

    /// Sends the path `request` (its id set here) on `qmarc/path` and returns the answer.
    pub fn send_path(&mut self, request: &PathRequest) -> Result<CommandResponse, CommandError> {
        if self.path.is_none() {
            let service = open_path_service(&self.node, false)?;
            let client = service.client_builder().create().map_err(|e| ipc(&e))?;
            self.path = Some((service, client));
        }
        let Some((_, client)) = &self.path else { unreachable!("opened above") };
        let mut loan = client.loan_uninit().map_err(|e| ipc(&e))?;
        let r = loan.payload_mut().write(*request);
        r.id = self.next_id;
        self.next_id += 1;
        // SAFETY: the payload was written whole just above.
        let pending = unsafe { loan.assume_init() }.send().map_err(|e| ipc(&e))?;
        self.notifier.notify().map_err(|e| ipc(&e))?;
        answer_of(|| pending.receive().map(|r| r.map(|r| *r.payload())), &self.service)
    }

    /// Polls the status until the robot is at rest at the end of the last move accepted (or
    /// the loop has ended), for at most `timeout`; returns the last status.
    pub fn wait(&mut self, timeout: Duration) -> Result<CommandResponse, CommandError> {
        let started = Instant::now();
        loop {
            let s = self.send(CommandRequest::of(CommandKind::Status))?;
            let ended = s.refused() == Some(Refusal::NotServing);
            let dropped = s.not_taken >= s.accepted && s.accepted > 0;
            if ended || dropped || (s.settled >= s.accepted && s.moving == 0) {
                return Ok(s);
            }
            if started.elapsed() > timeout {
                return Err(CommandError::Timeout(timeout));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

/// An iceoryx2 failure, in words.
fn ipc(e: &dyn std::fmt::Debug) -> CommandError {
    CommandError::Ipc(format!("{e:?}"))
}

/// Polls `receive` for the answer to a request sent, for at most [`ANSWER_WAIT`] and while
/// the command service's server lives.
fn answer_of<E: std::fmt::Debug>(
    mut receive: impl FnMut() -> Result<Option<CommandResponse>, E>,
    service: &CommandService,
) -> Result<CommandResponse, CommandError> {
    let started = Instant::now();
    loop {
        if let Some(r) = receive().map_err(|e| ipc(&e))? {
            return Ok(r);
        }
        if started.elapsed() > ANSWER_WAIT {
            return Err(CommandError::Timeout(ANSWER_WAIT));
        }
        if service.dynamic_config().number_of_servers() == 0 {
            return Err(CommandError::Ipc("the serving controller has gone".into()));
        }
        std::thread::sleep(Duration::from_micros(100));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_wire_numbers_are_those_of_v2() {
        let kinds: Vec<u32> = CommandKind::ALL.iter().map(|k| *k as u32).collect();
        assert_eq!(kinds, [1, 2, 3, 4, 5]);
        let refusals: Vec<u32> = Refusal::ALL.iter().map(|r| *r as u32).collect();
        assert_eq!(refusals, [1, 2, 3, 4, 5, 6, 7, 8]);
        assert_eq!(CommandKind::from_wire(3), Some(CommandKind::Status));
        assert_eq!((CommandKind::from_wire(0), Refusal::from_wire(9)), (None, None));
        let grip = CommandRequest::grip(true);
        assert_eq!((grip.kind, grip.flags), (5, CommandRequest::CLOSE));
        assert_eq!(CommandRequest::grip(false).flags, 0);
        assert_eq!(Refusal::NoGripper.name(), "no_gripper");
    }

    #[test]
    fn the_messages_are_fixed_size_plain_data() {
        assert_eq!(std::mem::size_of::<CommandRequest>(), 56);
        assert_eq!(std::mem::size_of::<CommandResponse>(), 400);
        assert_eq!(std::mem::align_of::<CommandResponse>(), 8);
    }

    #[test]
    fn a_reason_is_cut_at_a_character_boundary() {
        let mut r = CommandResponse::default();
        r.set_reason("motor 2 would go to 12000 counts");
        assert_eq!(r.reason(), "motor 2 would go to 12000 counts");
        let long = "é".repeat(REASON_BYTES);
        r.set_reason(&long);
        assert_eq!(r.reason().len(), REASON_BYTES);
        assert!(r.reason().chars().all(|c| c == 'é'));
        assert_eq!(r.refused(), Some(Refusal::BadRequest));
    }
}
