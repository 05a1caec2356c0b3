//! The channels a run is seen through, the same in `gather.mcap` and in the live view: their
//! topics, encodings and schemas, and the messages' payloads.
//!
//! | topic | encoding | schema |
//! |---|---|---|
//! | `/qmarc/gather` | json | JSON Schema `qmarc.GatherRow`: gather.csv's columns |
//! | `/joint_states` | cdr | ros2msg `sensor_msgs/msg/JointState` |
//! | `/qmarc/scene` | protobuf | `foxglove.SceneUpdate` |
//! | `/qmarc/effector` | json | JSON Schema `qmarc.Effector` |
//! | `/qmarc/log` | protobuf | `foxglove.Log` |

use foxglove::messages::{Log, SceneUpdate, log::Level};
use foxglove::{
    Channel, ChannelBuilder, Context, FoxgloveError, PartialMetadata, RawChannel, Schema,
};
use qmarc_ros2msg::msgs::{Header, JointState, Time};
use std::sync::Arc;

/// The gathered rows, one message each: gather.csv's columns and values.
pub const GATHER: &str = "/qmarc/gather";
/// The motors as ROS 2 joint states (rad from home, rad/s, the DAC's volts as effort).
pub const JOINT_STATES: &str = "/joint_states";
/// The Deltabot drawn (and the belt with its parts).
pub const SCENE: &str = "/qmarc/scene";
/// The effector's commanded and actual points, mm, and their distance.
pub const EFFECTOR: &str = "/qmarc/effector";
/// Phases, warnings and faults.
pub const LOG: &str = "/qmarc/log";

/// Whether gather.csv's column `name` holds whole numbers (the cycle, DAC codes, the
/// gripper's state, the belt's counts).
pub fn is_integer_column(name: &str) -> bool {
    name == "cycle" || name == "grip" || name == "conv" || name.starts_with("dac")
}

/// The JSON Schema of a gathered row with `columns` (gather.csv's header).
pub fn gather_schema(columns: &[String]) -> String {
    let properties: Vec<String> = columns
        .iter()
        .map(|c| {
            let kind = if is_integer_column(c) { "integer" } else { "number" };
            format!("\"{c}\":{{\"type\":\"{kind}\"}}")
        })
        .collect();
    let required: Vec<String> = columns.iter().map(|c| format!("\"{c}\"")).collect();
    format!(
        "{{\"title\":\"qmarc.GatherRow\",\"description\":\"One gathered servo cycle: \
         gather.csv's columns (counts, DAC codes, s)\",\"type\":\"object\",\
         \"properties\":{{{}}},\"required\":[{}]}}",
        properties.join(","),
        required.join(",")
    )
}

/// The JSON Schema of `/qmarc/effector`'s messages.
pub const EFFECTOR_SCHEMA: &str = r##"{"title":"qmarc.Effector","description":"The effector centre, robot frame, mm: commanded (the forward kinematics of the command) and actual (of the encoders), and their distance","type":"object","properties":{"cmd":{"$ref":"#/$defs/point"},"act":{"$ref":"#/$defs/point"},"error_mm":{"type":"number"}},"required":["cmd","act","error_mm"],"$defs":{"point":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}},"required":["x","y","z"]}}}"##;

/// The five channels, on one context (whose sinks, an MCAP file or a live server, get every
/// message logged on them).
pub struct Channels {
    /// [`GATHER`].
    pub gather: Arc<RawChannel>,
    /// [`JOINT_STATES`].
    pub joint_states: Arc<RawChannel>,
    /// [`SCENE`].
    pub scene: Channel<SceneUpdate>,
    /// [`EFFECTOR`].
    pub effector: Arc<RawChannel>,
    /// [`LOG`].
    pub log: Channel<Log>,
}

impl Channels {
    /// The channels on `ctx`, the gathered rows having `columns`.
    pub fn new(ctx: &Arc<Context>, columns: &[String]) -> Result<Channels, FoxgloveError> {
        let json = |topic: &str, name: &str, schema: String| {
            ChannelBuilder::new(topic)
                .context(ctx)
                .message_encoding("json")
                .schema(Schema::new(name, "jsonschema", schema.into_bytes()))
                .build_raw()
        };
        Ok(Channels {
            gather: json(GATHER, "qmarc.GatherRow", gather_schema(columns))?,
            joint_states: ChannelBuilder::new(JOINT_STATES)
                .context(ctx)
                .message_encoding("cdr")
                .schema(Schema::new(
                    qmarc_ros2msg::schema::JOINT_STATE,
                    "ros2msg",
                    qmarc_ros2msg::schema::joint_state().into_bytes(),
                ))
                .build_raw()?,
            scene: ChannelBuilder::new(SCENE).context(ctx).build::<SceneUpdate>(),
            effector: json(EFFECTOR, "qmarc.Effector", EFFECTOR_SCHEMA.to_string())?,
            log: ChannelBuilder::new(LOG).context(ctx).build::<Log>(),
        })
    }

    /// Logs `message` at `level` on `/qmarc/log` at `ns` (ns since the Unix epoch).
    pub fn say(&self, ns: u64, level: Level, message: &str) {
        let msg = Log {
            timestamp: Some(crate::scene::stamp(ns)),
            level: level as i32,
            message: message.to_string(),
            name: "qmarc".to_string(),
            ..Default::default()
        };
        self.log.log_with_time(&msg, ns);
    }

    /// Logs `bytes` on `channel` at `log_ns` (ns since the Unix epoch).
    pub fn put(channel: &RawChannel, bytes: &[u8], log_ns: u64) {
        channel.log_with_meta(bytes, PartialMetadata::with_log_time(log_ns));
    }
}

/// A JSON number: the shortest text that parses back to the same value (Ryū: the value
/// gather.csv's `{}` gives, perhaps written `1.0` or `1e-7`), `null` when not finite (JSON has
/// no NaN).
pub fn json_number(out: &mut String, v: f64) {
    // A whole number (an encoder's counts) as an integer: the same value, written faster.
    if v.fract() == 0.0 && v.abs() < 1e15 {
        json_integer(out, v as i64);
    } else if v.is_finite() {
        out.push_str(ryu::Buffer::new().format_finite(v));
    } else {
        out.push_str("null");
    }
}

/// A JSON integer.
pub fn json_integer(out: &mut String, v: i64) {
    out.push_str(itoa::Buffer::new().format(v));
}

/// `/qmarc/effector`'s message: the commanded and actual points, mm, and their distance.
pub fn effector_json(out: &mut String, cmd: [f64; 3], act: [f64; 3]) {
    out.clear();
    for (i, (name, p)) in [("cmd", cmd), ("act", act)].into_iter().enumerate() {
        out.push_str(if i == 0 { "{\"" } else { ",\"" });
        out.push_str(name);
        out.push_str("\":{");
        for (k, axis) in ["x", "y", "z"].into_iter().enumerate() {
            out.push_str(if k == 0 { "\"" } else { ",\"" });
            out.push_str(axis);
            out.push_str("\":");
            json_number(out, p[k]);
        }
        out.push('}');
    }
    out.push_str(",\"error_mm\":");
    let d = (0..3).map(|i| (cmd[i] - act[i]).powi(2)).sum::<f64>().sqrt();
    json_number(out, d);
    out.push('}');
}

/// The joint states of motors at `act` counts moving at `rate` counts/s, driven by DAC codes
/// `dac`, stamped `stamp_ns`, as the ROS 2 bridge publishes them: names `motor1…N`, rad from
/// home, rad/s, volts; a CDR payload.
pub fn joint_states_cdr(
    stamp_ns: u64,
    counts_per_rad: f64,
    act: &[f64],
    rate: &[f64],
    dac: &[i32],
) -> Vec<u8> {
    let msg = JointState {
        header: Header { stamp: Time::from_ns(stamp_ns), frame_id: String::new() },
        name: qmarc_ros2msg::msgs::motor_names(act.len()),
        position: act.iter().map(|c| c / counts_per_rad).collect(),
        velocity: rate.iter().map(|c| c / counts_per_rad).collect(),
        effort: dac.iter().map(|&d| qmarc_proto::dac_volts(d)).collect(),
    };
    // A JointState always encodes (strings and f64 sequences): never an empty payload.
    qmarc_ros2msg::cdr::to_cdr(&msg).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_gather_schema_names_every_column_with_its_kind() {
        let cols: Vec<String> =
            ["cycle", "time_s", "cmd1", "act1", "dac1", "grip", "conv"].map(String::from).into();
        let v: serde_json::Value = serde_json::from_str(&gather_schema(&cols)).unwrap();
        let props = v["properties"].as_object().unwrap();
        assert_eq!(props.len(), 7);
        for (c, kind) in [
            ("cycle", "integer"),
            ("time_s", "number"),
            ("cmd1", "number"),
            ("act1", "number"),
            ("dac1", "integer"),
            ("grip", "integer"),
            ("conv", "integer"),
        ] {
            assert_eq!(props[c]["type"], kind, "{c}");
        }
        assert_eq!(v["required"].as_array().unwrap().len(), 7);
        let _: serde_json::Value = serde_json::from_str(EFFECTOR_SCHEMA).unwrap();
    }

    #[test]
    fn the_effector_message_is_json_with_the_distance() {
        let mut s = String::new();
        effector_json(&mut s, [1.0, 2.5, -600.0], [1.0, 2.5 + 3.0, -600.0 - 4.0]);
        let v: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert_eq!(v["cmd"]["y"], 2.5);
        assert_eq!(v["act"]["z"], -604.0);
        assert_eq!(v["error_mm"], 5.0);
        effector_json(&mut s, [f64::NAN, 0.0, 0.0], [0.0; 3]);
        let v: serde_json::Value = serde_json::from_str(&s).unwrap();
        assert!(v["cmd"]["x"].is_null() && v["error_mm"].is_null());
    }

    #[test]
    fn joint_states_are_the_bridges_units() {
        let bytes = joint_states_cdr(
            1_500_000_001,
            1000.0,
            &[500.0, -2000.0],
            &[10.0, 0.0],
            &[8191, -4096],
        );
        let js: JointState = qmarc_ros2msg::cdr::from_cdr(&bytes, "JointState").unwrap();
        assert_eq!(js.header.stamp, Time { sec: 1, nanosec: 500_000_001 });
        assert_eq!(js.name, ["motor1", "motor2"]);
        assert_eq!(js.position, [0.5, -2.0]);
        assert_eq!(js.velocity, [0.01, 0.0]);
        assert_eq!(js.effort, [10.0, qmarc_proto::dac_volts(-4096)]);
    }
}
