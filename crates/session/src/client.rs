//! The client end of a serving session: [`CommandClient`] (`qmarc cmd`, the console, a
//! pick-and-place cycle, the ROS 2 bridge) sends orders and paths and reads the answers;
//! [`OrderLedger`] says, from a status, what became of an order — the one reading of an
//! answer's move ids that `qmarc cmd wait`, the bridge's goals and the benchmarks share.
//!
//! A client polls for its answer; the server sleeps on the event a client notifies after
//! each request ([`crate::wire`]).

use crate::wire::{
    CommandKind, CommandRequest, CommandResponse, CommandService, PathRequest, PathService,
    Refusal, Services,
};
use iceoryx2::port::client::Client;
use iceoryx2::prelude::*;
use qmarc_proto::service::{IpcLocation, ServiceError, create_node};
use qmarc_proto::state::FaultKind;
use std::time::{Duration, Instant};

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

/// The client end of the command service.
pub struct CommandClient {
    /// The node the ports are of.
    _node: Node<ipc::Service>,
    service: CommandService,
    client: Client<ipc::Service, CommandRequest, (), CommandResponse, ()>,
    /// The path service's client, made by the first path sent (a path request is 74 KiB of
    /// shared memory a client that sends none need not hold).
    path: Option<Client<ipc::Service, PathRequest, (), CommandResponse, ()>>,
    paths: PathService,
    notifier: iceoryx2::port::notifier::Notifier<ipc::Service>,
    next_id: u64,
}

/// How long a command waits for its answer.
pub const ANSWER_WAIT: Duration = Duration::from_secs(2);

impl CommandClient {
    /// Connects to the serving controller at `location`.
    pub fn connect(location: &IpcLocation) -> Result<CommandClient, CommandError> {
        let node = create_node::<ipc::Service>("qmarc-cmd", location)?;
        node.try_cleanup_dead_nodes();
        let no_server = || CommandError::NoServer { prefix: location.prefix.clone() };
        let services = Services::open(&node, false).map_err(|_| no_server())?;
        if services.command.dynamic_config().number_of_servers() == 0 {
            return Err(no_server());
        }
        let client = services.command.client_builder().create().map_err(|e| ipc(&e))?;
        let notifier = services.wake.notifier_builder().create().map_err(|e| ipc(&e))?;
        Ok(CommandClient {
            _node: node,
            service: services.command,
            client,
            path: None,
            paths: services.path,
            notifier,
            next_id: 1,
        })
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
            self.path = Some(self.paths.client_builder().create().map_err(|e| ipc(&e))?);
        }
        let Some(client) = &self.path else { unreachable!("made above") };
        let mut loan = client.loan_uninit().map_err(|e| ipc(&e))?;
        let r = loan.payload_mut().write(*request);
        r.id = self.next_id;
        self.next_id += 1;
        // SAFETY: the payload was written whole just above.
        let pending = unsafe { loan.assume_init() }.send().map_err(|e| ipc(&e))?;
        self.notifier.notify().map_err(|e| ipc(&e))?;
        answer_of(|| pending.receive().map(|r| r.map(|r| *r.payload())), &self.service)
    }

    /// Polls the status until the last move accepted has a final [`Fate`] — the robot at rest
    /// at its end, the move not taken, or the session ended (by its fault) — for at most
    /// `timeout`; returns the last status.
    pub fn wait(&mut self, timeout: Duration) -> Result<CommandResponse, CommandError> {
        let started = Instant::now();
        loop {
            let s = self.send(CommandRequest::of(CommandKind::Status))?;
            if OrderLedger::of(&s).fate(s.orders.accepted).is_final() {
                return Ok(s);
            }
            if started.elapsed() > timeout {
                return Err(CommandError::Timeout(timeout));
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }
}

/// What became of an order, as a status tells it ([`OrderLedger::fate`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fate {
    /// Accepted; the loop has not taken it yet.
    Queued,
    /// The loop has taken it: the robot moves for it, or the gripper goes.
    Running,
    /// The robot rests at its end (a grip: the gripper there too). Order 0, none, is settled
    /// once the robot rests, no motion having been taken.
    Settled,
    /// The loop could not take it: the robot went on as it was (the status's reason says
    /// why).
    NotTaken,
    /// A later motion order (this one) was taken: the robot follows it now, whether or not
    /// it had come to rest at this one's end.
    Superseded(u64),
    /// The session ended (a quit, a signal, the fault if there was one).
    Ended(Option<FaultKind>),
}

impl Fate {
    /// Nothing more will become of the order.
    pub fn is_final(self) -> bool {
        !matches!(self, Fate::Queued | Fate::Running)
    }
}

/// The move ids of a status: which orders the loop has taken, settled, not taken, and which
/// motion it follows — what an order's fate is read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct OrderLedger {
    /// The last order the robot has come to rest at the end of.
    pub settled: u64,
    /// The last order the loop took.
    pub taken: u64,
    /// The last order the loop could not take.
    pub not_taken: u64,
    /// The last motion order the loop took.
    pub motion: u64,
    /// The command moves.
    pub moving: bool,
    /// The session has ended: `Some(its fault)`.
    pub ended: Option<Option<FaultKind>>,
}

impl OrderLedger {
    /// The ledger of the status `s`.
    pub fn of(s: &CommandResponse) -> OrderLedger {
        let fault = FaultKind::from_wire(s.robot.fault);
        let ended = s.refused() == Some(Refusal::NotServing) || fault.is_some();
        let o = &s.orders;
        OrderLedger {
            settled: o.settled,
            taken: o.taken,
            not_taken: o.not_taken,
            motion: o.motion,
            moving: o.moving != 0,
            ended: ended.then_some(fault),
        }
    }

    /// The robot rests at the end of order `id` or of a later one: every order up to it has
    /// settled and the command does not move (a stop's end, whatever came after it).
    pub fn rests_past(&self, id: u64) -> bool {
        self.settled >= id && !self.moving
    }

    /// What became of order `id`.
    pub fn fate(&self, id: u64) -> Fate {
        if let Some(fault) = self.ended {
            return Fate::Ended(fault);
        }
        if id > 0 && self.not_taken == id {
            return Fate::NotTaken;
        }
        if self.motion > id {
            return Fate::Superseded(self.motion);
        }
        if self.rests_past(id) {
            return Fate::Settled;
        }
        if self.taken < id { Fate::Queued } else { Fate::Running }
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
    use crate::wire::Orders;

    /// Each fate from the move ids a status carries, the session's end first, and an order's
    /// end told apart from a later one's.
    #[test]
    fn an_orders_fate_is_read_from_the_status_move_ids() {
        let at = |settled, taken, not_taken, motion, moving, fault| {
            let mut s = CommandResponse::default();
            s.answer.ok = 1;
            s.orders = Orders {
                accepted: 5,
                settled,
                taken,
                not_taken,
                motion,
                moving: u32::from(moving),
                reserved: 0,
            };
            s.robot.fault = fault;
            OrderLedger::of(&s)
        };
        assert_eq!(at(4, 4, 0, 4, false, 0).fate(5), Fate::Queued);
        assert_eq!(at(4, 5, 0, 5, true, 0).fate(5), Fate::Running);
        assert_eq!(at(5, 5, 0, 5, false, 0).fate(5), Fate::Settled);
        assert_eq!(at(5, 5, 0, 5, true, 0).fate(5), Fate::Running, "at rest only when still");
        assert_eq!(at(4, 5, 5, 4, false, 0).fate(5), Fate::NotTaken);
        assert_eq!(at(4, 5, 5, 4, false, 0).fate(4), Fate::Settled, "a later one not taken");
        assert_eq!(at(4, 6, 0, 6, true, 0).fate(5), Fate::Superseded(6));
        let fault = FaultKind::wire(Some(FaultKind::FollowingError));
        let ended = at(4, 5, 0, 5, true, fault);
        assert_eq!(ended.fate(5), Fate::Ended(Some(FaultKind::FollowingError)));
        assert!(ended.fate(5).is_final() && !Fate::Running.is_final());
        assert_eq!(at(0, 0, 0, 0, false, 0).fate(0), Fate::Settled, "no order, at rest");
        // A stop (3) followed by a move (6): the robot rests past the stop only once the move
        // has ended too, though the stop's fate is the move's from its taking on.
        let moving = at(3, 6, 0, 6, true, 0);
        assert!(!moving.rests_past(3));
        assert!(at(6, 6, 0, 6, false, 0).rests_past(3));
    }
}
