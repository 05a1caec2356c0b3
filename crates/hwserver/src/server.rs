//! [`answer_requests`]: the iceoryx2 loop of the hardware server, which answers the
//! controller's requests (a serving session, `qmarc-starter serve`, is another thing).
//!
//! The server blocks on the request event (no busy spin unless asked), answers every pending
//! request through [`HwCore::handle`] and notifies the response event after each answer.
//! Around that it keeps the watchdog: if the controller is silent for longer than the
//! watchdog while any motor is enabled, the hardware goes to the safe state and the server
//! ends (the PC-crash protection the thesis lacked, 6.2.3).

use crate::core::HwCore;
use iceoryx2::prelude::PortFactory;
use qmarc_proto::service::{
    HWSERVER_NODE, IpcLocation, ServiceError, create_node, open_hw_services,
};
use qmarc_timer::clock::monotonic_now_ns;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// How the loop waits and when the watchdog fires.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct AnswerOptions {
    /// Controller silence (ns) tolerated while any motor is enabled.
    pub watchdog_ns: u64,
    /// Busy-poll instead of blocking.
    pub spin: bool,
    /// After a stop request or a watchdog trip, how long to keep answering (so the
    /// controller learns why, and can still send its disable and exit messages) before ending.
    pub shutdown_grace_ns: u64,
    /// Lock-step (simulated time): a controller silent past the watchdog trips it only when
    /// its process is gone; a living one is waiting out a host stall, which simulated time
    /// does not see.
    pub lockstep: bool,
}

/// Why [`answer_requests`] ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AnswerEnd {
    /// The controller sent [`qmarc_proto::MsgType::Exit`].
    Exit,
    /// The controller was silent for `silent_ns` with motors enabled: the safe state was
    /// commanded.
    Watchdog {
        /// How long it had been silent.
        silent_ns: u64,
        /// Whether its process was still there when the watchdog fired.
        controller_alive: bool,
    },
    /// A stop was requested (a signal) and no exit message followed within the grace time.
    Stopped,
}

/// The loop failed in iceoryx2.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum AnswerError {
    /// Node or services could not be opened.
    #[error(transparent)]
    Open(#[from] ServiceError),
    /// A port could not be created or used.
    #[error("iceoryx2 {op} failed: {reason}")]
    Port {
        /// The operation.
        op: &'static str,
        /// iceoryx2's error.
        reason: String,
    },
}

fn port_err(op: &'static str) -> impl FnOnce(&dyn std::fmt::Debug) -> AnswerError {
    move |e| AnswerError::Port { op, reason: format!("{e:?}") }
}

/// While ending, a controller silent this long is checked for (a cleanup of dead nodes: a
/// directory scan, so not after every request).
const GONE_CHECK_NS: u64 = 5_000_000;

/// Longest single wait, so that stop requests are noticed while idle.
const IDLE_WAIT_NS: u64 = 50_000_000;

/// Serves requests at `location` until exit, watchdog or stop. `stop` is polled between
/// waits; once it is set the hardware is made safe at once and [`crate::HwCore::shut_down`]
/// refuses further enables. On every return the hardware is in the safe state.
pub fn answer_requests(
    core: &mut HwCore,
    location: &IpcLocation,
    opts: &AnswerOptions,
    stop: &AtomicBool,
) -> Result<AnswerEnd, AnswerError> {
    let result = serve_inner(core, location, opts, stop);
    core.safe_state();
    result
}

fn serve_inner(
    core: &mut HwCore,
    location: &IpcLocation,
    opts: &AnswerOptions,
    stop: &AtomicBool,
) -> Result<AnswerEnd, AnswerError> {
    let node = create_node(HWSERVER_NODE, location)?;
    let services = open_hw_services(&node)?;
    let server =
        services.hw.server_builder().create().map_err(|e| port_err("server creation")(&e))?;
    let listener = services
        .request_event
        .listener_builder()
        .create()
        .map_err(|e| port_err("listener creation")(&e))?;
    let notifier = services
        .response_event
        .notifier_builder()
        .create()
        .map_err(|e| port_err("notifier creation")(&e))?;

    let mut last_request_ns = monotonic_now_ns();
    // Lock-step: when a silent controller was last seen alive.
    let mut seen_alive_ns = 0;
    // The controller's node alive (dead nodes cleaned up first: liveness is a file lock, so a
    // killed process is seen at once). Allocates: only called on a silent controller.
    let controller_alive = || {
        node.try_cleanup_dead_nodes();
        services.hw.dynamic_config().number_of_clients() > 0
    };
    // Once stopping: since when, and how it will be reported. The server goes on answering
    // (every response says why) until the controller exits or falls silent for the grace time.
    let mut ending: Option<(u64, AnswerEnd)> = None;
    loop {
        let now = monotonic_now_ns();
        if ending.is_none() && stop.load(Ordering::Relaxed) {
            core.shut_down();
            ending = Some((now, AnswerEnd::Stopped));
        }
        let silent_ns = now.saturating_sub(last_request_ns.max(seen_alive_ns));
        if ending.is_none() && core.any_enabled() && silent_ns > opts.watchdog_ns {
            if opts.lockstep && controller_alive() {
                seen_alive_ns = now;
            } else {
                core.trip_watchdog();
                let silent_ns = now.saturating_sub(last_request_ns);
                let end = AnswerEnd::Watchdog { silent_ns, controller_alive: controller_alive() };
                ending = Some((now, end));
            }
        }
        // Ending: until the controller has fallen silent for the grace time, or is silent and
        // gone (it gave up on us, or died: nobody is left to tell).
        if let Some((since, end)) = ending
            && (now.saturating_sub(since.max(last_request_ns)) > opts.shutdown_grace_ns
                || (now.saturating_sub(last_request_ns) > GONE_CHECK_NS && !controller_alive()))
        {
            return Ok(end);
        }

        wait_for_request(&listener, opts, (core.any_enabled(), silent_ns))?;

        while let Some(active) = server.receive().map_err(|e| port_err("server receive")(&e))? {
            let response = core.handle(active.payload());
            active.send_copy(response).map_err(|e| port_err("response send")(&e))?;
            // The controller is woken first: the rest is off its path (releasing the request
            // takes two locks of iceoryx2's port state, and the channel it closes is compared
            // by request id, so a next request on the same slot is not touched).
            notifier.notify().map_err(|e| port_err("response notify")(&e))?;
            drop(active);
            if let Some(why) = core.take_not_kept() {
                eprintln!("qmarc-hwserver: {why}");
            }
            last_request_ns = monotonic_now_ns();
            if core.exit_requested() {
                return Ok(ending.map_or(AnswerEnd::Exit, |(_, end)| end));
            }
        }
    }
}

/// Waits for the controller's request event: blocks until it comes, at most until the
/// watchdog could expire (50 ms while no motor is enabled, so a stop is noticed); with
/// `opts.spin`, returns at once without reading the event: a controller that knows the server
/// spins notifies nothing, and one that does not sends a single wake-up that stays unread
/// (iceoryx2 0.10 sends the next only once the last was read: an unread one makes every
/// further notification a compare-exchange, no system call).
fn wait_for_request(
    listener: &iceoryx2::port::listener::Listener<qmarc_proto::service::Link>,
    opts: &AnswerOptions,
    (enabled, silent_ns): (bool, u64),
) -> Result<(), AnswerError> {
    if opts.spin {
        std::hint::spin_loop();
        return Ok(());
    }
    let budget =
        if enabled { opts.watchdog_ns.saturating_sub(silent_ns).max(1_000) } else { IDLE_WAIT_NS };
    match listener.timed_wait(|_| {}, Duration::from_nanos(budget.min(IDLE_WAIT_NS))) {
        Ok(_) | Err(iceoryx2::port::listener::ListenerWaitError::InterruptSignal) => Ok(()),
        Err(e) => Err(port_err("listener wait")(&e)),
    }
}
