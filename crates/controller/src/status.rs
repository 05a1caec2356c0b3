//! [`LoopStatus`]: what the loop is doing, as the loop itself says it — its phase, the cycles
//! it has executed, the command, where the motors are, which frames are homed and the
//! gripper. The servo thread writes it with atomic stores only (no lock, no allocation, no
//! system call); any thread of the process reads it (the serving session's command thread).
//! The progress page (`qmarc_proto::progress`) is its view from other processes.

use qmarc_proto::state::Phase;
use qmarc_proto::{Gripper, MAX_MOTORS, MotorFlags};
use std::sync::atomic::{AtomicI64, AtomicU32, AtomicU64, Ordering};

/// The loop's status block: written by the servo thread, read by anyone holding it.
#[derive(Debug)]
pub struct LoopStatus {
    phase: AtomicU32,
    cycles: AtomicU64,
    command: [AtomicU64; MAX_MOTORS],
    actual: [AtomicU64; MAX_MOTORS],
    homed: AtomicU32,
    gripper: AtomicU32,
    /// The belt's sample: odd while the loop writes it ([`LoopStatus::belt`]).
    belt_seq: AtomicU64,
    belt_counts: AtomicI64,
    belt_ns: AtomicU64,
    belt_sample: AtomicU64,
}

impl Default for LoopStatus {
    fn default() -> LoopStatus {
        LoopStatus {
            phase: AtomicU32::new(Phase::Idle.wire()),
            cycles: AtomicU64::new(0),
            command: Default::default(),
            actual: Default::default(),
            homed: AtomicU32::new(0),
            gripper: AtomicU32::new(Gripper::ABSENT),
            belt_seq: AtomicU64::new(0),
            belt_counts: AtomicI64::new(0),
            belt_ns: AtomicU64::new(0),
            belt_sample: AtomicU64::new(0),
        }
    }
}

fn load(a: &[AtomicU64; MAX_MOTORS]) -> [f64; MAX_MOTORS] {
    a.each_ref().map(|x| f64::from_bits(x.load(Ordering::Acquire)))
}

fn store(a: &[AtomicU64; MAX_MOTORS], v: &[f64; MAX_MOTORS]) {
    for (x, v) in a.iter().zip(v) {
        x.store(v.to_bits(), Ordering::Release);
    }
}

impl LoopStatus {
    /// The loop's phase (`Idle` before it is prepared).
    pub fn phase(&self) -> Phase {
        Phase::from_wire(self.phase.load(Ordering::Acquire)).unwrap_or(Phase::Idle)
    }

    /// The loop has begun its cycles (a cycle executed, or its phase past preparing),
    /// whether or not it has ended since.
    pub fn begun(&self) -> bool {
        self.cycles() > 0 || !matches!(self.phase(), Phase::Idle | Phase::Preparing)
    }

    /// The cycles the loop has executed (a stall's skipped samples are no cycles).
    pub fn cycles(&self) -> u64 {
        self.cycles.load(Ordering::Acquire)
    }

    /// The command, counts.
    pub fn command(&self) -> [f64; MAX_MOTORS] {
        load(&self.command)
    }

    /// The motors' positions as the last read found them, counts.
    pub fn actual(&self) -> [f64; MAX_MOTORS] {
        load(&self.actual)
    }

    /// Bit m: motor m's frame is homed, as the last read found it.
    pub fn homed(&self) -> u32 {
        self.homed.load(Ordering::Acquire)
    }

    /// The gripper as the last read found it ([`Gripper`] bits).
    pub fn gripper(&self) -> Gripper {
        Gripper(self.gripper.load(Ordering::Acquire))
    }

    /// The belt encoder's counts at the last read and when that cycle's tick woke the loop
    /// (ns of `CLOCK_MONOTONIC`), read as one pair.
    pub fn belt(&self) -> (i64, u64) {
        let (counts, woke_ns, _) = self.belt_read();
        (counts, woke_ns)
    }

    /// [`LoopStatus::belt`] and the sample (cycle) of that read, read as one: when a sample
    /// was commanded, to the loop's tick.
    pub fn belt_read(&self) -> (i64, u64, u64) {
        loop {
            let before = self.belt_seq.load(Ordering::Acquire);
            let read = (
                self.belt_counts.load(Ordering::Acquire),
                self.belt_ns.load(Ordering::Acquire),
                self.belt_sample.load(Ordering::Acquire),
            );
            // The loop writes them in a few instructions: a torn read is retried at once.
            if before.is_multiple_of(2) && self.belt_seq.load(Ordering::Acquire) == before {
                return read;
            }
            std::hint::spin_loop();
        }
    }

    /// Sample `n`'s belt counts, read when the tick at `woke_ns` woke the loop. The loop's
    /// (as are the other setters; public for a test that stands in for the loop).
    #[inline]
    pub fn set_belt(&self, counts: i64, woke_ns: u64, n: u64) {
        let seq = self.belt_seq.load(Ordering::Relaxed);
        self.belt_seq.store(seq + 1, Ordering::Release);
        self.belt_counts.store(counts, Ordering::Release);
        self.belt_ns.store(woke_ns, Ordering::Release);
        self.belt_sample.store(n, Ordering::Release);
        self.belt_seq.store(seq + 2, Ordering::Release);
    }

    /// The loop's phase.
    pub fn set_phase(&self, phase: Phase) {
        self.phase.store(phase.wire(), Ordering::Release);
    }

    #[inline]
    pub(crate) fn set_cycles(&self, cycles: u64) {
        self.cycles.store(cycles, Ordering::Release);
    }

    /// The cycle's command.
    #[inline]
    pub fn set_command(&self, cmd: &[f64; MAX_MOTORS]) {
        store(&self.command, cmd);
    }

    /// A read of `n` motors: where they are, their flags, the gripper.
    #[inline]
    pub(crate) fn set_read(
        &self,
        n: usize,
        act: &[f64; MAX_MOTORS],
        flags: &[MotorFlags; MAX_MOTORS],
        gripper: Gripper,
    ) {
        store(&self.actual, act);
        let homed = (0..n.min(MAX_MOTORS)).filter(|&m| flags[m].homed()).fold(0, |b, m| b | 1 << m);
        self.homed.store(homed, Ordering::Release);
        self.gripper.store(gripper.0, Ordering::Release);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_status_reads_back_what_the_loop_wrote() {
        let s = LoopStatus::default();
        assert_eq!((s.phase(), s.begun(), s.gripper().0), (Phase::Idle, false, Gripper::ABSENT));
        s.set_phase(Phase::Preparing);
        assert!(!s.begun());
        s.set_cycles(1);
        assert!(s.begun(), "a cycle executed");
        s.set_cycles(0);
        s.set_phase(Phase::Moving);
        s.set_cycles(7);
        s.set_command(&[1.5, -2.0, 3.0, 0.0]);
        let flags = [
            MotorFlags(MotorFlags::HOMED),
            MotorFlags(0),
            MotorFlags(MotorFlags::HOMED),
            MotorFlags(MotorFlags::HOMED),
        ];
        s.set_read(3, &[1.0, -2.5, 3.5, 9.0], &flags, Gripper(0));
        assert!(s.begun());
        assert_eq!(s.cycles(), 7);
        assert_eq!(s.command(), [1.5, -2.0, 3.0, 0.0]);
        assert_eq!(s.actual(), [1.0, -2.5, 3.5, 9.0]);
        assert_eq!(s.homed(), 0b101, "only the robot's motors, by their flags");
        assert_eq!(s.gripper().0, 0);
        assert_eq!(s.belt(), (0, 0));
        s.set_belt(-12_345, 99, 7);
        assert_eq!(s.belt(), (-12_345, 99));
        assert_eq!(s.belt_read(), (-12_345, 99, 7));
        s.set_phase(Phase::Done);
        assert!(s.begun(), "begun, and ended since");
    }
}
