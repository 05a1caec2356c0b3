//! [`HwLink`]: one request/response exchange with the hardware server, and its [`LinkError`].
//!
//! The controller's loop talks to the hardware through this trait only. Over iceoryx2 it is
//! the controller's `IoxLink`; inside one process (tuning's evaluations, tests, benchmarks) it
//! is the hwserver's `HwCore` itself, which answers a request by handling it. The loop and the
//! hwserver thus stand side by side on this crate: neither knows the other.

use crate::HwMsg;

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
