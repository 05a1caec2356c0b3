//! A process-wide stop request set by SIGTERM, SIGINT or SIGHUP (the terminal went away) and
//! polled by real-time loops.
//!
//! The handler only stores to an atomic, so a loop can poll it every cycle without locking or
//! allocating. Handlers are installed with `SA_RESTART`; waits that still return `EINTR` retry.

use std::sync::atomic::{AtomicBool, AtomicI32, AtomicU32, Ordering};

static STOP: AtomicBool = AtomicBool::new(false);
static SIGNAL: AtomicI32 = AtomicI32::new(0);
static COUNT: AtomicU32 = AtomicU32::new(0);

extern "C" fn on_signal(sig: libc::c_int) {
    SIGNAL.store(sig, Ordering::Relaxed);
    COUNT.fetch_add(1, Ordering::Relaxed);
    STOP.store(true, Ordering::Relaxed);
}

/// How many stop signals have arrived: a phase that must not be cut short by the stop that
/// ended the move (writing its data) ends only on a later one.
pub fn count() -> u32 {
    COUNT.load(Ordering::Relaxed)
}

/// Installs the stop handler for SIGTERM, SIGINT and SIGHUP. Returns the flag it sets.
pub fn install() -> std::io::Result<&'static AtomicBool> {
    use nix::sys::signal::{SaFlags, SigAction, SigHandler, SigSet, Signal, sigaction};
    let act = SigAction::new(SigHandler::Handler(on_signal), SaFlags::SA_RESTART, SigSet::empty());
    for sig in [Signal::SIGTERM, Signal::SIGINT, Signal::SIGHUP] {
        // SAFETY: the handler is async-signal-safe: it only stores to atomics.
        unsafe { sigaction(sig, &act) }.map_err(std::io::Error::from)?;
    }
    Ok(&STOP)
}

/// The flag the handler sets.
pub fn flag() -> &'static AtomicBool {
    &STOP
}

/// True once a stop signal arrived.
#[inline]
pub fn requested() -> bool {
    STOP.load(Ordering::Relaxed)
}

/// The stop signal that has arrived or is pending (sent, its handler not run yet), if any.
/// Under load the handler can run milliseconds after the signal was sent; a loop that learns
/// of a stop from elsewhere (the hwserver shutting down on the same signal) asks here whether
/// it is its own, and which. A system call: not for the fast path.
pub fn arrived_or_pending() -> Option<i32> {
    if requested() {
        return Some(signal().unwrap_or(0));
    }
    // SAFETY: sigpending(2) fills the set it is given (nix has no wrapper for sigpending).
    let pending = unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        if libc::sigpending(&mut set) != 0 {
            return None;
        }
        set
    };
    // SAFETY: sigismember on an initialised set.
    [libc::SIGTERM, libc::SIGINT, libc::SIGHUP]
        .into_iter()
        .find(|&sig| unsafe { libc::sigismember(&pending, sig) } == 1)
}

/// `SIGTERM`, `SIGINT`, …: a signal's name for messages.
pub fn signal_name(sig: i32) -> &'static str {
    nix::sys::signal::Signal::try_from(sig).map_or("an unknown signal", |s| s.as_str())
}

/// The signal that asked to stop, if any.
pub fn signal() -> Option<i32> {
    match SIGNAL.load(Ordering::Relaxed) {
        0 => None,
        s => Some(s),
    }
}
