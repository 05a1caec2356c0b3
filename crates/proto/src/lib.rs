//! The protocol between `qmarc-controller` (client) and `qmarc-hwserver` (server).
//!
//! QMARC's controller and hardware server exchange one fixed-size message, [`HwMsg`], the Rust
//! form of the thesis' `ClientMessageT` (section 3.3.1): a message type, a per-motor `f64` data
//! array, a per-motor `i32` auxiliary array and a status word. The twelve message types of
//! thesis section 3.6, and the digital outputs its section 6.2.2 asks for, are [`MsgType`]; what went wrong is named by the bits of [`Status`].
//! [`service`] opens the iceoryx2 services both sides use, with identical QoS; [`telemetry`]
//! is the live sample a move publishes for its readers, [`state`] the words of a move on the wire
//! (its phase, the fault that ended it), [`progress`] the page the starter and console read
//! while a move runs and [`gather_page`] the file its gathered rows live in, which outlives a
//! killed controller.
//!
//! ```
//! use qmarc_proto::{HwMsg, MsgType, Status};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut dacs = [0; qmarc_proto::MAX_MOTORS];
//! dacs[0] = 120;
//! let req = HwMsg::write_all_dacs(&dacs);
//! assert_eq!(req.msg_type()?, MsgType::WriteAllDacs);
//! let status = Status::limit_top(0) | Status::UNKNOWN_MESSAGE;
//! assert_eq!(status.to_string(), "motor 1 top limit switch, unknown message type");
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod camera;
pub mod cell;
pub mod exit;
pub mod gather_page;
pub mod link;
pub mod msg;
pub mod progress;
pub mod service;
pub mod state;
pub mod status;
pub mod telemetry;
pub mod wake;

pub use msg::{Gripper, HwMsg, MotorFlags, MsgType, UnknownMsgType};
pub use status::Status;

/// Most motors one hardware server drives. One Sensoray 626 has four DACs (and six counters),
/// so four is the most one card can serve; every per-motor array in [`HwMsg`] has this length.
pub const MAX_MOTORS: usize = 4;

/// Bits of the hardware quadrature counter (the 626's counters are 24-bit and wrap).
pub const COUNTER_BITS: u32 = 24;

/// Mask of a raw counter value.
pub const COUNTER_MASK: u32 = (1 << COUNTER_BITS) - 1;

/// The raw counter value that means position zero: mid-range, as on the 626 (thesis 3.10.2).
pub const COUNTER_ZERO: u32 = 8_388_608;

/// Largest DAC code magnitude: 14-bit signed, ±8191 ↔ ±10 V.
pub const DAC_MAX: i32 = 8191;

/// Volts at [`DAC_MAX`].
pub const DAC_FULL_SCALE_V: f64 = 10.0;

/// The volts DAC code `code` puts out (±[`DAC_MAX`] ↔ ±[`DAC_FULL_SCALE_V`]).
pub fn dac_volts(code: i32) -> f64 {
    f64::from(code) * DAC_FULL_SCALE_V / f64::from(DAC_MAX)
}

/// Extends a 24-bit counter step to a signed difference: the change from `old` to `new`, valid
/// while the true motion between two reads is below 2²³ counts.
///
/// ```
/// use qmarc_proto::counter_delta;
/// assert_eq!(counter_delta(0xff_fffe, 0x00_0001), 3);
/// assert_eq!(counter_delta(0x00_0001, 0xff_fffe), -3);
/// ```
#[inline]
pub fn counter_delta(old: u32, new: u32) -> i32 {
    ((new.wrapping_sub(old) << (32 - COUNTER_BITS)) as i32) >> (32 - COUNTER_BITS)
}
