//! `qmarc-bridge`: a serving QMARC (`qmarc-starter serve`) as a ROS 2 participant over Eclipse
//! Zenoh, as ROS 2 Jazzy's rmw_zenoh makes one, with no ROS 2 installed: ROS 2 tools and MoveIt
//! see the robot, command it and watch it (thesis 6.2.4, QMARC in an existing system).
//!
//! The bridge is a process of its own. It talks to the controller only through the iceoryx2
//! services every client uses (telemetry, `qmarc/command`, `qmarc/path`), so the servo loop
//! never waits on the network. [`ros2`] is rmw_zenoh's wire conventions, [`msgs`] and
//! [`action_msgs`] the messages, [`action`] the `FollowJointTrajectory` server.
#![deny(missing_docs)]

pub use qmarc_ros2msg::msgs;

pub mod action;
pub mod action_msgs;
pub mod bridge;
pub mod convert;
pub mod node;
pub mod ros2;
