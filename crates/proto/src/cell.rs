//! What a conveyor session in a cell (issue 47, docs/cell.md) and its companion, the process
//! that holds the cell's Zenoh session, tell each other: one fixed-size [`CellMsg`] on two
//! publish–subscribe services of the run's prefix — [`CELL_IN`] from the cell to the
//! session's dispatcher (the camera's parts, the robots alive, the others' claims and
//! passes), and [`CELL_OUT`] from the dispatcher to the cell (first its own [`CellKind::Member`]:
//! it takes parts from now; then this robot's claims, picks, give-ups and the parts it lets
//! pass).
//! The network never reaches the servo loop: the dispatcher is a thread of its own.
//!
//! Times are the system clock's (`CLOCK_REALTIME`, ns since the Unix epoch): the cell's hosts
//! share it (PTP or NTP), not their monotonic clocks.

use crate::service::ServiceError;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe;

/// From the cell to the dispatcher.
pub const CELL_IN: &str = "qmarc/cell/in";
/// From the dispatcher to the cell.
pub const CELL_OUT: &str = "qmarc/cell/out";
/// Messages queued per reader: seconds of the cell's traffic at any rate a cell picks.
pub const CELL_BUFFER: usize = 1024;
/// Bytes of a robot's name (NUL-padded; at most one fewer used).
pub const NAME_BYTES: usize = 32;
/// What a robot's companion (`qmarc-cell robot`) prints on standard output once it has
/// joined its cell, followed by when the cell's world began (ns of this host's
/// `CLOCK_MONOTONIC`: the run's `epoch_ns`).
pub const JOINED: &str = "qmarc-cell: joined, epoch_ns=";

/// What a [`CellMsg`] says.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum CellKind {
    /// The cell's camera saw a new part: `part`, `t_ns` its exposure, `belt_mm` along the
    /// cell's belt then, `across_mm`.
    Part = 1,
    /// `robot` is alive, its window `window_mm` of its own belt, `belt_mm` its offset along
    /// the cell's (its liveliness token, or its window said anew). On [`CELL_OUT`], the
    /// dispatcher's first word: it takes parts from now (the others count it in).
    Member = 2,
    /// `robot` is gone (its token went) at `t_ns`.
    Gone = 3,
    /// `robot` claimed `part` at `t_ns`, to grip it by `grip_by_ns`.
    Claim = 4,
    /// `robot` picked `part` (it is off the belt) at `t_ns`.
    Picked = 5,
    /// `robot` gave `part` up at `t_ns`: its claim is gone, and it lets the part pass.
    Released = 6,
    /// This robot is cut off from the cell (it cannot see the cell's camera: its router is
    /// down, or its link): it goes on with what it claimed, and claims nothing.
    CutOff = 7,
    /// This robot is in the cell: the others and their claims had (said at first, after
    /// an outage, and again from time to time).
    Rejoined = 8,
    /// `robot` lets `part` pass at `t_ns`: it will not claim it (it left its window
    /// unclaimed, it could not place it, or its session ended). A robot downstream may claim
    /// it once every robot from the part's home to it has said so.
    Passed = 9,
}

impl CellKind {
    /// The kind of wire value `v`, if it is one.
    pub fn from_wire(v: u32) -> Option<CellKind> {
        use CellKind::*;
        [Part, Member, Gone, Claim, Picked, Released, CutOff, Rejoined, Passed]
            .into_iter()
            .find(|k| *k as u32 == v)
    }
}

/// One message between the cell and the dispatcher.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("qmarc.CellMsg.v1")]
#[repr(C)]
pub struct CellMsg {
    /// [`CellKind`] as its wire value.
    pub kind: u32,
    /// The part (the cell camera's number), 0 when none.
    pub part: u32,
    /// The robot (`[cell] robot`), NUL-padded; empty for the camera's.
    pub robot: [u8; NAME_BYTES],
    /// When, ns of the system clock.
    pub t_ns: u64,
    /// A claim's grip, ns of the system clock.
    pub grip_by_ns: u64,
    /// Along the belt, mm: a part's on the cell's belt, a member's offset.
    pub belt_mm: f64,
    /// Across the belt, mm.
    pub across_mm: f64,
    /// A member's window, its own belt coordinates, mm.
    pub window_mm: [f64; 2],
}

const _: () = assert!(core::mem::size_of::<CellMsg>() == 88);

impl CellMsg {
    /// A message of `kind` about `part` by `robot` at `t_ns` (longer names are cut at
    /// [`NAME_BYTES`] − 1 bytes: the settings allow 31).
    pub fn new(kind: CellKind, part: u32, robot: &str, t_ns: u64) -> CellMsg {
        let mut name = [0u8; NAME_BYTES];
        let n = robot.len().min(NAME_BYTES - 1);
        name[..n].copy_from_slice(&robot.as_bytes()[..n]);
        CellMsg {
            kind: kind as u32,
            part,
            robot: name,
            t_ns,
            grip_by_ns: 0,
            belt_mm: 0.0,
            across_mm: 0.0,
            window_mm: [0.0; 2],
        }
    }

    /// Its kind, if the wire value is one.
    pub fn kind(&self) -> Option<CellKind> {
        CellKind::from_wire(self.kind)
    }

    /// The robot's name (up to the first NUL; not UTF-8: empty).
    pub fn robot(&self) -> &str {
        let n = self.robot.iter().position(|&b| b == 0).unwrap_or(NAME_BYTES);
        std::str::from_utf8(&self.robot[..n]).unwrap_or("")
    }
}

/// A cell service.
pub type CellService = publish_subscribe::PortFactory<ipc::Service, CellMsg, ()>;

/// Opens the cell service `name` ([`CELL_IN`] or [`CELL_OUT`]) on `node`, creating it if it
/// is not there yet: one writer, a few readers (the session, a diagnostic), nothing lost
/// while a reader keeps up, the oldest dropped for one that does not (never holding up the
/// writer).
pub fn open_cell_service(
    node: &Node<ipc::Service>,
    name: &str,
) -> Result<CellService, ServiceError> {
    let failed = |e: &dyn std::fmt::Debug| ServiceError::new("service", name, e);
    let service = ServiceName::new(name).map_err(|e| failed(&e))?;
    node.service_builder(&service)
        .publish_subscribe::<CellMsg>()
        .max_publishers(1)
        .max_subscribers(4)
        .subscriber_max_buffer_size(CELL_BUFFER)
        .history_size(0)
        .enable_safe_overflow(true)
        .open_or_create()
        .map_err(|e| failed(&e))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_message_carries_its_kind_and_robot() {
        let m = CellMsg::new(CellKind::Claim, 7, "east-2", 5);
        assert_eq!((m.kind(), m.part, m.robot(), m.t_ns), (Some(CellKind::Claim), 7, "east-2", 5));
        let long = "x".repeat(40);
        assert_eq!(CellMsg::new(CellKind::Member, 0, &long, 0).robot(), &long[..31]);
        assert_eq!(CellMsg { kind: 99, ..m }.kind(), None);
        for k in [1, 2, 3, 4, 5, 6, 7, 8, 9] {
            assert_eq!(CellKind::from_wire(k).map(|k| k as u32), Some(k));
        }
        assert_eq!(CellKind::from_wire(0), None);
    }
}
