//! A ROS 2 payload: the CDR encapsulation header, then the message in OMG CDR
//! (`cdr-encoding`'s serde), as rmw_zenoh and rosbag2's MCAP storage carry it.

use serde::Serialize;
use serde::de::DeserializeOwned;

/// The CDR encapsulation header of a little-endian payload.
pub const CDR_LE: [u8; 4] = [0, 1, 0, 0];

/// Largest payload is decoded, bytes: nothing larger from the network is read.
pub const MAX_PAYLOAD_BYTES: usize = 1 << 20;

/// `value` as a ROS 2 payload: the header, then its CDR.
pub fn to_cdr<T: Serialize>(value: &T) -> Result<Vec<u8>, cdr_encoding::Error> {
    let body = cdr_encoding::to_vec::<T, byteorder::LittleEndian>(value)?;
    let mut out = Vec::with_capacity(4 + body.len());
    out.extend_from_slice(&CDR_LE);
    out.extend_from_slice(&body);
    Ok(out)
}

/// A payload that is not one is read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PayloadError {
    /// Too big.
    #[error("{0} bytes, more than the {MAX_PAYLOAD_BYTES} taken")]
    TooBig(usize),
    /// Not CDR with a little- or big-endian header.
    #[error("no CDR encapsulation header")]
    NoHeader,
    /// The CDR does not decode to the type.
    #[error("not a {0}: {1}")]
    Malformed(&'static str, String),
}

/// A ROS 2 payload of type `T` (named `what` in errors), checked: bounded, with its header,
/// fully decoded.
pub fn from_cdr<T: DeserializeOwned>(bytes: &[u8], what: &'static str) -> Result<T, PayloadError> {
    if bytes.len() > MAX_PAYLOAD_BYTES {
        return Err(PayloadError::TooBig(bytes.len()));
    }
    let (header, body) = bytes.split_at_checked(4).ok_or(PayloadError::NoHeader)?;
    let malformed = |e: cdr_encoding::Error| PayloadError::Malformed(what, e.to_string());
    match header {
        [0, 1, _, _] => cdr_encoding::from_bytes::<T, byteorder::LittleEndian>(body)
            .map(|v| v.0)
            .map_err(malformed),
        [0, 0, _, _] => cdr_encoding::from_bytes::<T, byteorder::BigEndian>(body)
            .map(|v| v.0)
            .map_err(malformed),
        _ => Err(PayloadError::NoHeader),
    }
}
