//! The servo loop (thesis 3.8.1.2.1, 4.1): one cycle is wait for the tick → read all encoders
//! (one exchange) → command position → law → write all DACs (one exchange) → gather.
//!
//! [`Servo`] owns everything a move needs, allocated in [`Servo::prepare`] before any motor
//! is enabled. A cycle ([`Cycling::cycle`]) then allocates nothing, locks nothing, formats nothing and
//! does no I/O besides the two exchanges of the link; a fault is recorded as a `Copy` value
//! and handled by disabling every motor.

use crate::fault::{Fault, FaultKind, HostStall};
use crate::gather::{Gather, GatherRow};
use crate::law::{ServoInput, ServoLaw, is_dac_code};
use crate::link::{HwLink, LinkError};
use crate::plan::MovePlan;
use crate::stats::{ErrorStats, TimingStats};
use crate::status::LoopStatus;
use crate::traj::{Sample, TrajStartError, TrajectoryGenerator};
use qmarc_config::{GatherFields, Mode};
pub use qmarc_proto::state::Phase;
use qmarc_proto::{Gripper, HwMsg, MAX_MOTORS, MotorFlags, MsgType, Status};
use qmarc_timer::{Clock, Tick};
use std::sync::Arc;

mod error;
mod limits;
mod live;
mod moving;
mod record;
mod run;
pub use error::MoveError;
pub use moving::Cycling;
use moving::MoveState;

/// How a cycle ended.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum CycleEnd {
    /// The cycle ran; the move goes on.
    Continue,
    /// The path has ended; nothing was written this cycle.
    Done,
    /// Something went wrong; the caller must run the fault handler.
    Fault(Fault),
}

/// A move: its plan, generator, law, clock, the loop's registers, and the move's state
/// (made afresh by [`Servo::prepare`]).
pub struct Servo {
    plan: MovePlan,
    generator: Box<dyn TrajectoryGenerator>,
    law: Box<dyn ServoLaw>,
    clock: Box<dyn Clock>,
    cmd: [f64; MAX_MOTORS],
    act: [f64; MAX_MOTORS],
    dac: [i32; MAX_MOTORS],
    t0_ns: u64,
    /// Tick 0 on the system clock, ns since the Unix epoch.
    t0_wall_ns: u64,
    phase: Phase,
    /// Where the move's progress is published, if anywhere.
    progress: Option<qmarc_proto::progress::Progress>,
    /// Where the live samples go, if anywhere (until the move ends).
    telemetry: Option<crate::telemetry::Telemetry>,
    /// Live samples dropped because their ring was full (known once the move ended).
    telemetry_dropped: u32,
    /// The gripper as the cycle's read reported it.
    grip: Gripper,
    /// The belt encoder's counts at this cycle's read.
    belt: i64,
    /// The free outputs as the cycle's read reported them (after a write of this cycle, as
    /// written).
    outputs: u32,
    /// What the loop is doing, for the threads of the process ([`LoopStatus`]).
    status: Arc<LoopStatus>,
    /// The move's own state: nothing before it is prepared, made whole by `prepare`.
    m: MoveState,
}

impl Servo {
    /// A move with `generator` and `law`; `clock` times the phases of each cycle.
    pub fn new(
        plan: MovePlan,
        generator: Box<dyn TrajectoryGenerator>,
        law: Box<dyn ServoLaw>,
        clock: Box<dyn Clock>,
    ) -> Servo {
        Servo {
            m: MoveState::new(&plan),
            plan,
            generator,
            law,
            clock,
            cmd: [0.0; MAX_MOTORS],
            act: [0.0; MAX_MOTORS],
            dac: [0; MAX_MOTORS],
            t0_ns: 0,
            t0_wall_ns: 0,
            phase: Phase::Idle,
            progress: None,
            telemetry: None,
            telemetry_dropped: 0,
            grip: Gripper(Gripper::ABSENT),
            belt: 0,
            outputs: 0,
            status: Arc::new(LoopStatus::default()),
        }
    }

    /// Writes what the loop is doing into `status` (the serving session's command thread
    /// reads it) instead of a block of its own.
    pub fn with_status(mut self, status: Arc<LoopStatus>) -> Servo {
        self.status = status;
        self
    }

    /// What the loop is doing, as it writes it every cycle.
    pub fn status(&self) -> &Arc<LoopStatus> {
        &self.status
    }

    /// Gathers into the gather page at `path` (`qmarc_proto::gather_page`), made when the
    /// move starts: the rows outlive this process.
    pub fn with_gather_page(mut self, path: std::path::PathBuf) -> Servo {
        self.plan.gather_page = Some(path);
        self
    }

    /// The gather buffer of a move of `samples` cycles: in the plan's gather page if it has
    /// one (a page that cannot be made is said, and the heap used), with the plan's fields and
    /// a ring for a path of unknown length that keeps its last rows.
    fn gather_buffer(&self, samples: u64) -> Gather {
        let (every, n) = (self.plan.gather_every, self.plan.n_motors);
        let buffer = match &self.plan.gather_page {
            Some(page) => Gather::in_page(page, samples, every, n).unwrap_or_else(|e| {
                // Before the move: the data then live only here, as they did before pages.
                eprintln!(
                    "qmarc-controller: warning: no gather page {} ({e}): a controller killed \
                     mid-move would lose its data",
                    page.display()
                );
                Gather::for_move(samples, every, n)
            }),
            None => Gather::for_move(samples, every, n),
        };
        buffer
            .with_fields(GatherFields {
                grip: self.plan.gather_fields.grip && self.plan.gripper_mask != 0,
                conv: self.plan.gather_fields.conv && self.plan.mode == Mode::Conveyor,
                ..self.plan.gather_fields
            })
            .keeping_last(self.plan.gather_keeps_last && self.m.planned_samples.is_none())
    }

    /// Hands a live sample to `telemetry` every few cycles ([`crate::telemetry`]).
    pub fn with_telemetry(mut self, telemetry: Option<crate::telemetry::Telemetry>) -> Servo {
        self.telemetry = telemetry;
        self
    }

    /// Live samples the loop dropped because their ring was full.
    pub fn telemetry_dropped(&self) -> u32 {
        self.telemetry.as_ref().map_or(self.telemetry_dropped, |t| t.dropped())
    }

    /// Publishes the move's phase and cycles in `progress` as it goes.
    pub fn with_progress(mut self, progress: Option<qmarc_proto::progress::Progress>) -> Servo {
        self.progress = progress;
        self
    }

    fn enter(&mut self, phase: Phase) {
        self.phase = phase;
        self.status.set_phase(phase);
        if let Some(p) = &self.progress {
            p.set_phase(phase.wire());
        }
    }

    /// Where the move is.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// The positions that read 0 after this move, if it defines a homed frame (homing).
    pub fn homed_frame(&self) -> Option<[f64; MAX_MOTORS]> {
        self.generator.report().homed_frame
    }

    /// Per motor, whether its frame was homed when the move began (the software limits held
    /// only for those).
    pub fn homed(&self) -> [bool; MAX_MOTORS] {
        self.m.homed
    }

    /// The plan.
    pub fn plan(&self) -> &MovePlan {
        &self.plan
    }

    /// Gathered data.
    pub fn gather(&self) -> &Gather {
        &self.m.gather
    }

    /// Error figures.
    pub fn errors(&self) -> &ErrorStats {
        &self.m.errors
    }

    /// Timing figures.
    pub fn timing(&self) -> &TimingStats {
        &self.m.timing
    }

    /// The fault that ended the move, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.m.fault
    }

    /// The generator's own explanation of the fault that ended the move, where it has one
    /// (a bad knot in a stream, why homing failed).
    pub fn failure(&self) -> Option<String> {
        self.generator_failed().then(|| self.generator.report().failure).flatten()
    }

    /// Whether the fault that ended the move is one the generator explains: its own
    /// failure, or a switch it watched itself (jog), not the hwserver's latch.
    fn generator_failed(&self) -> bool {
        self.m.fault.is_some_and(|f| match f.kind {
            FaultKind::TrajectoryError | FaultKind::HomingFailed | FaultKind::TooMuchTravel => true,
            FaultKind::LimitSwitch => f.status.is_ok(),
            _ => false,
        })
    }

    /// Cycles of the path executed (the error figures' cycles; the lead-in and the settle
    /// are apart).
    pub fn cycles(&self) -> u64 {
        self.m.executed - self.m.settle_executed - self.m.lead_executed
    }

    /// Command − actual of every motor in the last cycle.
    pub fn last_error(&self) -> [f64; MAX_MOTORS] {
        let mut e = [0.0; MAX_MOTORS];
        for (e, (c, a)) in e.iter_mut().zip(self.cmd.iter().zip(&self.act)) {
            *e = c - a;
        }
        e
    }

    fn request(link: &mut dyn HwLink, req: HwMsg) -> Result<HwMsg, MoveError> {
        let resp = link.exchange(&req)?;
        let status = resp.status();
        match status {
            s if s.is_ok() => Ok(resp),
            s if s.contains(Status::ESTOP) => Err(MoveError::EmergencyStop),
            s => Err(MoveError::Refused(s)),
        }
    }

    /// Everything before the first tick, in order: clear and arm the safety monitoring, read
    /// where the robot is, start the path from there, reset the law, size the gather buffer
    /// from the path's length, and only then enable the motors.
    ///
    /// The move's state is made afresh here; what comes back is the only way to cycle it.
    pub fn prepare(&mut self, link: &mut dyn HwLink) -> Result<Cycling<'_>, MoveError> {
        self.m = MoveState::new(&self.plan);
        self.enter(Phase::Preparing);
        Servo::request(link, HwMsg::request(MsgType::ClearSafetyStatus))?;
        let monitor =
            if self.plan.monitor_switches { MsgType::EnableSafety } else { MsgType::DisableSafety };
        Servo::request(link, HwMsg::request(monitor))?;
        let start = Servo::request(link, HwMsg::read_all_encoders())?;
        self.act = start.data;
        let flags = start.aux.map(MotorFlags);
        self.m.homed = flags.map(MotorFlags::homed);
        self.status.set_read(self.plan.n_motors, &self.act, &flags, Gripper(start.gripper));
        if self.plan.require_homed
            && let Some(m) = (0..self.plan.n_motors).find(|&m| !self.m.homed[m])
        {
            return Err(MoveError::NotHomed { motor: m + 1 });
        }
        self.generator.observe(&self.act, &flags);
        self.generator.start(&self.act)?;
        self.m.lead_in = self.generator.lead_in();
        if let (Some(soft), Some(bounds)) = (self.plan.limits.soft, self.generator.path_bounds()) {
            for m in (0..self.plan.n_motors).filter(|&m| self.m.homed[m]) {
                let ((min, max), (lo, hi)) = (soft[m], bounds[m]);
                if lo < min || hi > max {
                    let value = if lo < min { lo } else { hi };
                    return Err(MoveError::OutsideSoftLimits { motor: m + 1, value, min, max });
                }
            }
        }
        self.m.planned_samples = self.generator.samples();
        self.generator.sample(0, &mut self.cmd);
        if let Some(f) = self.check_command(0) {
            return Err(MoveError::Trajectory(TrajStartError::OutOfRange {
                motor: f.motor.map_or(1, |m| m + 1),
                sample: 0,
                value: f.value,
                reason: "not a finite number",
            }));
        }
        self.law.reset(&self.cmd, &self.act);
        self.status.set_command(&self.cmd);
        self.status.set_cycles(0);
        let samples = self.m.planned_samples.unwrap_or(self.plan.stream_gather_samples)
            + self.plan.settle_cycles;
        crate::gather::check_budget(samples, self.plan.gather_every)?;
        self.m.gather = self.gather_buffer(samples);
        // What may have changed while the path was prepared (a stream awaited, a path
        // planned): a fresh read, so that an emergency stop or a switch latched meanwhile
        // refuses the move before anything is enabled.
        Servo::request(link, HwMsg::read_all_encoders())?;
        for m in 0..self.plan.n_motors {
            if let Err(e) = Servo::request(link, HwMsg::for_motor(MsgType::EnableMotor, m as u32)) {
                self.disable_all(link);
                return Err(e);
            }
        }
        Ok(Cycling { servo: self })
    }

    /// Marks when tick 0 is due (the origin of gathered time in real-time runs).
    fn set_t0(&mut self, t0_ns: u64) {
        self.t0_ns = t0_ns;
        // The loop's clock (monotonic, or a lock-step run's own) against the system clock,
        // read once here, before the first cycle: the gathered rows' times on the wall.
        let since_t0 = self.clock.now_ns().saturating_sub(t0_ns);
        let wall = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.as_nanos() as u64);
        self.t0_wall_ns = wall.saturating_sub(since_t0);
        if let Some(p) = &self.progress {
            p.set_t0(t0_ns);
        }
    }

    /// One servo cycle for `tick`. Allocates nothing, locks nothing, formats nothing.
    #[inline]
    fn cycle(&mut self, link: &mut dyn HwLink, tick: &Tick) -> CycleEnd {
        let n = if self.plan.deterministic { self.m.executed } else { tick.index };
        self.m.last_sample = n;

        self.m.timing.record_tick(tick);
        if tick.missed > 0 && !self.plan.deterministic {
            self.m.last_stall = Some((n, tick.missed));
        }
        if tick.missed >= self.plan.limits.max_missed_in_row {
            return CycleEnd::Fault(Fault {
                value: tick.missed as f64,
                limit: self.plan.limits.max_missed_in_row as f64,
                ..Fault::new(FaultKind::Overrun, n)
            });
        }

        // 1. Read all encoders.
        let read_start = self.clock.now_ns();
        let hw_time_ns = match self.read_encoders(link, n) {
            Ok(t) => t,
            Err(f) => return CycleEnd::Fault(f),
        };
        let read_done = self.clock.now_ns();
        self.status.set_belt(self.belt, tick.woke_ns, n);

        // 2. Command position (frozen while holding after a starved trajectory).
        if !self.m.holding
            && let Some(end) = self.sample(n)
        {
            return end;
        }
        if let Some(f) = self.check_command(n).or_else(|| self.check_limits(n)) {
            return CycleEnd::Fault(Fault { hw_time_ns, ..f });
        }

        // 3. Law.
        let elapsed = n.saturating_sub(self.m.law_sample).max(1);
        self.m.law_sample = n;
        self.law.step(&ServoInput { n, elapsed, cmd: &self.cmd, act: &self.act }, &mut self.dac);
        if let Some(m) = (0..self.plan.n_motors).find(|&m| !is_dac_code(self.dac[m])) {
            return CycleEnd::Fault(Fault {
                motor: Some(m),
                hw_time_ns,
                ..Fault::new(FaultKind::BadOutput, n)
            });
        }
        let computed = self.clock.now_ns();

        // 4. Write all DACs.
        let resp = match link.exchange(&HwMsg::write_all_dacs(&self.dac)) {
            Ok(r) => r,
            Err(e) => return CycleEnd::Fault(Fault::from_link(e, n)),
        };
        let written = self.clock.now_ns();

        // 4b. The gripper, in a cycle its command changes: message 13, one more exchange.
        if let Some(f) = self.write_gripper(link, n) {
            return CycleEnd::Fault(Fault { hw_time_ns, ..f });
        }

        // 5. Gather.
        self.m.timing.record_cycle(tick, read_start, read_done, computed, written);
        self.record(n, tick);
        self.publish(n, tick, written, resp.status);
        self.m.executed += 1;
        self.status.set_command(&self.cmd);
        self.status.set_cycles(self.m.executed);
        if let Some(p) = &self.progress {
            p.set_cycle(self.m.executed, self.generator.progress());
        }
        match Fault::from_status(resp.status(), n) {
            Some(f) => CycleEnd::Fault(f),
            None => CycleEnd::Continue,
        }
    }

    /// Step 1 of a cycle: reads every encoder into `act` and shows the generator the
    /// feedback; the hardware's timestamp, or the fault the response carries.
    #[inline]
    fn read_encoders(&mut self, link: &mut dyn HwLink, n: u64) -> Result<u64, Fault> {
        let resp =
            link.exchange(&HwMsg::read_all_encoders()).map_err(|e| Fault::from_link(e, n))?;
        let hw_time_ns = resp.time_ns;
        if let Some(f) = Fault::from_status(resp.status(), n) {
            return Err(Fault { hw_time_ns, ..f });
        }
        self.act = resp.data;
        self.grip = Gripper(resp.gripper);
        self.belt = resp.belt;
        self.outputs = resp.outputs;
        let flags = resp.aux.map(MotorFlags);
        self.status.set_read(self.plan.n_motors, &self.act, &flags, self.grip);
        self.generator.observe(&self.act, &flags);
        self.generator.belt(self.belt);
        Ok(hw_time_ns)
    }

    /// Step 4b of a cycle: what the generator wants of the gripper, written when it is not
    /// what the outputs are (`None`: nothing to write, or written); the fault otherwise.
    #[inline]
    fn write_gripper(&mut self, link: &mut dyn HwLink, n: u64) -> Option<Fault> {
        let mask = self.plan.gripper_mask;
        let close = self.generator.gripper(self.grip)?;
        if mask == 0 || close == (self.outputs & mask != 0) {
            return None;
        }
        let values = if close { mask } else { 0 };
        match link.exchange(&HwMsg::write_outputs(mask, values)) {
            Err(e) => Some(Fault::from_link(e, n)),
            Ok(resp) => {
                self.outputs = (self.outputs & !mask) | values;
                Fault::from_status(resp.status(), n)
            }
        }
    }

    /// Step 2 of a cycle: the command of sample `n` into `cmd`, or how the cycle ends when
    /// the path has ended or failed.
    #[inline]
    fn sample(&mut self, n: u64) -> Option<CycleEnd> {
        match self.generator.sample(n, &mut self.cmd) {
            Sample::Ready => {
                self.m.last_ready = n;
                None
            }
            Sample::Done => {
                self.command_the_end();
                Some(CycleEnd::Done)
            }
            Sample::Starved => Some(CycleEnd::Fault(Fault::new(FaultKind::TrajectoryStarved, n))),
            Sample::Failed => Some(CycleEnd::Fault(Fault::new(self.generator.failure_kind(), n))),
        }
    }

    /// Periods missed at the very end of a path skip its last samples: the command the
    /// settle holds is then the path's last one, not one short of it.
    #[inline]
    fn command_the_end(&mut self) {
        // Only a settle holds it (homing and the check have none: their generators keep
        // books of what they sampled).
        if self.plan.settle_cycles == 0 {
            return;
        }
        if let Some(last) = self.m.planned_samples.and_then(|s| s.checked_sub(1))
            && self.m.last_ready < last
        {
            let mut end = self.cmd;
            if matches!(self.generator.sample(last, &mut end), Sample::Ready) {
                self.cmd = end;
            }
        }
    }

    /// Step 5 of a cycle: the error figures (the path's, or the settle's) and, when sample
    /// `n` is due, a row of the gather buffer.
    #[inline]
    fn record(&mut self, n: u64, tick: &Tick) {
        if self.m.settling {
            self.m.settle_errors.add(self.plan.n_motors, &self.cmd, &self.act);
            self.m.settle_executed += 1;
            self.m.settle_from.get_or_insert(n);
        } else if n < self.m.lead_in {
            self.m.lead_errors.add(self.plan.n_motors, &self.cmd, &self.act);
            self.m.lead_executed += 1;
        } else {
            self.m.errors.add(self.plan.n_motors, &self.cmd, &self.act);
        }
        if self.m.gather.due(n) {
            // Integer ns divided once: the correctly rounded decimal, no accumulated noise.
            let time_s = self.sample_time_ns(n, tick) as f64 / 1e9;
            self.m.gather.push(GatherRow {
                cycle: n,
                time_s,
                cmd: self.cmd,
                act: self.act,
                dac: self.dac,
                grip: self.grip.code(),
                conv: self.belt,
            });
        }
    }

    /// The gathered time of sample `n`, ns since tick 0: simulated in lock-step runs, else
    /// when the thread woke.
    #[inline]
    fn sample_time_ns(&self, n: u64, tick: &Tick) -> u64 {
        if self.plan.deterministic {
            n * self.plan.period_ns
        } else {
            tick.woke_ns.saturating_sub(self.t0_ns)
        }
    }

    /// The fault handler: disables every motor (DACs to 0 V first) unless the hwserver is
    /// known to be gone, and records `fault` with whether the disable was acknowledged.
    pub fn handle_fault(&mut self, link: &mut dyn HwLink, fault: Fault) {
        let disabled = !server_gone(Some(fault)) && self.disable_all(link);
        // A stall within the last second may be why: the plant ran on the last output.
        let recent = 1_000_000_000 / self.plan.period_ns.max(1);
        let stall = self.m.last_stall.and_then(|(at, missed)| {
            let cycles_before = fault.cycle.checked_sub(at)?;
            (cycles_before <= recent).then_some(HostStall { missed, cycles_before })
        });
        self.m.fault = Some(Fault { disabled, stall, ..fault });
        self.enter(Phase::Fault);
    }

    /// Commands `DisableAll`; true if the hwserver acknowledged it. Never fails: a fault path
    /// must go on.
    fn disable_all(&mut self, link: &mut dyn HwLink) -> bool {
        link.exchange(&HwMsg::request(MsgType::DisableAll)).is_ok()
    }
}

/// True when `fault` says the hwserver process is gone: nothing can reach the hardware. A
/// link that failed with the server still alive still gets the disable commands.
pub fn server_gone(fault: Option<Fault>) -> bool {
    matches!(fault.and_then(|f| f.link), Some(LinkError::Lost { server_alive: false, .. }))
}
