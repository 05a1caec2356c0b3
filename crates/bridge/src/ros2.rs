//! ROS 2 on Zenoh as rmw_zenoh (ROS 2 Jazzy, `rmw_zenoh_cpp` 0.2.4 and later) puts it there:
//! the key expressions of topics and services, the liveliness tokens that make a node and its
//! entities visible to the ROS graph (`ros2 topic list`), the QoS string in those tokens, the
//! attachment every sample, query and reply carries, and the CDR payload's encapsulation.
//! No crate does this apart from an experimental one (Cargo.toml says why); each format is
//! tested against rmw_zenoh's own documented examples.
//!
//! - Data: `<domain>/<name without its outer slashes>/<pkg>::<msg|srv>::dds_::<Type>_/RIHS01_<hash>`.
//! - Tokens: `@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<NN|MP|MS|SS|SC>/<enclave>/<namespace>/<node>`
//!   and, for an entity, `/<name>/<type>/<hash>/<qos>`, every `/` inside a part as `%`.
//! - Attachment: (i64 sequence number, i64 source time in ns, 16-byte gid), zenoh-ext
//!   serialised: 33 bytes.
//! - Payload: `00 01 00 00` (CDR, little-endian), then the CDR body.

/// A ROS 2 interface type as rmw_zenoh names it on the wire.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RosType {
    /// `sensor_msgs/msg/JointState`, as the ROS tools say it.
    pub name: &'static str,
    /// Its RIHS01 hash (rosidl's, over the type description).
    pub hash: &'static str,
}

impl RosType {
    /// The DDS-style name in key expressions: `sensor_msgs::msg::dds_::JointState_`.
    pub fn dds_name(&self) -> String {
        let mut parts: Vec<&str> = self.name.split('/').collect();
        let last = parts.pop().unwrap_or_default();
        format!("{}::dds_::{last}_", parts.join("::"))
    }
}

/// `sensor_msgs/msg/JointState`.
pub const JOINT_STATE: RosType = RosType {
    name: "sensor_msgs/msg/JointState",
    hash: "RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e",
};
/// `geometry_msgs/msg/PointStamped`.
pub const POINT_STAMPED: RosType = RosType {
    name: "geometry_msgs/msg/PointStamped",
    hash: "RIHS01_4c0296af86e01e562e9e0405d138a01537247580076c58ea38d7923ac1045897",
};
/// `diagnostic_msgs/msg/DiagnosticArray`.
pub const DIAGNOSTIC_ARRAY: RosType = RosType {
    name: "diagnostic_msgs/msg/DiagnosticArray",
    hash: "RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e",
};
/// `trajectory_msgs/msg/JointTrajectory`.
pub const JOINT_TRAJECTORY: RosType = RosType {
    name: "trajectory_msgs/msg/JointTrajectory",
    hash: "RIHS01_179b33eba59d676f6d967ac71fe35e7ca2f64b2f3928f4a018cec115e213796e",
};
/// `std_srvs/srv/Trigger` (a service: its hash is the service's).
pub const TRIGGER: RosType = RosType {
    name: "std_srvs/srv/Trigger",
    hash: "RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f",
};
/// `std_srvs/srv/SetBool`.
pub const SET_BOOL: RosType = RosType {
    name: "std_srvs/srv/SetBool",
    hash: "RIHS01_abe9e4bb6b41b40e6789712c00ec8871923e089af3f667a79992a428cff2da0a",
};

/// `control_msgs/action/FollowJointTrajectory`'s goal service (`_action/send_goal`).
pub const FJT_SEND_GOAL: RosType = RosType {
    name: "control_msgs/action/FollowJointTrajectory_SendGoal",
    hash: "RIHS01_b13789dddc325a7a962825c45e28c77d37237ec129dd0c34dc5994562938c57f",
};
/// Its result service (`_action/get_result`).
pub const FJT_GET_RESULT: RosType = RosType {
    name: "control_msgs/action/FollowJointTrajectory_GetResult",
    hash: "RIHS01_e3ceb38e3e1867c8dc0f46014df26e90eb93422f27e9e97f936e07f94be4bc8b",
};
/// Its feedback topic (`_action/feedback`).
pub const FJT_FEEDBACK: RosType = RosType {
    name: "control_msgs/action/FollowJointTrajectory_FeedbackMessage",
    hash: "RIHS01_80398fcb9674a79081a9906e2ccf0c804dd7cb15e22e362e606ee87186beab71",
};
/// Every action's cancel service (`_action/cancel_goal`).
pub const CANCEL_GOAL: RosType = RosType {
    name: "action_msgs/srv/CancelGoal",
    hash: "RIHS01_573d8b0a534451d7bc2ac8c5ffde8ac14b8593b7001175d0cd6516dcbeb8689a",
};
/// Every action's status topic (`_action/status`).
pub const GOAL_STATUS_ARRAY: RosType = RosType {
    name: "action_msgs/msg/GoalStatusArray",
    hash: "RIHS01_6c1684b00f177d37438febe6e709fc4e2b0d4248dca4854946f9ed8b30cda83e",
};

/// What kind of entity a liveliness token announces.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    /// A node (`NN`).
    Node,
    /// A publisher (`MP`).
    Publisher,
    /// A subscription (`MS`).
    Subscription,
    /// A service server (`SS`).
    Service,
}

impl EntityKind {
    fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
            EntityKind::Service => "SS",
        }
    }
}

/// A QoS profile, as far as the bridge sets one.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Reliable (else best effort).
    pub reliable: bool,
    /// Transient local (else volatile).
    pub transient_local: bool,
    /// Keep-last depth.
    pub depth: usize,
}

impl Qos {
    /// rclcpp's default: reliable, volatile, keep last 10.
    pub const DEFAULT: Qos = Qos { reliable: true, transient_local: false, depth: 10 };
    /// The sensor-data profile: best effort, volatile, keep last 5 (joint states at 250 Hz).
    pub const SENSOR_DATA: Qos = Qos { reliable: false, transient_local: false, depth: 5 };
    /// An action's status topic (rcl_action's): reliable, transient local, keep last 1.
    pub const ACTION_STATUS: Qos = Qos { reliable: true, transient_local: true, depth: 1 };

    /// The token's QoS string: `R:D:H,depth:deadline:lifespan:liveliness`, each field empty
    /// where it is rmw_zenoh's default (reliable, volatile, keep last, depth 42, infinite
    /// durations, automatic liveliness): rclcpp's default is `::,10:,:,:,,`.
    pub fn keyexpr(&self) -> String {
        let reliability = if self.reliable { "" } else { "2" };
        let durability = if self.transient_local { "1" } else { "" };
        let depth = if self.depth == 42 { String::new() } else { self.depth.to_string() };
        format!("{reliability}:{durability}:,{depth}:,:,:,,")
    }
}

/// A ROS name's parts in a token: every `/` as `%` (`/` alone is `%`).
pub fn mangle(name: &str) -> String {
    name.replace('/', "%")
}

/// The fully qualified name of `name` in namespace `ns` (`""` or `/robot1`): `/robot1/joint_states`;
/// a name starting with `/` is absolute.
pub fn qualified(ns: &str, name: &str) -> String {
    if name.starts_with('/') {
        return name.to_string();
    }
    let ns = ns.trim_end_matches('/');
    format!("{ns}/{name}")
}

/// The data key expression of `name` (fully qualified) of type `t` in `domain`.
pub fn data_keyexpr(domain: u32, name: &str, t: &RosType) -> String {
    let inner = name.strip_prefix('/').unwrap_or(name);
    let inner = inner.strip_suffix('/').unwrap_or(inner);
    format!("{domain}/{inner}/{}/{}", t.dds_name(), t.hash)
}

/// The node the bridge is in the ROS graph.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NodeInfo {
    /// The domain id.
    pub domain: u32,
    /// The Zenoh session's id, as it prints.
    pub zid: String,
    /// The node's id in the session.
    pub id: u32,
    /// Its namespace: `/` or `/robot1`.
    pub namespace: String,
    /// Its name.
    pub name: String,
}

impl NodeInfo {
    /// The liveliness token of the node itself.
    pub fn node_token(&self) -> String {
        self.token_head(self.id, EntityKind::Node)
    }

    /// The liveliness token of entity `id` of `kind` on `name` (fully qualified) of type `t`.
    pub fn entity_token(
        &self,
        id: u32,
        kind: EntityKind,
        name: &str,
        t: &RosType,
        qos: &Qos,
    ) -> String {
        format!(
            "{}/{}/{}/{}/{}",
            self.token_head(id, kind),
            mangle(name),
            t.dds_name(),
            t.hash,
            qos.keyexpr()
        )
    }

    /// The key expression of every node's token with this node's domain, namespace and
    /// name, whichever session and id announced it.
    pub fn same_node_tokens(&self) -> String {
        format!(
            "@ros2_lv/{}/*/*/*/{}/*/{}/{}",
            self.domain,
            EntityKind::Node.code(),
            mangle(&self.namespace),
            self.name
        )
    }

    fn token_head(&self, id: u32, kind: EntityKind) -> String {
        format!(
            "@ros2_lv/{}/{}/{}/{id}/{}/%/{}/{}",
            self.domain,
            self.zid,
            self.id,
            kind.code(),
            mangle(&self.namespace),
            self.name
        )
    }
}

/// The attachment of a sample, query or reply: its sequence number, its source time (ns
/// since the epoch) and the sender's 16-byte gid, zenoh-ext serialised as rmw_zenoh's
/// zenoh-cpp serialises them (33 bytes).
pub fn attachment(sequence: i64, time_ns: i64, gid: &[u8; 16]) -> zenoh::bytes::ZBytes {
    zenoh_ext::z_serialize(&(sequence, time_ns, *gid))
}

/// An attachment's fields, if it is one.
pub fn read_attachment(bytes: &zenoh::bytes::ZBytes) -> Option<(i64, i64, [u8; 16])> {
    zenoh_ext::z_deserialize::<(i64, i64, [u8; 16])>(bytes).ok()
}

/// A gid for entity `token`: 16 bytes that differ between entities and sessions (rmw_zenoh
/// hashes the token; only uniqueness matters to it).
pub fn gid_of(token: &str) -> [u8; 16] {
    use std::hash::{Hash, Hasher};
    let half = |salt: u64| {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (salt, token).hash(&mut h);
        h.finish().to_le_bytes()
    };
    let mut gid = [0u8; 16];
    gid[..8].copy_from_slice(&half(0));
    gid[8..].copy_from_slice(&half(1));
    gid
}

pub use qmarc_ros2msg::cdr::{CDR_LE, MAX_PAYLOAD_BYTES, PayloadError, from_cdr, to_cdr};

#[cfg(test)]
mod tests;
