//! [`HwMsg`], the one message type of the controller ⇄ hwserver protocol, and [`MsgType`].

use crate::{MAX_MOTORS, Status};
use iceoryx2::prelude::ZeroCopySend;

/// The twelve requests of thesis section 3.6, with their wire values, and the thirteenth its
/// section 6.2.2 asks for (the digital outputs of a gripper).
///
/// Single-motor requests name their motor in [`HwMsg::motor`]; all-motor requests use the
/// arrays. The numbering follows the thesis' list (1 = read all encoders … 12 = exit).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[repr(u32)]
pub enum MsgType {
    /// Thesis message 1: Read every motor's encoder; the response carries the 64-bit software
    /// positions in `data` (counts), the latched status, and per motor in `aux` the
    /// [`MotorFlags`] (switches as they are now, enabled, homed).
    ReadAllEncoders = 1,
    /// Thesis message 2: Write every motor's DAC from `aux` (codes, ±[`crate::DAC_MAX`]).
    WriteAllDacs = 2,
    /// Thesis message 3: Read the encoder of motor `motor` into `data[motor]`.
    ReadEncoder = 3,
    /// Thesis message 4: Write `aux[motor]` to the DAC of motor `motor`.
    WriteDac = 4,
    /// Thesis message 5: Enable the amplifier of motor `motor`.
    EnableMotor = 5,
    /// Thesis message 6: Disable the amplifier of motor `motor` (its DAC goes to 0 V first).
    DisableMotor = 6,
    /// Thesis message 7: Zero every DAC and disable every amplifier.
    DisableAll = 7,
    /// Thesis message 8: Reset the encoder "zero" of motor `motor` (or [`HwMsg::ALL_MOTORS`]):
    /// its software position becomes `data[m]` (whole counts; 0 is the thesis' reset) and
    /// its hardware counter [`crate::COUNTER_ZERO`] plus that. The frame is then homed.
    ResetEncoderZero = 8,
    /// Thesis message 9: Start watching the limit switches (a trip latches a status bit and stops watching).
    EnableSafety = 9,
    /// Thesis message 10: Stop watching the limit switches.
    DisableSafety = 10,
    /// Thesis message 11: Clear the latched safety status bits.
    ClearSafetyStatus = 11,
    /// Thesis message 12: Put the hardware in the safe state, answer, and exit the server.
    Exit = 12,
    /// Message 13 (thesis 6.2.2, a gripper on a free digital output): set the outputs of mask
    /// `aux[0]` (bit c: DIO channel c of the card's first bank) to the bits of `aux[1]`. A
    /// mask holding a channel the server keeps for itself (an amplifier enable, the charge
    /// pump, a reserved channel, an input) is refused with [`Status::PROTECTED_OUTPUT`] and
    /// nothing is written; while the emergency stop or a fault that ends the server holds, it
    /// is refused with that status. Build it with [`HwMsg::write_outputs`].
    WriteDigitalOutputs = 13,
}

impl MsgType {
    /// Every message type, in wire order.
    pub const ALL: [MsgType; 13] = [
        MsgType::ReadAllEncoders,
        MsgType::WriteAllDacs,
        MsgType::ReadEncoder,
        MsgType::WriteDac,
        MsgType::EnableMotor,
        MsgType::DisableMotor,
        MsgType::DisableAll,
        MsgType::ResetEncoderZero,
        MsgType::EnableSafety,
        MsgType::DisableSafety,
        MsgType::ClearSafetyStatus,
        MsgType::Exit,
        MsgType::WriteDigitalOutputs,
    ];

    /// Decodes a wire value; `None` for anything that is not one of the thirteen.
    #[inline]
    pub fn from_raw(raw: u32) -> Option<MsgType> {
        match raw {
            1..=13 => Some(Self::ALL[raw as usize - 1]),
            _ => None,
        }
    }
}

/// What a read response says about one motor, in `aux[motor]`: the limit switches as they
/// are *now* (not latched: homing needs to see a switch clear), whether its amplifier is
/// enabled and whether its counter frame is homed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct MotorFlags(pub i32);

impl MotorFlags {
    /// The top limit switch is active.
    pub const TOP: i32 = 1;
    /// The bottom limit switch is active.
    pub const BOTTOM: i32 = 2;
    /// The amplifier is enabled.
    pub const ENABLED: i32 = 4;
    /// The counter frame was set by homing (or survives from it).
    pub const HOMED: i32 = 8;

    /// The top switch is active.
    #[inline]
    pub fn top(self) -> bool {
        self.0 & Self::TOP != 0
    }

    /// The bottom switch is active.
    #[inline]
    pub fn bottom(self) -> bool {
        self.0 & Self::BOTTOM != 0
    }

    /// The amplifier is enabled.
    #[inline]
    pub fn enabled(self) -> bool {
        self.0 & Self::ENABLED != 0
    }

    /// The frame is homed.
    #[inline]
    pub fn homed(self) -> bool {
        self.0 & Self::HOMED != 0
    }
}

/// The gripper as a read response reports it ([`HwMsg::gripper`]): whether it is told to
/// close, and whether it is sensed (or, without a sensor, timed) fully open or fully closed.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Gripper(pub u32);

impl Gripper {
    /// Its output is on: it is told to close.
    pub const CLOSE: u32 = 1;
    /// It is fully open.
    pub const OPEN: u32 = 2;
    /// It is fully closed.
    pub const CLOSED: u32 = 4;
    /// No gripper is wired: nothing else is set.
    pub const ABSENT: u32 = 8;

    /// Told to close.
    #[inline]
    pub fn told_to_close(self) -> bool {
        self.0 & Self::CLOSE != 0
    }

    /// It is where it was told to be (fully closed when told to close, else fully open).
    #[inline]
    pub fn arrived(self) -> bool {
        let want = if self.told_to_close() { Self::CLOSED } else { Self::OPEN };
        self.0 & want != 0
    }

    /// Told to close (`close`) or to open, and there: fully closed, or fully open.
    #[inline]
    pub fn reached(self, close: bool) -> bool {
        self.told_to_close() == close && self.arrived()
    }

    /// The state as gather.csv's `grip` column writes it: 0 open, 1 closing, 2 closed,
    /// 3 opening (−1: no gripper).
    #[inline]
    pub fn code(self) -> i8 {
        match (self.0 & Self::ABSENT != 0, self.told_to_close(), self.arrived()) {
            (true, _, _) => -1,
            (false, false, true) => 0,
            (false, true, false) => 1,
            (false, true, true) => 2,
            (false, false, false) => 3,
        }
    }

    /// The state's name: `open`, `closing`, `closed`, `opening` or `none`.
    pub fn name(self) -> &'static str {
        ["none", "open", "closing", "closed", "opening"][(self.code() + 1) as usize]
    }
}

/// A wire value that is not a [`MsgType`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct UnknownMsgType(pub u32);

impl std::fmt::Display for UnknownMsgType {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "unknown message type {}", self.0)
    }
}

impl std::error::Error for UnknownMsgType {}

/// The request and the response between controller and hwserver (thesis `ClientMessageT`).
///
/// Plain old data: fixed arrays, no pointers, the same layout in both processes. A response
/// echoes `msg_type`, `seq` and `motor` of its request.
#[derive(Debug, Clone, Copy, Default, PartialEq, ZeroCopySend)]
#[type_name("qmarc.HwMsg.v3")]
#[repr(C)]
#[doc(alias = "ClientMessageT")]
pub struct HwMsg {
    /// A [`MsgType`] wire value (`iMsgType`). Kept raw so that an unknown value reaches the
    /// server and is answered with [`Status::UNKNOWN_MESSAGE`] instead of failing to decode.
    pub msg_type: u32,
    /// Sequence number set by the client; the response carries the same one.
    pub seq: u32,
    /// Status word of the server ([`Status`] bits, `iStatus`); 0 in requests.
    pub status: u32,
    /// Motor index (0-based) of single-motor requests, or [`HwMsg::ALL_MOTORS`].
    pub motor: u32,
    /// Server timestamp of the response in ns on the server's clock (the simulated clock in
    /// deterministic mode); 0 in requests.
    pub time_ns: u64,
    /// Per-motor floating-point data (`fMsgData`): software positions in counts.
    pub data: [f64; MAX_MOTORS],
    /// Per-motor integer data (`iInitData`): DAC codes.
    pub aux: [i32; MAX_MOTORS],
    /// In read responses: the digital outputs message 13 has set (bit c: DIO channel c of
    /// the first bank; the server's own channels are not shown); 0 in requests.
    pub outputs: u32,
    /// In read responses: the gripper as the server knows it ([`Gripper`] bits); 0 in
    /// requests.
    pub gripper: u32,
    /// In read responses: the belt encoder's position in counts (the conveyor's counter read
    /// in the same exchange as the motors', widened to 64 bits like theirs; 0 where no belt
    /// is read); 0 in requests.
    pub belt: i64,
}

const _: () = assert!(core::mem::size_of::<HwMsg>() == 88);
const _: () = assert!(core::mem::align_of::<HwMsg>() == 8);

impl HwMsg {
    /// The `motor` value that means every motor.
    pub const ALL_MOTORS: u32 = u32::MAX;

    /// A request of type `t` with every other field zero.
    #[inline]
    pub fn request(t: MsgType) -> HwMsg {
        HwMsg { msg_type: t as u32, ..HwMsg::default() }
    }

    /// A single-motor request of type `t` for motor index `motor`.
    #[inline]
    pub fn for_motor(t: MsgType, motor: u32) -> HwMsg {
        HwMsg { motor, ..HwMsg::request(t) }
    }

    /// The read-all-encoders request of every servo cycle.
    #[inline]
    pub fn read_all_encoders() -> HwMsg {
        HwMsg::request(MsgType::ReadAllEncoders)
    }

    /// The write-all-DACs request of every servo cycle.
    #[inline]
    pub fn write_all_dacs(codes: &[i32; MAX_MOTORS]) -> HwMsg {
        HwMsg { aux: *codes, ..HwMsg::request(MsgType::WriteAllDacs) }
    }

    /// Message 13: the outputs of `mask` to the bits of `values` (bit c: DIO channel c).
    #[inline]
    pub fn write_outputs(mask: u32, values: u32) -> HwMsg {
        let mut m = HwMsg::request(MsgType::WriteDigitalOutputs);
        m.aux[0] = mask as i32;
        m.aux[1] = (values & mask) as i32;
        m
    }

    /// Decodes [`HwMsg::msg_type`].
    #[inline]
    pub fn msg_type(&self) -> Result<MsgType, UnknownMsgType> {
        MsgType::from_raw(self.msg_type).ok_or(UnknownMsgType(self.msg_type))
    }

    /// The status word as [`Status`].
    #[inline]
    pub fn status(&self) -> Status {
        Status(self.status)
    }

    /// The answer to `self`: same type, sequence number and motor, everything else zero.
    #[inline]
    pub fn response(&self) -> HwMsg {
        HwMsg { msg_type: self.msg_type, seq: self.seq, motor: self.motor, ..HwMsg::default() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn every_type_round_trips_through_its_wire_value() {
        for (i, t) in MsgType::ALL.iter().enumerate() {
            assert_eq!(*t as u32, i as u32 + 1);
            assert_eq!(MsgType::from_raw(*t as u32), Some(*t));
        }
        for raw in [0, 14, 99, u32::MAX] {
            assert_eq!(MsgType::from_raw(raw), None);
            let m = HwMsg { msg_type: raw, ..HwMsg::default() };
            assert_eq!(m.msg_type(), Err(UnknownMsgType(raw)));
        }
    }

    #[test]
    fn response_echoes_type_sequence_and_motor() {
        let mut req = HwMsg::for_motor(MsgType::EnableMotor, 2);
        req.seq = 77;
        req.data = [1.0; MAX_MOTORS];
        let resp = req.response();
        assert_eq!((resp.msg_type, resp.seq, resp.motor), (5, 77, 2));
        assert_eq!(resp.data, [0.0; MAX_MOTORS]);
    }

    #[test]
    fn an_output_request_carries_only_its_masked_values() {
        let m = HwMsg::write_outputs(1 << 6, 0xffff_ffff);
        assert_eq!(m.msg_type(), Ok(MsgType::WriteDigitalOutputs));
        assert_eq!((m.aux[0], m.aux[1]), (64, 64));
        assert_eq!(HwMsg::write_outputs(1 << 6, 0).aux[1], 0);
        assert_eq!(HwMsg::write_outputs(1 << 31, 1 << 31).aux[0], i32::MIN);
    }

    #[test]
    fn the_gripper_states_have_their_codes_and_names() {
        let g = |bits| Gripper(bits);
        let cases = [
            (g(Gripper::OPEN), 0, "open", true),
            (g(Gripper::CLOSE), 1, "closing", false),
            (g(Gripper::CLOSE | Gripper::OPEN), 1, "closing", false),
            (g(Gripper::CLOSE | Gripper::CLOSED), 2, "closed", true),
            (g(0), 3, "opening", false),
            (g(Gripper::CLOSED), 3, "opening", false),
            (g(Gripper::ABSENT), -1, "none", false),
        ];
        for (state, code, name, arrived) in cases {
            assert_eq!((state.code(), state.name(), state.arrived()), (code, name, arrived));
            let close = state.told_to_close();
            assert_eq!(state.reached(close), arrived, "{name}");
            assert!(!state.reached(!close), "{name}: not where the other order puts it");
        }
    }

    fn to_bytes(m: &HwMsg) -> [u8; 88] {
        // SAFETY: HwMsg is repr(C) plain old data of exactly 88 bytes without padding
        // (4 × u32, u64, 4 × f64, 4 × i32, 2 × u32, i64), so every byte is initialised.
        unsafe { core::mem::transmute_copy(m) }
    }

    fn from_bytes(b: &[u8; 88]) -> HwMsg {
        // SAFETY: every bit pattern is a valid HwMsg (integers and floats only).
        unsafe { core::mem::transmute_copy(b) }
    }

    proptest! {
        #[test]
        fn message_round_trips_through_its_bytes(
            msg_type in any::<u32>(), seq in any::<u32>(), status in any::<u32>(),
            motor in any::<u32>(), time_ns in any::<u64>(),
            data in proptest::array::uniform4(any::<f64>()),
            aux in proptest::array::uniform4(any::<i32>()),
            outputs in any::<u32>(), gripper in any::<u32>(), belt in any::<i64>(),
        ) {
            let m =
                HwMsg { msg_type, seq, status, motor, time_ns, data, aux, outputs, gripper, belt };
            let back = from_bytes(&to_bytes(&m));
            prop_assert_eq!(to_bytes(&back), to_bytes(&m));
            prop_assert_eq!(back.msg_type, msg_type);
            prop_assert_eq!(back.aux, aux);
            prop_assert_eq!(back.belt, belt);
            prop_assert_eq!(back.data.map(f64::to_bits), data.map(f64::to_bits));
        }

        #[test]
        fn counter_delta_inverts_wrapping_add(old in 0u32..(1 << 24), d in -(1i32 << 23)..(1i32 << 23)) {
            let new = (old as i64 + d as i64).rem_euclid(1 << 24) as u32;
            prop_assert_eq!(crate::counter_delta(old, new), d);
        }
    }
}
