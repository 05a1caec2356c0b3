//! The part of the comedi user-space API (`linux/comedi.h`) QMARC uses: the instruction and
//! information structs, the instruction types, the chanspec packing and the ioctl numbers,
//! with the ioctl calls themselves. Transcribed for x86_64 and aarch64 (LP64); the crate's tests
//! compile a C probe against the installed header and compare every size, offset and number.

use std::ffi::c_char;

/// Length of the driver and board names in [`ComediDevinfo`] (`COMEDI_NAMELEN`).
pub const COMEDI_NAMELEN: usize = 20;

/// Instruction type bit: the instruction writes.
pub const INSN_MASK_WRITE: u32 = 0x0800_0000;
/// Instruction type bit: the instruction reads.
pub const INSN_MASK_READ: u32 = 0x0400_0000;
/// Reads `n` samples of one channel into `data`.
pub const INSN_READ: u32 = INSN_MASK_READ;
/// Writes `n` samples of `data` to one channel.
pub const INSN_WRITE: u32 = 1 | INSN_MASK_WRITE;
/// Digital I/O: `data[0]` is a mask of the channels to write, `data[1]` their new state;
/// `data[1]` comes back with the state of every channel.
pub const INSN_BITS: u32 = 2 | INSN_MASK_READ | INSN_MASK_WRITE;
/// Configures a channel (`data[0]` is the configuration ID). Never used on the 626's DIO.
pub const INSN_CONFIG: u32 = 3 | INSN_MASK_READ | INSN_MASK_WRITE;

/// Analog reference: ground.
pub const AREF_GROUND: u32 = 0;

/// Subdevice type: analog input (`COMEDI_SUBD_AI`).
pub const SUBD_AI: u32 = 1;
/// Subdevice type: analog output.
pub const SUBD_AO: u32 = 2;
/// Subdevice type: digital input/output.
pub const SUBD_DIO: u32 = 5;
/// Subdevice type: counter.
pub const SUBD_COUNTER: u32 = 6;

/// `CR_PACK(chan, rng, aref)`: the chanspec of channel `chan`, range index `range` and analog
/// reference `aref`.
pub const fn cr_pack(chan: u32, range: u32, aref: u32) -> u32 {
    ((aref & 0x3) << 24) | ((range & 0xff) << 16) | chan
}

/// `struct comedi_insn`: one instruction.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct ComediInsn {
    /// `INSN_*`.
    pub insn: u32,
    /// Length of `data`.
    pub n: u32,
    /// The samples the instruction reads or writes.
    pub data: *mut u32,
    /// Subdevice index.
    pub subdev: u32,
    /// [`cr_pack`] of the channel.
    pub chanspec: u32,
    /// Reserved.
    pub unused: [u32; 3],
}

/// `struct comedi_insnlist`: instructions run in order by one `COMEDI_INSNLIST` ioctl.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct ComediInsnlist {
    /// Number of instructions.
    pub n_insns: u32,
    /// The instructions.
    pub insns: *mut ComediInsn,
}

/// `struct comedi_devinfo`: what `COMEDI_DEVINFO` returns.
#[repr(C)]
#[derive(Debug, Clone, Copy)]
pub struct ComediDevinfo {
    /// Comedi's version.
    pub version_code: u32,
    /// Number of subdevices.
    pub n_subdevs: u32,
    /// NUL-terminated driver name (`s626`).
    pub driver_name: [c_char; COMEDI_NAMELEN],
    /// NUL-terminated board name.
    pub board_name: [c_char; COMEDI_NAMELEN],
    /// Index of the read subdevice, −1 if none.
    pub read_subdevice: i32,
    /// Index of the write subdevice, −1 if none.
    pub write_subdevice: i32,
    /// Reserved.
    pub unused: [i32; 30],
}

/// `struct comedi_subdinfo`: one element of what `COMEDI_SUBDINFO` returns.
#[repr(C)]
#[derive(Debug, Clone, Copy, Default)]
pub struct ComediSubdinfo {
    /// `SUBD_*`.
    pub kind: u32,
    /// Number of channels.
    pub n_chan: u32,
    /// `SDF_*` flags.
    pub subd_flags: u32,
    /// Always 5.
    pub timer_type: u32,
    /// Longest channel list of an asynchronous command.
    pub len_chanlist: u32,
    /// Largest sample value.
    pub maxdata: u32,
    /// Channel flags.
    pub flags: u32,
    /// Range type.
    pub range_type: u32,
    /// Unused.
    pub settling_time_0: u32,
    /// Whether `INSN_BITS` is supported.
    pub insn_bits_support: u32,
    /// Reserved.
    pub unused: [u32; 8],
}

const _: () = assert!(std::mem::size_of::<ComediInsn>() == 40);
const _: () = assert!(std::mem::size_of::<ComediInsnlist>() == 16);
const _: () = assert!(std::mem::size_of::<ComediDevinfo>() == 176);
const _: () = assert!(std::mem::size_of::<ComediSubdinfo>() == 72);

/// The ioctl type of comedi (`CIO`).
const CIO: u8 = b'd';

/// `COMEDI_DEVINFO` = `_IOR('d', 1, struct comedi_devinfo)`.
pub const COMEDI_DEVINFO: u64 =
    nix::request_code_read!(CIO, 1, std::mem::size_of::<ComediDevinfo>()) as u64;
/// `COMEDI_SUBDINFO` = `_IOR('d', 2, struct comedi_subdinfo)`.
pub const COMEDI_SUBDINFO: u64 =
    nix::request_code_read!(CIO, 2, std::mem::size_of::<ComediSubdinfo>()) as u64;
/// `COMEDI_LOCK` = `_IO('d', 5)`; the argument is the subdevice.
#[allow(clippy::unnecessary_cast)] // nix's ioctl number type is u64 on glibc, i32 on musl
pub const COMEDI_LOCK: u64 = nix::request_code_none!(CIO, 5) as u64;
/// `COMEDI_UNLOCK` = `_IO('d', 6)`.
#[allow(clippy::unnecessary_cast)] // as above
pub const COMEDI_UNLOCK: u64 = nix::request_code_none!(CIO, 6) as u64;
/// `COMEDI_INSNLIST` = `_IOR('d', 11, struct comedi_insnlist)`.
pub const COMEDI_INSNLIST: u64 =
    nix::request_code_read!(CIO, 11, std::mem::size_of::<ComediInsnlist>()) as u64;
/// `COMEDI_INSN` = `_IOR('d', 12, struct comedi_insn)`.
pub const COMEDI_INSN: u64 =
    nix::request_code_read!(CIO, 12, std::mem::size_of::<ComediInsn>()) as u64;

/// The ioctl calls (nix's wrappers over `libc::ioctl`; each is `unsafe`: the caller passes a
/// valid pointer).
pub mod ioctl {
    use super::{CIO, ComediDevinfo, ComediInsnlist, ComediSubdinfo};
    nix::ioctl_read!(
        /// `COMEDI_DEVINFO`.
        devinfo,
        CIO,
        1,
        ComediDevinfo
    );
    nix::ioctl_read!(
        /// `COMEDI_SUBDINFO`: `data` points to one element per subdevice.
        subdinfo,
        CIO,
        2,
        ComediSubdinfo
    );
    nix::ioctl_write_int_bad!(
        /// `COMEDI_LOCK` of the subdevice given as the argument.
        lock,
        nix::request_code_none!(CIO, 5)
    );
    nix::ioctl_read!(
        /// `COMEDI_INSNLIST`: returns how many instructions completed.
        insnlist,
        CIO,
        11,
        ComediInsnlist
    );
}
