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

/// What a cell refuses — a robot that cannot join it, a second camera — said, and the
/// program ends with exit code 3 (refused before anything moved).
#[derive(Debug, thiserror::Error)]
#[error("cell {cell}: {why}")]
pub struct Refused {
    /// The cell.
    pub cell: String,
    /// Why.
    pub why: String,
}

/// The exit code of a cell program that ended with `e`: 3 for a [`Refused`], else 1.
pub fn exit_code(e: &anyhow::Error) -> u8 {
    if e.is::<Refused>() { qmarc_proto::exit::REFUSED } else { qmarc_proto::exit::INTERNAL }
}
