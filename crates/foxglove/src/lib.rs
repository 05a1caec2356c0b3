//! The robot as Foxglove, PlotJuggler and rosbag2 see it (issue 45): every move's data as
//! `gather.mcap` ([`recording`]) on the channels of [`channels`] — the gathered rows, the
//! motors as ROS 2 joint states, the effector, the Deltabot drawn from its kinematics
//! ([`scene`]) and the run's log — written after the move from what the loop gathered, never
//! from the loop. Foxglove's own SDK (`foxglove`) writes the file and carries the schemas;
//! only the drawing is ours (docs/foxglove.md). [`read`] and [`render`] read a file's scene
//! back and draw it to a PNG (`qmarc-foxglove scene`).
#![deny(missing_docs)]

pub mod belt;
pub mod channels;
pub mod live;
pub mod proxy;
pub mod publish;
pub mod read;
pub mod recording;
pub mod render;
pub mod scene;
pub mod watch;
