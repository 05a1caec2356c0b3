//! The serving session: `qmarc-starter serve` keeps the robot under control and takes orders
//! from other programs (`qmarc cmd`, the console, a pick-and-place cycle, the ROS 2 bridge)
//! until it is told to quit. Everything of it lives here:
//!
//! - [`wire`]: the services `qmarc/command` and `qmarc/path` and their messages;
//! - [`client`]: a program's end ([`client::CommandClient`]) and what became of an order
//!   ([`client::OrderLedger`]);
//! - [`server`]: the controller's command thread, which checks each request and answers at
//!   once, then hands the loop what it accepted;
//! - [`generator`]: the loop's end, [`generator::ServeMove`], the trajectory generator that
//!   holds, moves, stops and follows lines and paths as orders arrive; [`path`] samples a sent
//!   path;
//! - [`discovery`]: which sessions (and runs) are alive, whose, and what their dead ones left;
//! - [`conveyor`]: the conveyor session — its dispatcher between the camera and the loop, and
//!   its picker, the generator that intercepts, tracks and places the belt's parts.
#![deny(missing_docs)]

pub mod client;
pub mod conveyor;
pub mod discovery;
pub mod generator;
pub mod path;
pub mod server;
pub mod wire;
