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

/// The node could not be opened.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum NodeOpenError {
    /// Zenoh failed.
    #[error(transparent)]
    Zenoh(#[from] ZenohError),
    /// A node of the same name is alive in the domain (its liveliness token says so): two
    /// would be one node to ROS, their topics interleaved and every command reaching both.
    #[error(
        "a ROS node {node} is already alive in domain {domain} (its liveliness token \
         {token}; one that died keeps it for its session's lease, about 10 s): give this \
         bridge another --namespace (or --domain), or start it again once the other is gone"
    )]
    Alive {
        /// The node's fully qualified name.
        node: String,
        /// The domain id.
        domain: u32,
        /// The live node's token.
        token: String,
    },
}

/// How long the bridge asks the network for a live node of its name before it announces its
/// own: the router answers at once with what it knows; a peer's link may take a moment.
const ALIVE_QUERY: std::time::Duration = std::time::Duration::from_secs(2);

/// How long the bridge (and a cell's process) waits for its session to reach a router or
/// peer it connects to (rmw_zenoh's default router may not run: it then goes on, retrying,
/// as rmw_zenoh does).
pub const LINK_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

/// Whether `session` has reached a router or a peer.
fn linked(session: &zenoh::Session) -> bool {
    let info = session.info();
    info.routers_zid().wait().next().is_some() || info.peers_zid().wait().next().is_some()
}

/// Opens the session of `config` and, when it connects to anyone, waits up to
/// [`LINK_WAIT`] for it to reach a router or a peer: until then, nobody could answer what it
/// asks (a node or robot of its name alive, the cell's camera). It goes on after, retrying.
pub fn open_linked(config: zenoh::Config) -> Result<zenoh::Session, ZenohError> {
    let connects = config
        .get_json("connect/endpoints")
        .is_ok_and(|j| j.trim() != "[]" && !j.trim().is_empty());
    let session = zenoh::open(config).wait().map_err(failed("opening the session"))?;
    let since = std::time::Instant::now();
    while connects && !linked(&session) && since.elapsed() < LINK_WAIT {
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    Ok(session)
}

/// The error of a Zenoh call that failed while `what` was being done.
pub fn failed(what: impl Into<String>) -> impl FnOnce(zenoh::Error) -> ZenohError {
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
    ) -> Result<Node, NodeOpenError> {
        // Linked first: until then nobody could say whether a node of its name is alive.
        let session = open_linked(config)?;
        let info = NodeInfo {
            domain,
            zid: session.zid().to_string(),
            id: 0,
            namespace: if namespace.is_empty() { "/".into() } else { namespace.into() },
            name: name.into(),
        };
        // A node of this name alive in the domain: refused, naming it.
        let alive = info.same_node_tokens();
        let replies = session
            .liveliness()
            .get(alive.as_str())
            .timeout(ALIVE_QUERY)
            .wait()
            .map_err(failed(format!("asking for {alive}")))?;
        if let Some(token) = replies
            .iter()
            .filter_map(|r| r.result().ok().map(|s| s.key_expr().to_string()))
            .find(|t| !t.contains(&format!("/{}/", info.zid)))
        {
            return Err(NodeOpenError::Alive {
                node: ros2::qualified(&info.namespace, name),
                domain,
                token,
            });
        }
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
