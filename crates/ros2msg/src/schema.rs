//! `ros2msg` schema texts as rosbag2's MCAP storage writes them: the message's definition,
//! then each type it uses, after a line of 80 `=` and `MSG: <type>`. The texts are those of
//! ROS 2 Jazzy's `.msg` files without their comments, byte for byte what rosbags'
//! `generate_msgdef` gives (checked by `tests/mcap.rs`, with rosbags itself).

/// The line between a definition and each type it uses.
const SEPARATOR: &str =
    "================================================================================\n";

/// `sensor_msgs/msg/JointState`'s name in a schema record.
pub const JOINT_STATE: &str = "sensor_msgs/msg/JointState";

/// The `ros2msg` text of `sensor_msgs/msg/JointState`, with `std_msgs/Header` and
/// `builtin_interfaces/Time`.
pub fn joint_state() -> String {
    [
        "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\n\
         float64[] effort\n",
        SEPARATOR,
        "MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n",
        SEPARATOR,
        "MSG: builtin_interfaces/Time\nint32 sec\nuint32 nanosec\n",
    ]
    .concat()
}

#[cfg(test)]
mod tests {
    /// Every type the definition uses is defined after it, once, and each field line is
    /// `<type> <name>`.
    #[test]
    fn the_joint_state_text_defines_every_type_it_uses() {
        let text = super::joint_state();
        let parts: Vec<&str> = text.split(super::SEPARATOR).collect();
        assert_eq!(parts.len(), 3);
        assert_eq!(parts[1].lines().next(), Some("MSG: std_msgs/Header"));
        assert_eq!(parts[2].lines().next(), Some("MSG: builtin_interfaces/Time"));
        for line in text.lines().filter(|l| !l.starts_with("MSG:") && !l.starts_with('=')) {
            assert_eq!(line.split(' ').count(), 2, "{line}");
        }
        assert!(text.ends_with("uint32 nanosec\n"));
    }
}
