//! Reading a move's telemetry from another process: which runs there are (their run files in
//! `/dev/shm`), and a subscriber of one run's `qmarc/telemetry`. A reader never creates the
//! service: only a move makes it, so "no move runs" is an answer, not a new empty service.

use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::{PortFactory, ipc};
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation, ServiceError, create_node, run_file};
use qmarc_proto::state::Phase;
use qmarc_proto::telemetry::{
    TELEMETRY_BUFFER, TELEMETRY_SERVICE, TelemetryOpenError, TelemetrySample, TelemetryService,
    open_telemetry_service,
};
use std::collections::VecDeque;

/// Node name of a reader.
pub const READER_NODE: &str = "qmarc-scope";

/// A subscriber of one run's telemetry, with its node and service (dropped in that order),
/// and what it saw: samples received, samples lost (gaps in their numbers), the move's last
/// sample, whether its publisher was ever there.
pub struct TelemetryReader {
    subscriber: Subscriber<ipc::Service, TelemetrySample, ()>,
    service: TelemetryService,
    _node: iceoryx2::node::Node<ipc::Service>,
    count: SeqCount,
    last: Option<TelemetrySample>,
    publisher_seen: bool,
    /// Samples still queued when the publisher was found gone, not yet received.
    pending: VecDeque<TelemetrySample>,
}

/// Samples received and lost, from their numbers (0, 1, 2… over the move).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SeqCount {
    /// The number of the last sample received.
    pub last: Option<u64>,
    /// Samples received.
    pub received: u64,
    /// Gaps between received samples.
    pub lost: u64,
    /// Samples before the first received, when counting from the start.
    pub before_first: u64,
    /// Count from the move's first sample.
    pub from_start: bool,
}

impl SeqCount {
    /// Counts the sample numbered `seq`.
    pub fn see(&mut self, seq: u64) {
        match self.last {
            Some(l) => self.lost += seq.saturating_sub(l + 1),
            None if self.from_start => self.before_first = seq,
            None => {}
        }
        self.last = Some(seq);
        self.received += 1;
    }
}

/// How a move's telemetry ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum End {
    /// With the move's last sample (phase done or fault).
    Last(TelemetrySample),
    /// Its publisher went without one (the controller died).
    Gone,
}

/// Whether `s` is a move's last sample: its phase is done or fault.
pub fn is_last(s: &TelemetrySample) -> bool {
    matches!(Phase::from_wire(s.phase), Some(Phase::Done | Phase::Fault))
}

impl TelemetryReader {
    /// Subscribes to the telemetry of the run at `location`; [`TelemetryOpenError::NoMove`]
    /// when no move publishes there now.
    pub fn open(location: &IpcLocation) -> Result<TelemetryReader, TelemetryOpenError> {
        let node = create_node(READER_NODE, location).map_err(TelemetryOpenError::Failed)?;
        let service = open_telemetry_service(&node, false)?;
        let subscriber =
            service.subscriber_builder().buffer_size(TELEMETRY_BUFFER).create().map_err(|e| {
                TelemetryOpenError::Failed(ServiceError::new("subscriber", TELEMETRY_SERVICE, e))
            })?;
        Ok(TelemetryReader {
            subscriber,
            service,
            _node: node,
            count: SeqCount::default(),
            last: None,
            publisher_seen: false,
            pending: VecDeque::new(),
        })
    }

    /// [`open`](Self::open) for a run of the starter's: [`TelemetryOpenError::NoMove`],
    /// without a node, while the run's file is absent — no run of that prefix is alive then,
    /// and a node made now would leave iceoryx2's management file of the prefix behind with
    /// nobody to remove it (the starter removes a run's files when the run ends).
    pub fn open_run(location: &IpcLocation) -> Result<TelemetryReader, TelemetryOpenError> {
        if !run_file(&location.prefix).exists() {
            return Err(TelemetryOpenError::NoMove);
        }
        TelemetryReader::open(location)
    }

    /// The next sample queued for this reader, if any; counted, and a gap in the numbers
    /// counted as lost.
    pub fn receive(&mut self) -> Result<Option<TelemetrySample>, String> {
        let s = match self.pending.pop_front() {
            Some(s) => s,
            None => match self.subscriber.receive() {
                Ok(Some(s)) => *s.payload(),
                Ok(None) => return Ok(None),
                Err(e) => return Err(format!("cannot read qmarc/telemetry: {e:?}")),
            },
        };
        self.count.see(s.seq);
        if is_last(&s) {
            self.last = Some(s);
        }
        Ok(Some(s))
    }

    /// Counts the move's samples from its first: a reader attached while waiting for the
    /// move counts those published before it attached as lost (before: "0 lost" while the
    /// whole step transient had gone by).
    pub fn count_from_start(&mut self) {
        self.count.from_start = true;
    }

    /// Samples received so far.
    pub fn received(&self) -> u64 {
        self.count.received
    }

    /// Samples lost so far: gaps in their numbers, and, counted from the start, those before
    /// the first received.
    pub fn lost(&self) -> u64 {
        self.count.lost + self.count.before_first
    }

    /// Of [`lost`](Self::lost), those published before the first received (counted from the
    /// start only).
    pub fn lost_before_first(&self) -> u64 {
        self.count.before_first
    }

    /// How the move ended, once it did: its last sample was received, or its publisher,
    /// once there, is gone and every sample it published has been received.
    pub fn end(&mut self) -> Option<End> {
        if let Some(s) = self.last {
            return Some(End::Last(s));
        }
        if !self.pending.is_empty() {
            return None;
        }
        let publishers = self.publishers();
        self.publisher_seen |= publishers > 0;
        if !(self.publisher_seen && publishers == 0) {
            return None;
        }
        // Gone — but what it published before it went (after the caller last received) may
        // still be queued, its last sample among it: kept for `receive`, and the end said
        // once they have been received.
        while let Ok(Some(s)) = self.subscriber.receive() {
            self.pending.push_back(*s.payload());
        }
        self.pending.is_empty().then_some(End::Gone)
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

/// A run found by its run file in `/dev/shm`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct FoundRun {
    /// Where its iceoryx2 files are.
    pub location: IpcLocation,
    /// The user whose run it is (its run file's owner).
    pub uid: u32,
}

/// The runs whose run files are in `/dev/shm` now (under `root` only, if given): the
/// caller's own first, newest first within each.
pub fn runs(root: Option<&str>) -> Vec<FoundRun> {
    use std::os::unix::fs::MetadataExt;
    let Ok(entries) = std::fs::read_dir(qmarc_proto::service::SHM_DIR) else {
        return Vec::new();
    };
    let found = entries
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().ends_with("run.json"))
        .filter_map(|e| {
            let spec = qmarc_config::RunSpec::read(&e.path()).ok()?;
            let meta = e.metadata().ok()?;
            let run = FoundRun {
                location: IpcLocation::new(&spec.iox_prefix, &spec.iox_root),
                uid: meta.uid(),
            };
            (run_file(&spec.iox_prefix) == e.path() && root.is_none_or(|r| r == spec.iox_root))
                .then_some((meta.modified().ok()?, run))
        })
        .collect();
    own_first(found, nix::unistd::geteuid().as_raw())
}

/// `found` (with when each was made) in the order to try them: `me`'s own first, newest first
/// within each.
pub fn own_first(mut found: Vec<(std::time::SystemTime, FoundRun)>, me: u32) -> Vec<FoundRun> {
    found.sort_by_key(|(when, run)| (run.uid != me, std::cmp::Reverse(*when)));
    found.into_iter().map(|(_, r)| r).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::relay::TelemetryPublisher;

    fn sample(seq: u64, phase: Phase) -> TelemetrySample {
        TelemetrySample { seq, phase: phase.wire(), ..TelemetrySample::default() }
    }

    /// A publisher that sends its last samples and goes between the reader's receiving and
    /// its asking how the move ended: the move ended with its last sample (it was said to
    /// have died, "controller_lost", when a loaded machine ran the two in that order).
    #[test]
    fn the_last_samples_of_a_publisher_gone_meanwhile_are_received_before_the_end() {
        let location =
            IpcLocation::new(&format!("qmarc_readerend_{}_", std::process::id()), DEFAULT_ROOT);
        // Its files removed however the test ends.
        struct Removed(IpcLocation);
        impl Drop for Removed {
            fn drop(&mut self) {
                self.0.remove_files();
            }
        }
        let _removed = Removed(location.clone());
        let publisher = TelemetryPublisher::open(&location).unwrap();
        let mut reader = TelemetryReader::open(&location).unwrap();
        assert_eq!(reader.end(), None, "its publisher is there");
        assert!(publisher.publish(sample(0, Phase::Moving)));
        assert!(publisher.publish(sample(1, Phase::Done)));
        drop(publisher);
        assert_eq!(reader.end(), None, "two samples to receive first");
        assert_eq!(reader.receive().unwrap().map(|s| s.seq), Some(0));
        assert_eq!(reader.receive().unwrap().map(|s| s.seq), Some(1));
        assert_eq!(reader.receive().unwrap(), None);
        assert_eq!(reader.end(), Some(End::Last(sample(1, Phase::Done))));
        assert_eq!((reader.received(), reader.lost()), (2, 0));
        drop(reader);
        // A publisher gone without its last sample: gone, once what it sent is received.
        let publisher = TelemetryPublisher::open(&location).unwrap();
        let mut reader = TelemetryReader::open(&location).unwrap();
        assert_eq!(reader.end(), None);
        assert!(publisher.publish(sample(0, Phase::Moving)));
        drop(publisher);
        assert_eq!(reader.end(), None);
        assert_eq!(reader.receive().unwrap().map(|s| s.seq), Some(0));
        assert_eq!(reader.end(), Some(End::Gone));
    }
}
