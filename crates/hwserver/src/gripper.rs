//! [`GripperModel`]: the gripper on a free digital output (thesis 6.2.2), as the server reports
//! it in every read response ([`qmarc_proto::Gripper`]).
//!
//! The output closes the gripper when on. Without a sensor the server times it: the jaws
//! travel from fully open to fully closed in `s626.gripper_close_s` and back in the same time,
//! at a constant rate from wherever they are when the output changes. This is the simulated
//! robot's gripper, and on the card the time after which the gripper counts as closed or open.

use qmarc_proto::Gripper;

/// The gripper of one server: which output it is on and how far closed it is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GripperModel {
    /// The output's bit (bit c: DIO channel c); 0: no gripper.
    mask: u32,
    /// Travel time from fully open to fully closed, ns (≥ 1).
    travel_ns: u64,
    /// Told to close.
    close: bool,
    /// How far closed it was when the output last changed, 0 (open) ‥ 1 (closed).
    from: f64,
    /// When the output last changed, ns of the backend's clock.
    since_ns: u64,
}

impl GripperModel {
    /// No gripper: every state reads [`Gripper::ABSENT`].
    pub const NONE: GripperModel =
        GripperModel { mask: 0, travel_ns: 1, close: false, from: 0.0, since_ns: 0 };

    /// A gripper on output bit `mask` whose jaws travel in `travel_s`, at rest as `outputs`
    /// (the pins read when the server starts) leave it: fully closed if its output is on.
    pub fn new(mask: u32, travel_s: f64, outputs: u32) -> GripperModel {
        let close = outputs & mask != 0;
        GripperModel {
            mask,
            travel_ns: ((travel_s * 1e9).round() as u64).max(1),
            close,
            from: if close { 1.0 } else { 0.0 },
            since_ns: 0,
        }
    }

    /// How far closed at `now_ns`, 0 ‥ 1.
    fn closedness(&self, now_ns: u64) -> f64 {
        let moved = now_ns.saturating_sub(self.since_ns) as f64 / self.travel_ns as f64;
        if self.close { (self.from + moved).min(1.0) } else { (self.from - moved).max(0.0) }
    }

    /// The outputs are `outputs` from `now_ns` on: the jaws go on from where they are, toward
    /// closed while the gripper's bit is on, else toward open (the ramp taken up again from
    /// its point now is the same ramp when the bit did not change).
    pub fn set(&mut self, outputs: u32, now_ns: u64) {
        self.from = self.closedness(now_ns);
        self.since_ns = now_ns;
        self.close = outputs & self.mask != 0;
    }

    /// The state at `now_ns`.
    pub fn state(&self, now_ns: u64) -> Gripper {
        if self.mask == 0 {
            return Gripper(Gripper::ABSENT);
        }
        let x = self.closedness(now_ns);
        let mut bits = if self.close { Gripper::CLOSE } else { 0 };
        if x <= 0.0 {
            bits |= Gripper::OPEN;
        }
        if x >= 1.0 {
            bits |= Gripper::CLOSED;
        }
        Gripper(bits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MS: u64 = 1_000_000;

    #[test]
    fn it_closes_and_opens_in_its_travel_time() {
        let mut g = GripperModel::new(1 << 6, 0.05, 0);
        assert_eq!(g.state(0).name(), "open");
        g.set(1 << 6, 10 * MS);
        assert_eq!(g.state(10 * MS).name(), "closing");
        assert_eq!(g.state(60 * MS - 1).name(), "closing");
        assert_eq!(g.state(60 * MS).name(), "closed");
        g.set(0, 100 * MS);
        assert_eq!(g.state(100 * MS).name(), "opening");
        assert_eq!(g.state(150 * MS - 1).name(), "opening");
        assert_eq!(g.state(150 * MS).name(), "open");
    }

    #[test]
    fn it_turns_round_where_it_is() {
        let mut g = GripperModel::new(1 << 6, 0.05, 0);
        g.set(1 << 6, 0);
        g.set(0, 20 * MS); // 40 % closed
        assert_eq!(g.state(40 * MS - 1).name(), "opening");
        assert_eq!(g.state(40 * MS).name(), "open");
        // Other bits change nothing; the same bit again does not restart the travel.
        g.set(1 << 6 | 1 << 7, 100 * MS);
        g.set(1 << 6, 120 * MS);
        assert_eq!(g.state(150 * MS).name(), "closed");
    }

    #[test]
    fn it_starts_where_the_pins_leave_it_and_none_is_absent() {
        assert_eq!(GripperModel::new(1 << 6, 0.05, 1 << 6).state(0).name(), "closed");
        assert_eq!(GripperModel::new(1 << 6, 0.05, 1 << 7).state(0).name(), "open");
        let mut none = GripperModel::NONE;
        none.set(u32::MAX, 5);
        assert_eq!(none.state(10).name(), "none");
    }
}
