//! [`SimDeltabot`]: a simulated Deltabot, the default backend and what tests and CI run on.
//!
//! Per motor (`../shared/notes/deltabot.md`): a velocity-mode servo amplifier turns the DAC
//! code into a velocity command `Kv · code · 10 V / 8191` that the motor follows through the
//! amplifier's velocity loop — second order (ωn, ζ) by default, or a first-order lag τ
//! ([`plant`]); a disabled amplifier drives nothing and the motor coasts to rest with
//! its own time constant. The position, in counts, is quantised by a 24-bit quadrature counter
//! that wraps and whose "zero" is [`COUNTER_ZERO`], as on the 626. Top and bottom limit
//! switches are active beyond their positions.
//!
//! Two clocks: real time (the plant advances by the measured time since the last access) and
//! lock-step (every read of the inputs advances it by exactly one servo period, so two runs
//! with the same requests give identical data).

use crate::backend::{Backend, BackendOpenError, FrameNotKept, HwFault, Inputs, Outputs};
use qmarc_config::{Settings, SimPlant};
use qmarc_proto::{COUNTER_MASK, COUNTER_ZERO, DAC_FULL_SCALE_V, DAC_MAX, MAX_MOTORS, Status};
use qmarc_timer::clock::monotonic_now_ns;

mod belt;
mod params;
pub mod plant;
pub use belt::SimBelt;
pub use params::{SimParams, SimParamsError};
use plant::{AxisState, VelocityLoop};

/// One simulated axis.
#[derive(Debug, Clone, Copy, Default)]
struct Axis {
    /// True position, counts (homed frame).
    x: f64,
    /// Velocity, counts/s.
    v: f64,
    /// Rate of the velocity, counts/s² (the second-order velocity loop's state).
    a: f64,
    /// DAC code in effect.
    dac: i32,
    /// Amplifier enabled.
    enabled: bool,
    /// Raw counter value minus floor(x), mod 2^24: what a counter load changes.
    counter_offset: u32,
}

/// What the simulator records for tests and post-mortems, on its own clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SimEvent {
    /// A limit switch became active (`top`) or inactive.
    Switch {
        /// Motor, 0-based.
        motor: u8,
        /// The top switch (else the bottom one).
        top: bool,
        /// Active now.
        on: bool,
    },
    /// An amplifier was enabled or disabled.
    Amp {
        /// Motor, 0-based.
        motor: u8,
        /// Enabled now.
        on: bool,
    },
    /// A free digital output (message 13: the gripper) was switched.
    Output {
        /// DIO channel.
        channel: u8,
        /// On now.
        on: bool,
    },
}

/// Events the log keeps; later ones are dropped (and counted).
pub const SIM_EVENT_CAPACITY: usize = 4096;

/// The simulated Deltabot backend.
#[derive(Debug, Clone)]
pub struct SimDeltabot {
    p: SimParams,
    axes: [Axis; MAX_MOTORS],
    /// The enabled amplifiers' velocity loop.
    velocity_loop: VelocityLoop,
    /// Switch states at the last read, to log their edges.
    switches: Status,
    /// Stuck switch has tripped.
    stuck: bool,
    events: Vec<(u64, SimEvent)>,
    dropped_events: u64,
    /// Simulated time of the last access by the server (reads, writes, enables, loads).
    last_access_ns: u64,
    /// Simulated time of the plant state, ns.
    t_ns: u64,
    /// In real time: the monotonic time `t_ns` corresponds to.
    origin_ns: u64,
    /// Sign of the direction toward the top switch (−1 when top < bottom).
    top_dir: f64,
    /// Per motor: the counter frame is homed.
    homed: [bool; MAX_MOTORS],
    /// Where the homed frame is kept between runs ([`SimDeltabot::with_state_file`]).
    state_file: Option<std::path::PathBuf>,
    /// Where the event log goes when the server ends ([`Backend::finish`]).
    events_file: Option<std::path::PathBuf>,
    /// The emergency-stop button, pressed from outside ([`SimDeltabot::estop_button`]).
    estop_button: std::sync::Arc<std::sync::atomic::AtomicBool>,
    /// The free outputs that are on.
    outputs: u32,
    /// The belt and its encoder, if the robot stands at one ([`SimDeltabot::with_belt`]).
    belt: Option<SimBelt>,
}

/// What the simulated robot's state file says its frame belongs to.
pub const SIM_IDENTITY: &str = "the simulated Deltabot";

impl SimDeltabot {
    /// A robot at rest at its start positions, amplifiers off, DACs at 0 V.
    pub fn new(p: SimParams) -> Result<SimDeltabot, SimParamsError> {
        p.validate()?;
        let mut axes = [Axis::default(); MAX_MOTORS];
        let offset = if p.plant.homed { 0 } else { p.plant.counter_offset };
        for (axis, &start) in axes.iter_mut().zip(&p.start_counts) {
            axis.x = start;
            axis.counter_offset = COUNTER_ZERO.wrapping_add(offset as u32);
        }
        let top_dir =
            if p.plant.top_switch_counts < p.plant.bottom_switch_counts { -1.0 } else { 1.0 };
        Ok(SimDeltabot {
            p,
            axes,
            velocity_loop: VelocityLoop::new(
                p.plant.velocity_loop_hz,
                p.plant.velocity_loop_zeta,
                p.plant.tau_s,
            ),
            switches: Status::OK,
            stuck: false,
            events: Vec::with_capacity(SIM_EVENT_CAPACITY),
            dropped_events: 0,
            last_access_ns: 0,
            t_ns: 0,
            origin_ns: monotonic_now_ns(),
            top_dir,
            homed: [p.plant.homed; MAX_MOTORS],
            state_file: None,
            events_file: None,
            estop_button: std::sync::Arc::default(),
            outputs: 0,
            belt: None,
        })
    }

    /// The emergency-stop button: while it holds true the chain reads open (pressing it is
    /// one atomic store; the tests and the conformance rig press it).
    pub fn estop_button(&self) -> std::sync::Arc<std::sync::atomic::AtomicBool> {
        self.estop_button.clone()
    }

    /// Whether the emergency-stop chain is open now: the button, or the injected window.
    fn estop_open(&self) -> bool {
        let t = self.t_ns as f64 * 1e-9;
        self.estop_button.load(std::sync::atomic::Ordering::Relaxed)
            || self.p.plant.estop_open_s.is_some_and(|[from, to]| (from..to).contains(&t))
    }

    /// The registry's check: a robot whose homed frame `sim.state_file` can keep.
    pub fn check(s: &Settings, lockstep: bool) -> Result<(), BackendOpenError> {
        SimDeltabot::open(s, lockstep)?;
        let why = super::state::keep_problem("sim.state_file", s.sim.state_file.as_deref());
        why.map_or(Ok(()), |why| Err(BackendOpenError::Invalid(why)))
    }

    /// The simulated robot of the settings `s`, its homed frame kept in `sim.state_file` and
    /// its event log written to `sim.events_file` when the server ends: the registry's
    /// constructor.
    pub fn open(s: &Settings, lockstep: bool) -> Result<SimDeltabot, BackendOpenError> {
        let sim = SimDeltabot::new(SimParams::from_settings(s, lockstep))
            .map_err(|e| BackendOpenError::Invalid(e.to_string()))?;
        let sim = match &s.sim.state_file {
            Some(path) => sim.with_state_file(path),
            None => sim,
        };
        Ok(SimDeltabot { events_file: s.sim.events_file.clone(), ..sim }.with_belt(SimBelt::of(s)))
    }

    /// The robot stands at `belt`, whose encoder it reads with its motors' counters.
    pub fn with_belt(mut self, belt: SimBelt) -> SimDeltabot {
        self.belt = Some(belt);
        self
    }

    /// Keeps the homed frame in `path` between runs, the way the 626's counters keep theirs
    /// while the card is powered: a motor homed by an earlier run (the file says so) starts
    /// homed — its counter in the homed frame — whatever `homed` says. Put the file on a
    /// tmpfs (`/dev/shm`) so that a reboot clears it, as a power cycle clears the card.
    /// Nothing is kept when the file cannot be read (a fresh machine) or written.
    pub fn with_state_file(mut self, path: &std::path::Path) -> SimDeltabot {
        let kept = super::state::load_homed(path, self.p.n_motors, SIM_IDENTITY);
        for m in (0..self.p.n_motors).filter(|&m| kept[m]) {
            if !self.homed[m] {
                self.homed[m] = true;
                self.axes[m].counter_offset = COUNTER_ZERO;
            }
        }
        self.state_file = Some(path.to_path_buf());
        self
    }

    /// The recorded events (time on the simulator's clock, ns).
    pub fn events(&self) -> &[(u64, SimEvent)] {
        &self.events
    }

    fn log(&mut self, event: SimEvent) {
        if self.events.len() < self.events.capacity() {
            self.events.push((self.t_ns, event));
        } else {
            self.dropped_events += 1;
        }
    }

    fn set_enabled(&mut self, motor: usize, on: bool) {
        if self.axes[motor].enabled != on {
            self.axes[motor].enabled = on;
            self.log(SimEvent::Amp { motor: motor as u8, on });
        }
    }

    /// The parameters.
    pub fn params(&self) -> &SimParams {
        &self.p
    }

    /// True position of `motor` in counts (not quantised).
    pub fn position(&self, motor: usize) -> f64 {
        self.axes[motor].x
    }

    /// Velocity of `motor` in counts/s.
    pub fn velocity(&self, motor: usize) -> f64 {
        self.axes[motor].v
    }

    /// Whether the amplifier of `motor` is on.
    pub fn enabled(&self, motor: usize) -> bool {
        self.axes[motor].enabled
    }

    /// The DAC code in effect on `motor`.
    pub fn dac(&self, motor: usize) -> i32 {
        self.axes[motor].dac
    }

    /// Advances the plant by `dt_ns` with the DACs and enables as they are (zero-order hold),
    /// exactly ([`plant`]): an enabled motor through the amplifier's velocity loop, a
    /// disabled one coasting to rest with `coast_tau_s`.
    pub fn advance(&mut self, dt_ns: u64) {
        if dt_ns == 0 {
            return;
        }
        let dt = dt_ns as f64 * 1e-9;
        let n = self.p.n_motors;
        let volts_per_code = DAC_FULL_SCALE_V / f64::from(DAC_MAX);
        for (m, axis) in self.axes[..n].iter_mut().enumerate() {
            if SimPlant::is(self.p.plant.stall_motor, m) {
                (axis.v, axis.a) = (0.0, 0.0);
                continue;
            }
            let mut s = AxisState { x: axis.x, v: axis.v, a: axis.a };
            if axis.enabled {
                let wired = if SimPlant::is(self.p.plant.reversed_motor, m) { -1.0 } else { 1.0 };
                let target = wired * self.p.plant.kv * volts_per_code * f64::from(axis.dac);
                self.velocity_loop.advance(&mut s, target, dt);
            } else {
                plant::first_order(&mut s, 0.0, self.p.plant.coast_tau_s, dt);
            }
            (axis.x, axis.v, axis.a) = (s.x, s.v, s.a);
        }
        self.t_ns += dt_ns;
    }

    /// In real time, brings the plant up to now.
    fn catch_up(&mut self) {
        if !self.p.lockstep {
            let now = monotonic_now_ns().saturating_sub(self.origin_ns);
            self.advance(now.saturating_sub(self.t_ns));
        }
    }

    fn counter(&self, motor: usize) -> u32 {
        let axis = &self.axes[motor];
        ((axis.x.floor() as i64 as u32).wrapping_add(axis.counter_offset)) & COUNTER_MASK
    }

    fn limits(&mut self) -> Status {
        let mut s = Status::OK;
        for (m, axis) in self.axes[..self.p.n_motors].iter().enumerate() {
            if (axis.x - self.p.plant.top_switch_counts) * self.top_dir >= 0.0 {
                s |= Status::limit_top(m);
            }
            if (axis.x - self.p.plant.bottom_switch_counts) * self.top_dir <= 0.0 {
                s |= Status::limit_bottom(m);
            }
        }
        if let Some(m) = self.p.plant.stuck_top_motor.and_then(|m| m.checked_sub(1)) {
            self.stuck |= s.contains(Status::limit_top(m));
            if self.stuck {
                s |= Status::limit_top(m);
            }
        }
        s
    }
}

impl Backend for SimDeltabot {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn n_motors(&self) -> usize {
        self.p.n_motors
    }

    fn read_inputs(&mut self, inputs: &mut Inputs) -> Result<(), HwFault> {
        if self.p.lockstep {
            self.advance(self.p.period_ns);
        } else {
            self.catch_up();
        }
        for m in 0..self.p.n_motors {
            inputs.counters[m] = self.counter(m);
        }
        inputs.limits = self.limits();
        inputs.estop_open = self.estop_open();
        inputs.outputs = self.outputs;
        inputs.belt = self
            .belt
            .as_ref()
            .map_or(COUNTER_ZERO, |b| b.counter(self.t_ns, self.origin_ns, self.p.lockstep));
        let changed = inputs.limits.0 ^ self.switches.0;
        for m in 0..self.p.n_motors {
            for (top, bit) in [(true, Status::limit_top(m)), (false, Status::limit_bottom(m))] {
                if changed & bit.0 != 0 {
                    self.log(SimEvent::Switch {
                        motor: m as u8,
                        top,
                        on: inputs.limits.contains(bit),
                    });
                }
            }
        }
        self.switches = inputs.limits;
        self.last_access_ns = self.t_ns;
        Ok(())
    }

    fn write_dacs(&mut self, codes: &[i32; MAX_MOTORS]) -> Result<(), HwFault> {
        self.catch_up();
        let n = self.p.n_motors;
        for (axis, &code) in self.axes[..n].iter_mut().zip(codes) {
            axis.dac = code.clamp(-DAC_MAX, DAC_MAX);
        }
        self.last_access_ns = self.t_ns;
        Ok(())
    }

    fn set_amp_enable(&mut self, motor: usize, on: bool) -> Result<(), HwFault> {
        self.catch_up();
        self.set_enabled(motor, on);
        self.last_access_ns = self.t_ns;
        Ok(())
    }

    fn load_counter(&mut self, motor: usize, raw: u32) -> Result<(), HwFault> {
        self.catch_up();
        let axis = &mut self.axes[motor];
        axis.counter_offset = raw.wrapping_sub(axis.x.floor() as i64 as u32);
        Ok(())
    }

    fn free_outputs(&self) -> u32 {
        self.p.free_outputs
    }

    fn write_outputs(&mut self, mask: u32, values: u32) -> Result<(), HwFault> {
        self.catch_up();
        let new = (self.outputs & !mask) | (values & mask);
        let changed = new ^ self.outputs;
        self.outputs = new;
        for channel in (0..32u8).filter(|c| changed & 1 << c != 0) {
            self.log(SimEvent::Output { channel, on: new & 1 << channel != 0 });
        }
        self.last_access_ns = self.t_ns;
        Ok(())
    }

    fn safe_state(&mut self) {
        self.catch_up();
        for m in 0..MAX_MOTORS {
            self.axes[m].dac = 0;
            if m < self.p.n_motors {
                self.set_enabled(m, false);
            }
        }
    }

    fn homed(&self, motor: usize) -> bool {
        self.homed[motor]
    }

    /// Records the homed frame, in the state file too if there is one (a file write: this
    /// hook runs after homing, not in the servo loop).
    fn set_homed(&mut self, motor: usize) -> Result<(), FrameNotKept> {
        self.homed[motor] = true;
        let Some(path) = &self.state_file else { return Ok(()) };
        let n = self.p.n_motors;
        super::state::save_homed(path, &self.homed[..n], SIM_IDENTITY).map_err(|e| {
            self.homed[motor] = false;
            FrameNotKept {
                motor: motor + 1,
                path: path.clone(),
                key: "sim.state_file",
                reason: e.to_string(),
            }
        })
    }

    /// CSV: `t_ns,event,motor` (motor 1-based; events `top_on`, `top_off`, `bottom_on`,
    /// `bottom_off`, `amp_on`, `amp_off`; `out_on` and `out_off` name a DIO channel in the
    /// third column), then `t_ns,last_access,0`: the last time the server touched the robot
    /// before it ended.
    fn write_log(&self, w: &mut dyn std::io::Write) -> std::io::Result<()> {
        writeln!(w, "t_ns,event,motor")?;
        for (t, e) in &self.events {
            // Motors 1-based; an output's DIO channel as it is.
            let (name, column) = match *e {
                SimEvent::Switch { motor, top, on } => {
                    let name = match (top, on) {
                        (true, true) => "top_on",
                        (true, false) => "top_off",
                        (false, true) => "bottom_on",
                        (false, false) => "bottom_off",
                    };
                    (name, u32::from(motor) + 1)
                }
                SimEvent::Amp { motor, on } => {
                    (if on { "amp_on" } else { "amp_off" }, u32::from(motor) + 1)
                }
                SimEvent::Output { channel, on } => {
                    (if on { "out_on" } else { "out_off" }, u32::from(channel))
                }
            };
            writeln!(w, "{t},{name},{column}")?;
        }
        writeln!(w, "{},last_access,0", self.last_access_ns)?;
        if self.dropped_events > 0 {
            writeln!(w, "{},dropped_events,{}", self.t_ns, self.dropped_events)?;
        }
        Ok(())
    }

    fn set_epoch(&mut self, epoch_ns: u64) {
        if let Some(b) = &mut self.belt {
            b.set_epoch(epoch_ns);
        }
    }

    fn now_ns(&self) -> u64 {
        if self.p.lockstep { self.t_ns } else { monotonic_now_ns().saturating_sub(self.origin_ns) }
    }

    fn outputs(&self) -> Option<Outputs> {
        let mut o = Outputs::default();
        for m in 0..self.p.n_motors {
            o.dac[m] = self.axes[m].dac;
            o.enabled[m] = self.axes[m].enabled;
        }
        Some(o)
    }

    /// Writes the event log to `sim.events_file`, if one is set.
    fn finish(&mut self) -> std::io::Result<()> {
        let Some(path) = self.events_file.clone() else { return Ok(()) };
        let mut out = Vec::new();
        self.write_log(&mut out)?;
        std::fs::write(&path, out)
            .map_err(|e| std::io::Error::new(e.kind(), format!("{}: {e}", path.display())))
    }
}

mod rig;
pub use rig::SimRig;

#[cfg(test)]
mod tests;
