//! [`Status`], the hwserver's status word: one bit per thing that went wrong.

use crate::MAX_MOTORS;

/// Status bits of a response (thesis `iStatus`). Zero means all is well.
///
/// Limit-switch bits are per motor and side, encoder-overflow bits per motor; the rest are
/// server-wide. Limit bits latch while safety monitoring is on until a
/// [`crate::MsgType::ClearSafetyStatus`].
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Status(pub u32);

impl Status {
    /// No bit set.
    pub const OK: Status = Status(0);
    /// Mask of every limit-switch bit (bits 0‥7: motor m top = 2m, bottom = 2m + 1).
    pub const LIMIT_MASK: Status = Status(0xff);
    /// Mask of every encoder-overflow bit (bits 8‥11, one per motor).
    pub const ENCODER_MASK: Status = Status(0xf00);
    /// The request's type was not one of the twelve; nothing was done.
    pub const UNKNOWN_MESSAGE: Status = Status(1 << 16);
    /// The request named a motor the server does not drive; nothing was done.
    pub const BAD_MOTOR: Status = Status(1 << 17);
    /// The server's watchdog fired (the controller was silent while motors were enabled): all
    /// motors were disabled.
    pub const WATCHDOG: Status = Status(1 << 18);
    /// The hardware reported an error (a short or failed I/O operation).
    pub const HARDWARE_FAULT: Status = Status(1 << 19);
    /// The server was asked to stop (SIGTERM/SIGINT): motors are disabled and stay disabled.
    pub const SHUTDOWN: Status = Status(1 << 20);
    /// The emergency-stop chain opened (the button pressed, or a broken wire): every motor was
    /// disabled in the read that saw it. Latched until a [`crate::MsgType::ClearSafetyStatus`]
    /// finds the chain closed again; enabling is refused meanwhile.
    pub const ESTOP: Status = Status(1 << 21);
    /// A preset homed the frame, but it could not be kept where the hardware keeps it between
    /// runs (the simulator's state file, the card's state folder): the next run would find
    /// the robot unhomed, so the homing failed. The hwserver says where and why.
    pub const NOT_KEPT: Status = Status(1 << 22);
    /// A [`crate::MsgType::WriteDigitalOutputs`] was refused and nothing written: its mask
    /// held a channel the server keeps for itself (an amplifier enable, the charge pump, a
    /// reserved channel, an input, or one the card does not have), or the outputs may not
    /// change now (the emergency stop, a fault that ends the server).
    pub const PROTECTED_OUTPUT: Status = Status(1 << 23);

    /// Bit of motor `motor`'s top limit switch.
    #[inline]
    pub const fn limit_top(motor: usize) -> Status {
        Status(1 << (2 * motor))
    }

    /// Bit of motor `motor`'s bottom limit switch.
    #[inline]
    pub const fn limit_bottom(motor: usize) -> Status {
        Status(1 << (2 * motor + 1))
    }

    /// Bit of motor `motor`'s encoder overflow (a counter step too large to unwrap).
    #[inline]
    pub const fn encoder_overflow(motor: usize) -> Status {
        Status(1 << (8 + motor))
    }

    /// True if no bit is set.
    #[inline]
    pub const fn is_ok(self) -> bool {
        self.0 == 0
    }

    /// True if every bit of `other` is set in `self`.
    #[inline]
    pub const fn contains(self, other: Status) -> bool {
        self.0 & other.0 == other.0
    }

    /// True if any bit of `other` is set in `self`.
    #[inline]
    pub const fn intersects(self, other: Status) -> bool {
        self.0 & other.0 != 0
    }

    /// The first (lowest) motor with a limit bit set, and whether it is the top switch.
    #[inline]
    pub fn first_limit(self) -> Option<(usize, bool)> {
        (0..MAX_MOTORS).find_map(|m| {
            if self.contains(Status::limit_top(m)) {
                Some((m, true))
            } else if self.contains(Status::limit_bottom(m)) {
                Some((m, false))
            } else {
                None
            }
        })
    }

    /// The first (lowest) motor with an encoder-overflow bit set.
    #[inline]
    pub fn first_encoder_overflow(self) -> Option<usize> {
        (0..MAX_MOTORS).find(|&m| self.contains(Status::encoder_overflow(m)))
    }
}

impl core::ops::BitOr for Status {
    type Output = Status;
    #[inline]
    fn bitor(self, rhs: Status) -> Status {
        Status(self.0 | rhs.0)
    }
}

impl core::ops::BitOrAssign for Status {
    #[inline]
    fn bitor_assign(&mut self, rhs: Status) {
        self.0 |= rhs.0;
    }
}

impl core::ops::BitAnd for Status {
    type Output = Status;
    #[inline]
    fn bitand(self, rhs: Status) -> Status {
        Status(self.0 & rhs.0)
    }
}

impl core::ops::Not for Status {
    type Output = Status;
    #[inline]
    fn not(self) -> Status {
        Status(!self.0)
    }
}

/// Lists every set bit by name ("motor 1 top limit switch, watchdog"), motors 1-based as
/// users count them; "ok" when none is set.
impl std::fmt::Display for Status {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.is_ok() {
            return f.write_str("ok");
        }
        let mut first = true;
        let mut item = |f: &mut std::fmt::Formatter<'_>, args: std::fmt::Arguments<'_>| {
            let sep = if first { "" } else { ", " };
            first = false;
            write!(f, "{sep}{args}")
        };
        for m in 0..MAX_MOTORS {
            if self.contains(Status::limit_top(m)) {
                item(f, format_args!("motor {} top limit switch", m + 1))?;
            }
            if self.contains(Status::limit_bottom(m)) {
                item(f, format_args!("motor {} bottom limit switch", m + 1))?;
            }
        }
        for m in 0..MAX_MOTORS {
            if self.contains(Status::encoder_overflow(m)) {
                item(f, format_args!("motor {} encoder overflow", m + 1))?;
            }
        }
        let named = [
            (Status::UNKNOWN_MESSAGE, "unknown message type"),
            (Status::BAD_MOTOR, "no such motor"),
            (Status::WATCHDOG, "watchdog"),
            (Status::HARDWARE_FAULT, "hardware fault"),
            (Status::SHUTDOWN, "server shutting down"),
            (Status::ESTOP, "emergency stop"),
            (Status::NOT_KEPT, "homed frame not kept"),
            (Status::PROTECTED_OUTPUT, "digital output refused"),
        ];
        for (bit, name) in named {
            if self.contains(bit) {
                item(f, format_args!("{name}"))?;
            }
        }
        let known = Status::LIMIT_MASK.0
            | Status::ENCODER_MASK.0
            | named.iter().fold(0, |acc, (b, _)| acc | b.0);
        if self.0 & !known != 0 {
            item(f, format_args!("unknown status bits {:#x}", self.0 & !known))?;
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(status: Status, expected: &str) {
        assert_eq!(status.to_string(), expected);
    }

    #[test]
    fn bits_are_named() {
        check(Status::OK, "ok");
        check(Status::limit_top(0), "motor 1 top limit switch");
        check(Status::limit_bottom(2), "motor 3 bottom limit switch");
        check(Status::encoder_overflow(3), "motor 4 encoder overflow");
        check(Status::WATCHDOG | Status::limit_bottom(1), "motor 2 bottom limit switch, watchdog");
        check(Status(1 << 30), "unknown status bits 0x40000000");
    }

    #[test]
    fn bits_do_not_overlap() {
        let mut seen = 0u32;
        let all = (0..MAX_MOTORS)
            .flat_map(|m| {
                [Status::limit_top(m), Status::limit_bottom(m), Status::encoder_overflow(m)]
            })
            .chain([
                Status::UNKNOWN_MESSAGE,
                Status::BAD_MOTOR,
                Status::WATCHDOG,
                Status::HARDWARE_FAULT,
                Status::SHUTDOWN,
                Status::ESTOP,
                Status::NOT_KEPT,
                Status::PROTECTED_OUTPUT,
            ]);
        for s in all {
            assert_eq!(s.0.count_ones(), 1);
            assert_eq!(seen & s.0, 0, "{s} overlaps");
            seen |= s.0;
        }
        assert!(Status::LIMIT_MASK.contains(Status::limit_bottom(MAX_MOTORS - 1)));
        assert!(Status::ENCODER_MASK.contains(Status::encoder_overflow(MAX_MOTORS - 1)));
    }

    #[test]
    fn first_limit_finds_the_lowest_motor() {
        assert_eq!(Status::OK.first_limit(), None);
        assert_eq!(
            (Status::limit_bottom(2) | Status::limit_top(3)).first_limit(),
            Some((2, false))
        );
        assert_eq!(Status::limit_top(1).first_limit(), Some((1, true)));
        assert_eq!(Status::encoder_overflow(2).first_encoder_overflow(), Some(2));
    }
}
