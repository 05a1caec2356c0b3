//! [`HwLink`]: one request/response exchange with the hardware server, and its [`LinkError`].
//!
//! The controller's loop talks to the hardware through this trait only. Over iceoryx2 it is
//! [`IoxLink`], the client end of the wire (the controller's, and the hwserver's tests'); inside
//! one process (tuning's evaluations, tests, benchmarks) it is the hwserver's `HwCore` itself,
//! which answers a request by handling it. The loop and the hwserver thus stand side by side
//! on this crate: neither knows the other.

use crate::HwMsg;
use crate::service::{
    CONTROLLER_NODE, HwServices, IpcLocation, Link, ServiceError, create_node, open_hw_services,
};
use iceoryx2::port::client::Client;
use iceoryx2::port::listener::{Listener, ListenerWaitError};
use iceoryx2::port::notifier::Notifier;
use iceoryx2::prelude::*;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// An exchange failed. Carries numbers only: it is created in the servo loop.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LinkError {
    /// No response in time, or the hwserver process is gone.
    #[error("no response from the hwserver for {:.1} ms (server process {})", *.waited_ns as f64 / 1e6, if *.server_alive { "alive" } else { "gone" })]
    Lost {
        /// How long the exchange waited.
        waited_ns: u64,
        /// Whether the server's node was still alive when the exchange gave up.
        server_alive: bool,
    },
    /// An iceoryx2 operation failed.
    #[error("iceoryx2 {op} failed")]
    Ipc {
        /// The operation.
        op: &'static str,
    },
    /// A stop signal (Ctrl-C, SIGTERM) arrived while the response was late.
    #[error("a stop signal arrived while waiting {:.1} ms for the hwserver", *.waited_ns as f64 / 1e6)]
    Stopped {
        /// How long the exchange waited.
        waited_ns: u64,
    },
    /// The response answered another request.
    #[error("response sequence {got} does not match request {expected}")]
    Sequence {
        /// Sequence number sent.
        expected: u32,
        /// Sequence number received.
        got: u32,
    },
}

/// One request, one response. Implementations never allocate in `exchange` in our code
/// (iceoryx2's own loan allocation is stated in ARCHITECTURE.md).
pub trait HwLink {
    /// Sends `req` and waits for its response.
    fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, LinkError>;
}

/// Connecting to the hwserver failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LinkConnectError {
    /// Node or services could not be opened.
    #[error(transparent)]
    Service(#[from] ServiceError),
    /// A port could not be created.
    #[error("cannot create the iceoryx2 {port}: {reason}")]
    Port {
        /// Which port.
        port: &'static str,
        /// iceoryx2's error.
        reason: String,
    },
    /// A stop signal arrived while waiting for the server.
    #[error("a stop signal arrived while waiting for the hwserver")]
    Stopped,
    /// The server did not appear in time.
    #[error("no hwserver at prefix `{prefix}` under {root} after {waited_ms} ms")]
    NoServer {
        /// The prefix looked at.
        prefix: String,
        /// The root looked at.
        root: String,
        /// How long we waited.
        waited_ms: u64,
    },
}

/// Deadlines of one exchange.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LinkTimeouts {
    /// Every time this long goes by without a response the exchange checks whether the server
    /// is alive (and whether a stop signal arrived); a dead server ends the exchange at once.
    pub deadline_ns: u64,
    /// After this long without a response the server is lost, alive or not (`u64::MAX`:
    /// never, only its death ends the wait — lock-step runs, whose time is simulated).
    pub give_up_ns: u64,
    /// Poll for the response this long before blocking on its event (0: block at once):
    /// with a spinning hwserver the response comes in microseconds, and a wake-up costs more.
    pub spin_ns: u64,
}

/// The controller's end of the iceoryx2 link (client port + two event ports).
///
/// `!Send` (iceoryx2 ipc ports): create it in the thread that runs the loop.
pub struct IoxLink {
    node: Node<Link>,
    services: HwServices,
    client: Client<Link, HwMsg, (), HwMsg, ()>,
    notifier: Notifier<Link>,
    listener: Listener<Link>,
    timeouts: LinkTimeouts,
    seq: u32,
    stop: Option<&'static AtomicBool>,
    /// Notify the request event after each request (false: the hwserver busy-polls and needs
    /// no wake-up — one system call less per exchange).
    notify_requests: bool,
}

fn port_err(port: &'static str, e: impl std::fmt::Debug) -> LinkConnectError {
    LinkConnectError::Port { port, reason: format!("{e:?}") }
}

impl IoxLink {
    /// Opens the link at `location` and waits up to `wait` for the hwserver to be listening.
    /// With `stop`, a stop signal ends that wait (`Stopped`) and any later wait for a
    /// response that does not come (checked at each deadline).
    pub fn connect(
        location: &IpcLocation,
        timeouts: LinkTimeouts,
        wait: Duration,
        stop: Option<&'static AtomicBool>,
    ) -> Result<IoxLink, LinkConnectError> {
        let node = create_node(CONTROLLER_NODE, location)?;
        let started = std::time::Instant::now();
        let services = loop {
            // The server creates the services; opening them first would race its QoS.
            match open_hw_services(&node) {
                Ok(s)
                    if s.hw.dynamic_config().number_of_servers() > 0
                        && s.request_event.dynamic_config().number_of_listeners() > 0 =>
                {
                    break s;
                }
                _ if stop.is_some_and(|s| s.load(Ordering::Relaxed)) => {
                    return Err(LinkConnectError::Stopped);
                }
                Ok(_) | Err(_) if started.elapsed() < wait => {
                    std::thread::sleep(Duration::from_millis(2))
                }
                Ok(_) => {
                    return Err(LinkConnectError::NoServer {
                        prefix: location.prefix.clone(),
                        root: location.root.clone(),
                        waited_ms: started.elapsed().as_millis() as u64,
                    });
                }
                Err(e) => return Err(e.into()),
            }
        };
        let client = services.hw.client_builder().create().map_err(|e| port_err("client", e))?;
        let notifier = services
            .request_event
            .notifier_builder()
            .create()
            .map_err(|e| port_err("notifier", e))?;
        let listener = services
            .response_event
            .listener_builder()
            .create()
            .map_err(|e| port_err("listener", e))?;
        Ok(IoxLink {
            node,
            services,
            client,
            notifier,
            listener,
            timeouts,
            seq: 0,
            stop,
            notify_requests: true,
        })
    }

    /// The link to a hwserver that busy-polls for requests (`hwserver.wait = "spin"`): no
    /// request is notified, as nothing waits on the event.
    pub fn to_spinning_server(mut self) -> IoxLink {
        self.notify_requests = false;
        self
    }

    /// True while the hwserver's node is alive: dead nodes are cleaned up first (liveness is
    /// a file lock, so a killed server is seen at once). Allocates: call it off the fast path.
    pub fn server_alive(&self) -> bool {
        self.node.try_cleanup_dead_nodes();
        self.services.hw.dynamic_config().number_of_servers() > 0
    }
}

impl HwLink for IoxLink {
    fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, LinkError> {
        self.seq = self.seq.wrapping_add(1);
        let mut msg = *req;
        msg.seq = self.seq;
        let started = std::time::Instant::now();
        let pending =
            self.client.send_copy(msg).map_err(|_| LinkError::Ipc { op: "request send" })?;
        if self.notify_requests {
            self.notifier.notify().map_err(|_| LinkError::Ipc { op: "request notify" })?;
        }
        let mut next_check = self.timeouts.deadline_ns;
        loop {
            if let Some(resp) =
                pending.receive().map_err(|_| LinkError::Ipc { op: "response receive" })?
            {
                let r = *resp.payload();
                if r.seq != msg.seq {
                    return Err(LinkError::Sequence { expected: msg.seq, got: r.seq });
                }
                return Ok(r);
            }
            let waited = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
            if waited >= self.timeouts.give_up_ns {
                return Err(LinkError::Lost {
                    waited_ns: waited,
                    server_alive: self.server_alive(),
                });
            }
            if waited < self.timeouts.spin_ns {
                // Polling reads no wake-up: iceoryx2 0.10 sends one only when the last was
                // read (`iceoryx2-cal` event `notify`: a pending one makes the next a compare-
                // exchange), so the server's notifications cost no system call while we poll.
                // A wait that blocks later reads the stale one and waits again.
                std::hint::spin_loop();
                continue;
            }
            if waited >= next_check {
                if !self.server_alive() {
                    return Err(LinkError::Lost { waited_ns: waited, server_alive: false });
                }
                if self.stop.is_some_and(|s| s.load(Ordering::Relaxed)) {
                    return Err(LinkError::Stopped { waited_ns: waited });
                }
                next_check = waited.saturating_add(self.timeouts.deadline_ns);
            }
            let next = next_check.min(self.timeouts.give_up_ns);
            let budget = Duration::from_nanos(next.saturating_sub(waited).max(1_000));
            match self.listener.timed_wait(|_| {}, budget) {
                Ok(_) | Err(ListenerWaitError::InterruptSignal) => {}
                Err(_) => {
                    return Err(LinkError::Ipc { op: "response wait" });
                }
            }
        }
    }
}
