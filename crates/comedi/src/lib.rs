//! A small binding to the Linux comedi user-space API — `repr(C)` structs and ioctl numbers
//! checked against the kernel's header, no C library — and what QMARC needs of the Sensoray
//! 626's `s626` driver: its subdevices and codes ([`s626`]) and a fake of it ([`fake`]) that
//! follows the driver's rules, so the 626 backend is tested without the card.
//!
//! An instruction list is built once and run again and again, one ioctl each time:
//!
//! ```
//! use qmarc_comedi::fake::FakeS626;
//! use qmarc_comedi::list::{Insn, InsnList};
//! use qmarc_comedi::s626::{SUBDEV_AO, SUBDEV_COUNTER, dac_sample};
//! use qmarc_comedi::uapi::{INSN_READ, INSN_WRITE};
//! use qmarc_comedi::Transport;
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let mut card = FakeS626::new(); // or qmarc_comedi::Comedi::open("/dev/comedi0".as_ref())?
//! let mut list = InsnList::new(&[
//!     Insn::one(INSN_READ, SUBDEV_COUNTER, 0),
//!     Insn::one(INSN_WRITE, SUBDEV_AO, 0),
//! ]);
//! list.data_mut(1)[0] = dac_sample(0); // exactly 0 V
//! assert_eq!(card.run(&mut list)?, 2);
//! assert_eq!(card.dac_volts(0), 0.0);
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

pub mod device;
pub mod fake;
pub mod list;
pub mod s626;
pub mod uapi;

pub use device::{Comedi, ComediOpenError, DevInfo, SubdInfo, Transport};
