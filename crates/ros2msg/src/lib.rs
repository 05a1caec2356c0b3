//! The ROS 2 side of QMARC's data, with no ROS 2 and no network: the messages it speaks
//! ([`msgs`], field for field as Jazzy's `.msg` files), their payloads ([`cdr`]: the CDR
//! encapsulation header, then OMG CDR) and the `ros2msg` schema texts rosbag2 stores beside
//! them in an MCAP file ([`schema`]). The ROS 2 bridge (`qmarc-bridge`) sends these over
//! Zenoh; `gather.mcap` (`qmarc-foxglove`) stores them.
#![deny(missing_docs)]

pub mod cdr;
pub mod msgs;
pub mod schema;
