//! The controller's telemetry thread: empties the loop's ring every `RELAY_WAKE` and
//! publishes each sample on `qmarc/telemetry`. iceoryx2's work — a loan per sample (one
//! allocation, iceoryx2 #101) and opening the connection to a reader that just arrived
//! (shared memory, system calls) — runs here, never in the servo thread. It ends when the
//! loop lets go of the ring (the move ended), after publishing what was left in it.

use iceoryx2::prelude::ipc;
use qmarc_proto::service::{IpcLocation, create_node};
use qmarc_proto::telemetry::{TelemetryOpenError, TelemetrySample, open_telemetry_service};
use std::time::Duration;

/// How often the thread empties the ring.
pub const RELAY_WAKE: Duration = Duration::from_millis(5);

/// Node name of the publishing thread.
pub const RELAY_NODE: &str = "qmarc-telemetry";

/// A publisher of `qmarc/telemetry` with its node and service (dropped in that order).
pub struct TelemetryPublisher {
    publisher: iceoryx2::port::publisher::Publisher<ipc::Service, TelemetrySample, ()>,
    _service: qmarc_proto::telemetry::TelemetryService,
    _node: iceoryx2::node::Node<ipc::Service>,
}

impl TelemetryPublisher {
    /// Creates the run's telemetry service at `location` and its one publisher.
    pub fn open(location: &IpcLocation) -> Result<TelemetryPublisher, String> {
        let node = create_node(RELAY_NODE, location).map_err(|e| e.to_string())?;
        let service = open_telemetry_service(&node, true).map_err(|e| match e {
            TelemetryOpenError::Failed(e) => e.to_string(),
            TelemetryOpenError::NoMove => "the telemetry service could not be made".into(),
        })?;
        let publisher = service
            .publisher_builder()
            .max_loaned_samples(1)
            .create()
            .map_err(|e| format!("cannot publish qmarc/telemetry: {e:?}"))?;
        Ok(TelemetryPublisher { publisher, _service: service, _node: node })
    }

    /// Publishes `sample` to every reader; false if iceoryx2 refused it (the sample is lost).
    pub fn publish(&self, sample: TelemetrySample) -> bool {
        match self.publisher.loan_uninit() {
            Ok(s) => s.write_payload(sample).send().is_ok(),
            Err(_) => false,
        }
    }
}

/// What the thread did.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RelayReport {
    /// Samples published.
    pub published: u64,
    /// Samples iceoryx2 refused.
    pub refused: u64,
    /// Why nothing could be published, if so (the loop then drops every sample).
    pub error: Option<String>,
}

/// The running thread.
#[derive(Debug)]
pub struct Relay {
    handle: std::thread::JoinHandle<RelayReport>,
}

/// Starts the thread publishing what the loop puts into `rx` at `location`.
pub fn spawn(
    location: IpcLocation,
    mut rx: rtrb::Consumer<TelemetrySample>,
) -> std::io::Result<Relay> {
    let handle = std::thread::Builder::new().name("qmarc-telemetry".into()).spawn(move || {
        let publisher = match TelemetryPublisher::open(&location) {
            Ok(p) => p,
            // The ring goes with `rx`: the loop's samples are dropped and counted there.
            Err(e) => return RelayReport { error: Some(e), ..RelayReport::default() },
        };
        let mut report = RelayReport::default();
        loop {
            // Looked at before emptying: what the loop pushed before letting go is read.
            let ended = rx.is_abandoned();
            while let Ok(sample) = rx.pop() {
                if publisher.publish(sample) {
                    report.published += 1;
                } else {
                    report.refused += 1;
                }
            }
            if ended {
                return report;
            }
            std::thread::sleep(RELAY_WAKE);
        }
    })?;
    Ok(Relay { handle })
}

impl Relay {
    /// Waits for the thread (the loop must have let go of the ring).
    pub fn join(self) -> RelayReport {
        self.handle.join().unwrap_or_else(|_| RelayReport {
            error: Some("the telemetry thread panicked".into()),
            ..RelayReport::default()
        })
    }
}
