//! Reading a move's telemetry from another process: which runs there are (their run files in
//! `/dev/shm`), and a subscriber of one run's `qmarc/telemetry`. A reader never creates the
//! service: only a move makes it, so "no move runs" is an answer, not a new empty service.

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{PortFactory, ipc};
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation, create_node, run_file};
use qmarc_proto::telemetry::{
    TELEMETRY_BUFFER, TelemetryOpenError, TelemetrySample, TelemetryService, open_telemetry_service,
};

/// Node name of a reader.
pub const READER_NODE: &str = "qmarc-scope";

/// A subscriber of one run's telemetry, with its node and service (dropped in that order).
pub struct TelemetryReader {
    subscriber: Subscriber<ipc::Service, TelemetrySample, ()>,
    service: TelemetryService,
    _node: iceoryx2::node::Node<ipc::Service>,
}

impl TelemetryReader {
    /// Subscribes to the telemetry of the run at `location`; [`TelemetryOpenError::NoMove`]
    /// when no move publishes there now.
    pub fn open(location: &IpcLocation) -> Result<TelemetryReader, TelemetryOpenError> {
        let node = create_node(READER_NODE, location).map_err(TelemetryOpenError::Failed)?;
        let service = open_telemetry_service(&node, false)?;
        let subscriber =
            service.subscriber_builder().buffer_size(TELEMETRY_BUFFER).create().map_err(|e| {
                TelemetryOpenError::Failed(qmarc_proto::service::ServiceError {
                    what: "a subscriber of qmarc/telemetry".into(),
                    reason: format!("{e:?}"),
                })
            })?;
        Ok(TelemetryReader { subscriber, service, _node: node })
    }

    /// The next sample queued for this reader, if any.
    pub fn receive(&self) -> Result<Option<TelemetrySample>, String> {
        match self.subscriber.receive() {
            Ok(s) => Ok(s.map(|s| *s.payload())),
            Err(e) => Err(format!("cannot read qmarc/telemetry: {e:?}")),
        }
    }

    /// Publishers of the service now (0 once the move's controller let go of it).
    pub fn publishers(&self) -> usize {
        self.service.dynamic_config().number_of_publishers()
    }
}

/// Where the run with iceoryx2 prefix `prefix` keeps its files: `root`, else the root its run
/// file names, else iceoryx2's default.
pub fn location_of(prefix: &str, root: Option<&str>) -> IpcLocation {
    let from_run = || qmarc_config::RunSpec::read(&run_file(prefix)).ok().map(|s| s.iox_root);
    let root = root.map(str::to_string).or_else(from_run).unwrap_or_else(|| DEFAULT_ROOT.into());
    IpcLocation::new(prefix, &root)
}

/// The runs whose run files are in `/dev/shm` now, newest first.
pub fn runs() -> Vec<IpcLocation> {
    let Ok(entries) = std::fs::read_dir(qmarc_proto::service::SHM_DIR) else {
        return Vec::new();
    };
    let mut found: Vec<(std::time::SystemTime, IpcLocation)> = entries
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with("run.json"))
        .filter_map(|e| {
            let spec = qmarc_config::RunSpec::read(&e.path()).ok()?;
            let when = e.metadata().and_then(|m| m.modified()).ok()?;
            (run_file(&spec.iox_prefix) == e.path())
                .then(|| (when, IpcLocation::new(&spec.iox_prefix, &spec.iox_root)))
        })
        .collect();
    found.sort_by_key(|f| std::cmp::Reverse(f.0));
    found.into_iter().map(|(_, l)| l).collect()
}
