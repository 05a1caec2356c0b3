//! A cell of robots on one belt over Zenoh (issue 47, docs/cell.md): the processes that put
//! conveyor sessions on different hosts together.
//!
//! - [`camera`]: the cell's camera (`qmarc-cell camera`): the camera server of the cell's
//!   settings, its detections merged into parts numbered once for every robot, published with
//!   their exposure on the system clock; the cell's belt for the robots that join.
//! - [`robot`]: a robot's companion (`qmarc-cell robot`, started by `qmarc-starter conveyor
//!   --cell NAME`): it joins the cell (refused if its belt disagrees with the cell's), then
//!   relays between the cell and its conveyor session's dispatcher
//!   ([`qmarc_proto::cell::CellMsg`] over iceoryx2): the network never reaches the loop.
//!
//! Everything on the wire is JSON ([`wire`]) on the key expressions of [`keys`], so that any
//! Zenoh client can watch a cell; who is alive is Zenoh's liveliness tokens.
#![deny(missing_docs)]

pub mod camera;
pub mod keys;
pub mod robot;
pub mod session;
pub mod wire;
