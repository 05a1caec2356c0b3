//! The ROS 2 messages QMARC speaks, field for field as their `.msg` files (Jazzy) define
//! them, for `cdr-encoding`'s serde: the order of the fields is the wire's.

use serde::{Deserialize, Serialize};

/// `builtin_interfaces/msg/Time`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Time {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, 0‥1e9.
    pub nanosec: u32,
}

impl Time {
    /// The time `ns` nanoseconds after the epoch.
    pub fn from_ns(ns: u64) -> Time {
        Time { sec: (ns / 1_000_000_000) as i32, nanosec: (ns % 1_000_000_000) as u32 }
    }

    /// Now, on the system clock (ROS time).
    pub fn now() -> Time {
        let d =
            std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).unwrap_or_default();
        Time::from_ns(d.as_nanos() as u64)
    }
}

/// `std_msgs/msg/Header`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Header {
    /// When.
    pub stamp: Time,
    /// In which frame.
    pub frame_id: String,
}

/// `sensor_msgs/msg/JointState`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointState {
    /// Stamp and frame.
    pub header: Header,
    /// Joint names.
    pub name: Vec<String>,
    /// rad.
    pub position: Vec<f64>,
    /// rad/s.
    pub velocity: Vec<f64>,
    /// The drive's effort (here the DAC's volts).
    pub effort: Vec<f64>,
}

/// The joint names of `n` motors: `motor1` … `motorN`.
pub fn motor_names(n: usize) -> Vec<String> {
    (1..=n).map(|m| format!("motor{m}")).collect()
}

/// `geometry_msgs/msg/Point`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Point {
    /// m.
    pub x: f64,
    /// m.
    pub y: f64,
    /// m.
    pub z: f64,
}

/// `geometry_msgs/msg/PointStamped`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct PointStamped {
    /// Stamp and frame.
    pub header: Header,
    /// The point.
    pub point: Point,
}

/// `diagnostic_msgs/msg/KeyValue`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct KeyValue {
    /// The key.
    pub key: String,
    /// Its value, as text.
    pub value: String,
}

/// `diagnostic_msgs/msg/DiagnosticStatus`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticStatus {
    /// 0 OK, 1 WARN, 2 ERROR, 3 STALE.
    pub level: u8,
    /// What is diagnosed.
    pub name: String,
    /// Its state in words.
    pub message: String,
    /// The hardware.
    pub hardware_id: String,
    /// The details.
    pub values: Vec<KeyValue>,
}

impl DiagnosticStatus {
    /// Level OK.
    pub const OK: u8 = 0;
    /// Level WARN.
    pub const WARN: u8 = 1;
    /// Level ERROR.
    pub const ERROR: u8 = 2;
}

/// `diagnostic_msgs/msg/DiagnosticArray`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct DiagnosticArray {
    /// Stamp.
    pub header: Header,
    /// One per thing diagnosed.
    pub status: Vec<DiagnosticStatus>,
}

/// `std_srvs/srv/Trigger`'s request: empty, which CDR carries as one byte.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct TriggerRequest {
    /// rosidl's member of an empty structure.
    pub structure_needs_at_least_one_member: u8,
}

/// `std_srvs/srv/Trigger`'s and `SetBool`'s response.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct SuccessResponse {
    /// Done.
    pub success: bool,
    /// Why not, or what was done.
    pub message: String,
}

/// `std_srvs/srv/SetBool`'s request.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct SetBoolRequest {
    /// On (true) or off.
    pub data: bool,
}

/// `builtin_interfaces/msg/Duration`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Duration {
    /// Seconds.
    pub sec: i32,
    /// Nanoseconds, 0‥1e9.
    pub nanosec: u32,
}

/// `trajectory_msgs/msg/JointTrajectoryPoint`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTrajectoryPoint {
    /// rad, one per joint.
    pub positions: Vec<f64>,
    /// rad/s: one per joint, or none.
    pub velocities: Vec<f64>,
    /// rad/s²: one per joint, or none.
    pub accelerations: Vec<f64>,
    /// One per joint, or none.
    pub effort: Vec<f64>,
    /// When, from the trajectory's start.
    pub time_from_start: Duration,
}

/// `trajectory_msgs/msg/JointTrajectory`.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct JointTrajectory {
    /// Stamp and frame (not waited for: a trajectory starts when it arrives).
    pub header: Header,
    /// The joints the points' columns are.
    pub joint_names: Vec<String>,
    /// The points, their times rising.
    pub points: Vec<JointTrajectoryPoint>,
}
