//! The bridge's ROS 2 node on Zenoh: its session (rmw_zenoh's defaults, or a file's), its
//! liveliness tokens, and its publishers, subscriptions and services, each declared where
//! rmw_zenoh would declare it and announced as rmw_zenoh announces it.

use crate::ros2::{self, EntityKind, NodeInfo, Qos, RosType};
use std::path::Path;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::handlers::FifoChannelHandler;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::{Publisher, Subscriber};
use zenoh::query::{Query, Queryable};
use zenoh::sample::Sample;

/// A Zenoh call failed.
#[derive(Debug, thiserror::Error)]
#[error("zenoh: {what}: {why}")]
pub struct ZenohError {
    /// What was being done.
    pub what: String,
    /// Zenoh's words.
    pub why: String,
}

fn failed(what: impl Into<String>) -> impl FnOnce(zenoh::Error) -> ZenohError {
    let what = what.into();
    move |e| ZenohError { what, why: e.to_string() }
}

/// rmw_zenoh's session: a peer that connects to a router at `tcp/localhost:7447` (retrying
/// while there is none), listens on a port of its own on localhost, and does not scout by
/// multicast. `file`, when given, is a Zenoh configuration (JSON5) used instead.
pub fn session_config(file: Option<&Path>) -> Result<zenoh::Config, ZenohError> {
    if let Some(path) = file {
        return zenoh::Config::from_file(path)
            .map_err(failed(format!("the configuration {}", path.display())));
    }
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v).map_err(failed(format!("setting {k}")))
    };
    set(&mut c, "mode", r#""peer""#)?;
    set(&mut c, "connect/endpoints", r#"["tcp/localhost:7447"]"#)?;
    set(&mut c, "listen/endpoints", r#"["tcp/localhost:0"]"#)?;
    set(&mut c, "scouting/multicast/enabled", "false")?;
    Ok(c)
}

/// The node: the session, its tokens and its entities' ids.
pub struct Node {
    session: zenoh::Session,
    info: NodeInfo,
    next_id: u32,
    tokens: Vec<LivelinessToken>,
}

/// How often a reliable transient-local publisher says what it last sent (rmw_zenoh's
/// sporadic heartbeat), so that a subscriber that missed it asks the cache.
const MISS_HEARTBEAT: std::time::Duration = std::time::Duration::from_millis(500);

/// A Zenoh publisher as rmw_zenoh declares it for a QoS: plain for a volatile topic; for a
/// transient-local one, zenoh-ext's advanced publisher, whose cache of the last `depth`
/// samples a subscriber that joins later queries.
enum ZenohPublisher {
    Volatile(Publisher<'static>),
    TransientLocal(zenoh_ext::AdvancedPublisher<'static>),
}

/// A publisher and what each of its samples carries.
pub struct RosPublisher {
    publisher: ZenohPublisher,
    gid: [u8; 16],
    sequence: i64,
    /// The data key expression.
    pub keyexpr: String,
}

impl RosPublisher {
    /// Publishes `payload` (CDR with its header), with its attachment.
    pub fn put(&mut self, payload: Vec<u8>) -> Result<(), ZenohError> {
        self.sequence += 1;
        let attachment = ros2::attachment(self.sequence, now_ns(), &self.gid);
        match &self.publisher {
            ZenohPublisher::Volatile(p) => p.put(payload).attachment(attachment).wait(),
            ZenohPublisher::TransientLocal(p) => p.put(payload).attachment(attachment).wait(),
        }
        .map_err(failed(format!("publishing on {}", self.keyexpr)))
    }
}

/// Nanoseconds since the epoch, the attachment's source time.
pub fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as i64)
}

/// A service server: its queries, and the gid its replies carry.
pub struct RosService {
    queryable: Queryable<FifoChannelHandler<Query>>,
    /// The data key expression.
    pub keyexpr: String,
}

impl RosService {
    /// The next request waiting, if any.
    pub fn try_recv(&self) -> Option<Query> {
        self.queryable.try_recv().ok().flatten()
    }

    /// Answers `query` with `payload` (CDR), echoing its sequence number and client gid as
    /// rmw_zenoh's clients match them.
    pub fn reply(&self, query: &Query, payload: Vec<u8>) -> Result<(), ZenohError> {
        let (sequence, _, gid) =
            query.attachment().and_then(ros2::read_attachment).unwrap_or((0, 0, [0; 16]));
        query
            .reply(&self.keyexpr, payload)
            .attachment(ros2::attachment(sequence, now_ns(), &gid))
            .wait()
            .map_err(failed(format!("replying on {}", self.keyexpr)))
    }
}

/// The payload of a query or a sample, as bytes.
pub fn payload_of(bytes: Option<&ZBytes>) -> Vec<u8> {
    bytes.map(|b| b.to_bytes().into_owned()).unwrap_or_default()
}

impl Node {
    /// Opens the session of `config` and announces the node `name` in `namespace` (`/` or
    /// `/robot1`) of `domain`.
    pub fn open(
        config: zenoh::Config,
        domain: u32,
        namespace: &str,
        name: &str,
    ) -> Result<Node, ZenohError> {
        let session = zenoh::open(config).wait().map_err(failed("opening the session"))?;
        let info = NodeInfo {
            domain,
            zid: session.zid().to_string(),
            id: 0,
            namespace: if namespace.is_empty() { "/".into() } else { namespace.into() },
            name: name.into(),
        };
        let mut node = Node { session, info, next_id: 1, tokens: Vec::new() };
        let token = node.info.node_token();
        node.announce(&token)?;
        Ok(node)
    }

    /// The node's namespace.
    pub fn namespace(&self) -> &str {
        &self.info.namespace
    }

    fn announce(&mut self, token: &str) -> Result<(), ZenohError> {
        let t = self
            .session
            .liveliness()
            .declare_token(token.to_string())
            .wait()
            .map_err(failed(format!("the liveliness token {token}")))?;
        self.tokens.push(t);
        Ok(())
    }

    /// The fully qualified name, key expression and token of a new entity.
    fn entity(&mut self, kind: EntityKind, name: &str, t: &RosType, qos: &Qos) -> (String, String) {
        let name = ros2::qualified(&self.info.namespace, name);
        let id = self.next_id;
        self.next_id += 1;
        (
            ros2::data_keyexpr(self.info.domain, &name, t),
            self.info.entity_token(id, kind, &name, t, qos),
        )
    }

    /// A publisher of `t` on `name` (relative to the namespace, or absolute), declared as
    /// rmw_zenoh declares one for `qos`: dropping samples rather than waiting on a busy link;
    /// if transient local, detectable, with a cache of `depth` samples, and (if reliable)
    /// sporadic heartbeats for the subscribers' miss detection. (A best-effort
    /// transient-local topic's cache orders samples by timestamp, which the session's
    /// `timestamping` must then enable: the bridge has no such topic.)
    pub fn publisher(
        &mut self,
        name: &str,
        t: &RosType,
        qos: &Qos,
    ) -> Result<RosPublisher, ZenohError> {
        use zenoh_ext::{AdvancedPublisherBuilderExt, CacheConfig, MissDetectionConfig};
        let (keyexpr, token) = self.entity(EntityKind::Publisher, name, t, qos);
        let declared = || failed(format!("a publisher on {keyexpr}"));
        let builder = self
            .session
            .declare_publisher(keyexpr.clone())
            .congestion_control(zenoh::qos::CongestionControl::Drop);
        let publisher = if qos.transient_local {
            let mut advanced = builder
                .cache(CacheConfig::default().max_samples(qos.depth.max(1)))
                .publisher_detection();
            if qos.reliable {
                let heartbeat = MissDetectionConfig::default().sporadic_heartbeat(MISS_HEARTBEAT);
                advanced = advanced.sample_miss_detection(heartbeat);
            }
            ZenohPublisher::TransientLocal(advanced.wait().map_err(declared())?)
        } else {
            ZenohPublisher::Volatile(builder.wait().map_err(declared())?)
        };
        self.announce(&token)?;
        Ok(RosPublisher { publisher, gid: ros2::gid_of(&token), sequence: 0, keyexpr })
    }

    /// A subscription to `t` on `name`: its samples queue (at most `depth` kept).
    pub fn subscription(
        &mut self,
        name: &str,
        t: &RosType,
        qos: &Qos,
    ) -> Result<Subscriber<FifoChannelHandler<Sample>>, ZenohError> {
        let (keyexpr, token) = self.entity(EntityKind::Subscription, name, t, qos);
        let sub = self
            .session
            .declare_subscriber(keyexpr.clone())
            .with(zenoh::handlers::FifoChannel::new(qos.depth.max(1)))
            .wait()
            .map_err(failed(format!("a subscription to {keyexpr}")))?;
        self.announce(&token)?;
        Ok(sub)
    }

    /// A service server of `t` on `name`.
    pub fn service(&mut self, name: &str, t: &RosType) -> Result<RosService, ZenohError> {
        let (keyexpr, token) = self.entity(EntityKind::Service, name, t, &Qos::DEFAULT);
        let queryable = self
            .session
            .declare_queryable(keyexpr.clone())
            .complete(true)
            .with(zenoh::handlers::FifoChannel::new(16))
            .wait()
            .map_err(failed(format!("a service on {keyexpr}")))?;
        self.announce(&token)?;
        Ok(RosService { queryable, keyexpr })
    }
}
