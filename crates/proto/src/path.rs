//! The path service of a serving controller: `qmarc/path`, an iceoryx2 request/response
//! service beside `qmarc/command` whose request is a whole timed path, [`PathRequest`]: up to
//! [`MAX_PATH_KNOTS`] knots of time from the start, position and (optionally) velocity per
//! motor — what a ROS 2 `JointTrajectory` is. The controller checks it as it checks a PVT knot
//! file (times rising, finite numbers, the motors' limits, the soft limits) and answers with a
//! [`CommandResponse`], accepted or refused with the reason; an accepted path is followed from
//! where the robot rests, through the same cubic segments as a PVT file
//! ([`CommandClient::send_path`](crate::command::CommandClient::send_path) sends one).
//!
//! The request is fixed-size (74 KiB): one copy into shared memory, no allocation on either
//! side's wire.

use crate::MAX_MOTORS;
use crate::command::{CommandResponse, MAX_COMMAND_CLIENTS};
use crate::service::ServiceError;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::request_response;

/// Name of the request/response service.
pub const PATH_SERVICE: &str = "qmarc/path";
/// Most knots a path request carries.
pub const MAX_PATH_KNOTS: usize = 1024;

/// One knot of a path.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[repr(C)]
pub struct PathKnot {
    /// Time from the path's start (where the robot rests, at rest), s.
    pub t_s: f64,
    /// Position per motor, counts.
    pub pos: [f64; MAX_MOTORS],
    /// Velocity per motor, counts/s (with [`PathRequest::VELOCITIES`]; else ignored).
    pub vel: [f64; MAX_MOTORS],
}

/// A timed path for the loop to follow from where the robot rests.
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[type_name("qmarc.PathRequest.v1")]
#[repr(C)]
pub struct PathRequest {
    /// The client's number for it, echoed in the response.
    pub id: u64,
    /// Knots used, 1‥[`MAX_PATH_KNOTS`].
    pub n_knots: u32,
    /// [`PathRequest::VELOCITIES`].
    pub flags: u32,
    /// The knots; those past `n_knots` are ignored.
    pub knots: [PathKnot; MAX_PATH_KNOTS],
}

impl Default for PathRequest {
    fn default() -> PathRequest {
        PathRequest { id: 0, n_knots: 0, flags: 0, knots: [PathKnot::default(); MAX_PATH_KNOTS] }
    }
}

impl PathRequest {
    /// The knots' velocities are given (else the controller chooses them: see
    /// `qmarc_plugins::path`).
    pub const VELOCITIES: u32 = 1;

    /// First a jerk-limited move from where the robot rests to the first knot (the run's
    /// `--approach`), then the path from there: its first knot need not be where the robot
    /// rests.
    pub const APPROACH: u32 = 2;

    /// The request of `knots`, with their velocities if `velocities`; `None` for more than
    /// [`MAX_PATH_KNOTS`].
    pub fn new(knots: &[PathKnot], velocities: bool) -> Option<Box<PathRequest>> {
        if knots.len() > MAX_PATH_KNOTS {
            return None;
        }
        let mut r = Box::<PathRequest>::default();
        r.knots[..knots.len()].copy_from_slice(knots);
        r.n_knots = knots.len() as u32;
        r.flags = if velocities { PathRequest::VELOCITIES } else { 0 };
        Some(r)
    }

    /// The knots used (at most [`MAX_PATH_KNOTS`], whatever `n_knots` says).
    pub fn knots(&self) -> &[PathKnot] {
        &self.knots[..(self.n_knots as usize).min(MAX_PATH_KNOTS)]
    }

    /// The knots' velocities are given.
    pub fn has_velocities(&self) -> bool {
        self.flags & PathRequest::VELOCITIES != 0
    }

    /// The path is approached from where the robot rests ([`PathRequest::APPROACH`]).
    pub fn approached(&self) -> bool {
        self.flags & PathRequest::APPROACH != 0
    }
}

/// The path service.
pub type PathService =
    request_response::PortFactory<ipc::Service, PathRequest, (), CommandResponse, ()>;

/// The path service with the QoS both sides use: created by the server (`create`), only
/// opened by a client. Its requests wake the server through the command service's event.
pub fn open_path_service(
    node: &Node<ipc::Service>,
    create: bool,
) -> Result<PathService, ServiceError> {
    let name = ServiceName::new(PATH_SERVICE)
        .map_err(|e| ServiceError::new("service name", PATH_SERVICE, e))?;
    let builder = node
        .service_builder(&name)
        .request_response::<PathRequest, CommandResponse>()
        .max_clients(MAX_COMMAND_CLIENTS)
        .max_servers(1)
        .max_active_requests_per_client(1)
        .max_response_buffer_size(1);
    let err = |e: &dyn std::fmt::Debug| ServiceError::new("service", PATH_SERVICE, e);
    if create {
        builder.open_or_create().map_err(|e| err(&e))
    } else {
        builder.open().map_err(|e| err(&e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_request_carries_its_knots_and_no_more() {
        let k = PathKnot { t_s: 0.5, pos: [1.0, 2.0, 3.0, 0.0], vel: [0.0; MAX_MOTORS] };
        let r = PathRequest::new(&[k, k], true).unwrap();
        assert_eq!((r.knots().len(), r.has_velocities()), (2, true));
        assert!(!PathRequest::new(&[k], false).unwrap().has_velocities());
        assert!(PathRequest::new(&vec![k; MAX_PATH_KNOTS + 1], false).is_none());
        let lying = PathRequest { n_knots: u32::MAX, ..PathRequest::default() };
        assert_eq!(lying.knots().len(), MAX_PATH_KNOTS, "a count past the array is cut");
        assert_eq!(std::mem::size_of::<PathRequest>(), 16 + MAX_PATH_KNOTS * 72);
    }
}
