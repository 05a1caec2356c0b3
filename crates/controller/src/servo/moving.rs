//! A move's own state ([`MoveState`], made afresh by [`Servo::prepare`]) and the prepared move
//! that alone may cycle ([`Cycling`]).

use super::{CycleEnd, Servo};
use crate::fault::Fault;
use crate::gather::Gather;
use crate::link::HwLink;
use crate::plan::MovePlan;
use crate::stats::{ErrorStats, TimingStats};
use qmarc_proto::MAX_MOTORS;
use qmarc_timer::Tick;

/// What one move counts and records, from [`Servo::prepare`] on: a new move starts from a
/// new one, never from the last one's.
pub(super) struct MoveState {
    pub(super) executed: u64,
    pub(super) last_sample: u64,
    /// The last sample index the generator answered with a command.
    pub(super) last_ready: u64,
    /// The sample of the law's previous cycle (0 = the sample its reset seeded).
    pub(super) law_sample: u64,
    pub(super) gather: Gather,
    pub(super) errors: ErrorStats,
    pub(super) timing: TimingStats,
    pub(super) fault: Option<Fault>,
    /// The latest host stall in a real-time run: its sample and the periods it missed.
    pub(super) last_stall: Option<(u64, u64)>,
    pub(super) planned_samples: Option<u64>,
    /// The command is frozen: the trajectory starved, or the path ended and the robot settles.
    pub(super) holding: bool,
    /// Cycles of the settle at the end of the path (their errors go to `settle_errors`).
    pub(super) settle_executed: u64,
    pub(super) settling: bool,
    /// The sample index the settle began at (the path's rows are the ones before it).
    pub(super) settle_from: Option<u64>,
    pub(super) settle_errors: ErrorStats,
    /// Σ (command − actual) per motor over the move.
    pub(super) integrated_error: [f64; MAX_MOTORS],
    /// Per motor: its frame is homed (read before the move); the software limits, which hold
    /// in the homed frame, are checked only there.
    pub(super) homed: [bool; MAX_MOTORS],
    /// Samples before the path proper (an approach to its start), from the generator.
    pub(super) lead_in: u64,
    /// Cycles of the lead-in executed, and their error figures (apart from the path's).
    pub(super) lead_executed: u64,
    pub(super) lead_errors: ErrorStats,
}

impl MoveState {
    /// A move of `plan` before anything is known of it: nothing executed, nothing gathered.
    pub(super) fn new(plan: &MovePlan) -> MoveState {
        MoveState {
            executed: 0,
            last_sample: 0,
            last_ready: 0,
            law_sample: 0,
            gather: Gather::for_move(0, plan.gather_every, plan.n_motors),
            errors: ErrorStats::default(),
            timing: TimingStats::new(plan.period_ns),
            fault: None,
            last_stall: None,
            planned_samples: None,
            holding: false,
            settle_executed: 0,
            settling: false,
            settle_from: None,
            settle_errors: ErrorStats::default(),
            integrated_error: [0.0; MAX_MOTORS],
            homed: [false; MAX_MOTORS],
            lead_in: 0,
            lead_executed: 0,
            lead_errors: ErrorStats::default(),
        }
    }
}

/// A prepared move, and the only way to cycle one: [`Servo::prepare`] returns it, so no cycle
/// runs on a move whose state was not made afresh and whose motors were not enabled. It
/// reads and handles the move as the [`Servo`] it borrows.
pub struct Cycling<'s> {
    pub(super) servo: &'s mut Servo,
}

impl Cycling<'_> {
    /// Marks when tick 0 is due (the origin of gathered time in real-time runs).
    pub fn set_t0(&mut self, t0_ns: u64) {
        self.servo.set_t0(t0_ns);
    }

    /// One servo cycle for `tick`. Allocates nothing, locks nothing, formats nothing.
    #[inline]
    pub fn cycle(&mut self, link: &mut dyn HwLink, tick: &Tick) -> CycleEnd {
        self.servo.cycle(link, tick)
    }
}

impl std::ops::Deref for Cycling<'_> {
    type Target = Servo;
    fn deref(&self) -> &Servo {
        self.servo
    }
}

impl std::ops::DerefMut for Cycling<'_> {
    fn deref_mut(&mut self) -> &mut Servo {
        self.servo
    }
}
