//! [`HwCore`]: what the server does with each request, independent of IPC and hardware.

use crate::backend::{Backend, FrameNotKept, Inputs};
use crate::gripper::GripperModel;
use qmarc_proto::link::{HwLink, LinkError};
use qmarc_proto::{
    COUNTER_ZERO, DAC_MAX, HwMsg, MAX_MOTORS, MotorFlags, MsgType, Status, counter_delta,
};

/// The server's state machine around a [`Backend`]: software positions, enables, latched
/// status, watchdog bookkeeping. `handle` is called once per request and never allocates,
/// locks, formats or panics.
pub struct HwCore {
    backend: Box<dyn Backend>,
    n_motors: usize,
    inputs: Inputs,
    /// 64-bit software position per motor (thesis 3.10.2's software counter, widened).
    position: [i64; MAX_MOTORS],
    /// The belt encoder's position, counts, widened the same way: its counter's distance from
    /// [`COUNTER_ZERO`] when the server started, then every step since.
    belt: i64,
    enabled: [bool; MAX_MOTORS],
    dacs: [i32; MAX_MOTORS],
    monitoring: bool,
    latched: Status,
    exit_requested: bool,
    /// Per motor: is the counter frame homed?
    homed: [bool; MAX_MOTORS],
    /// Fastest a counter can physically change, counts/s (∞: unchecked).
    max_counts_per_s: f64,
    last_read_ns: u64,
    /// The free outputs as message 13 last set them (from the pins read at start).
    outputs: u32,
    /// The gripper on one of them, if one is wired.
    gripper: GripperModel,
    /// A homed frame the backend could not keep, for whoever serves the core to say
    /// ([`HwCore::take_not_kept`]): `handle` formats nothing.
    not_kept: Option<FrameNotKept>,
}

/// Counts a counter may move beyond the physical bound between two reads (quantisation and
/// timestamp jitter).
pub const ENCODER_SLACK_COUNTS: i64 = 16;

impl HwCore {
    /// Wraps `backend`. The software positions start at the counters' distance from
    /// [`COUNTER_ZERO`], so a frame set by an earlier homing survives a server restart as long
    /// as the counters kept counting. The hardware is put in the safe state first.
    pub fn new(mut backend: Box<dyn Backend>) -> HwCore {
        backend.safe_state();
        let n_motors = backend.n_motors().min(MAX_MOTORS);
        let mut core = HwCore {
            backend,
            n_motors,
            inputs: Inputs::default(),
            position: [0; MAX_MOTORS],
            belt: 0,
            enabled: [false; MAX_MOTORS],
            dacs: [0; MAX_MOTORS],
            monitoring: false,
            latched: Status::OK,
            exit_requested: false,
            homed: [false; MAX_MOTORS],
            max_counts_per_s: f64::INFINITY,
            last_read_ns: 0,
            outputs: 0,
            gripper: GripperModel::NONE,
            not_kept: None,
        };
        // The kept frame holds only where the counters could be read: their distance from
        // COUNTER_ZERO is the position. Without that read no motor counts as homed.
        if core.backend.read_inputs(&mut core.inputs).is_ok() {
            for m in 0..n_motors {
                core.homed[m] = core.backend.homed(m);
                core.position[m] = i64::from(counter_delta(COUNTER_ZERO, core.inputs.counters[m]));
            }
            core.belt = i64::from(counter_delta(COUNTER_ZERO, core.inputs.belt));
            core.outputs = core.inputs.outputs & core.backend.free_outputs();
        }
        core.last_read_ns = core.backend.now_ns();
        core
    }

    /// Flags a counter change faster than `counts_per_s` between two reads (plus
    /// [`ENCODER_SLACK_COUNTS`]) as an encoder fault: [`Status::encoder_overflow`] latches and
    /// the jump is not added to the position. A 24-bit wrap is a normal step, not a jump.
    pub fn with_encoder_limit(mut self, counts_per_s: f64) -> HwCore {
        self.max_counts_per_s = counts_per_s;
        self
    }

    /// The server of the settings `s` around `backend`: the encoder limit of
    /// `hwserver.max_counts_per_s` and the gripper of `s626.gripper_dio`.
    pub fn for_settings(backend: Box<dyn Backend>, s: &qmarc_config::Settings) -> HwCore {
        let core = HwCore::new(backend).with_encoder_limit(s.hwserver.max_counts_per_s);
        match s.s626.gripper_dio {
            Some(c) => core.with_gripper(1 << c, s.s626.gripper_close_s),
            None => core,
        }
    }

    /// A gripper on the free output bit `mask` whose jaws travel in `travel_s`
    /// ([`GripperModel`]), as the outputs read at start leave it. A bit the backend does not
    /// leave free is no gripper (the settings' check refuses it before this).
    pub fn with_gripper(mut self, mask: u32, travel_s: f64) -> HwCore {
        if mask & self.backend.free_outputs() == mask && mask != 0 {
            self.gripper = GripperModel::new(mask, travel_s, self.outputs);
        }
        self
    }

    /// Number of motors served.
    pub fn n_motors(&self) -> usize {
        self.n_motors
    }

    /// The backend.
    pub fn backend(&self) -> &dyn Backend {
        self.backend.as_ref()
    }

    /// The server ends: the backend flushes what it keeps ([`Backend::finish`]).
    pub fn finish(&mut self) -> std::io::Result<()> {
        self.backend.finish()
    }

    /// The flags a read response carries for `motor`.
    fn flags(&self, motor: usize) -> i32 {
        let mut f = 0;
        if self.inputs.limits.contains(Status::limit_top(motor)) {
            f |= MotorFlags::TOP;
        }
        if self.inputs.limits.contains(Status::limit_bottom(motor)) {
            f |= MotorFlags::BOTTOM;
        }
        if self.enabled[motor] {
            f |= MotorFlags::ENABLED;
        }
        if self.homed[motor] {
            f |= MotorFlags::HOMED;
        }
        f
    }

    /// True once an [`MsgType::Exit`] was handled.
    pub fn exit_requested(&self) -> bool {
        self.exit_requested
    }

    /// True if any amplifier is enabled.
    pub fn any_enabled(&self) -> bool {
        self.enabled[..self.n_motors].iter().any(|&e| e)
    }

    /// Software position of `motor` in counts.
    pub fn position(&self, motor: usize) -> i64 {
        self.position[motor]
    }

    /// Puts the hardware in the safe state: DACs 0, amplifiers off.
    pub fn safe_state(&mut self) {
        self.backend.safe_state();
        self.enabled = [false; MAX_MOTORS];
        self.dacs = [0; MAX_MOTORS];
    }

    /// The watchdog fired: safe state, the charge pump stops and every later response
    /// carries [`Status::WATCHDOG`].
    pub fn trip_watchdog(&mut self) {
        self.safe_state();
        self.backend.stop_charge_pump();
        self.latched |= Status::WATCHDOG;
    }

    /// A stop was requested (signal): safe state, the charge pump stops, and every later
    /// response carries [`Status::SHUTDOWN`]; enabling is refused from now on.
    pub fn shut_down(&mut self) {
        self.safe_state();
        self.backend.stop_charge_pump();
        self.latched |= Status::SHUTDOWN;
    }

    /// The hardware failed (a driver error, an operation cut short): safe state at once,
    /// whatever the controller does next, and [`Status::HARDWARE_FAULT`] latched: every later
    /// response carries it and enabling is refused for the rest of the server's life.
    fn hardware_failed(&mut self) -> Status {
        self.safe_state();
        self.latched |= Status::HARDWARE_FAULT;
        Status::HARDWARE_FAULT
    }

    /// True once the server must keep the outputs off for good: a watchdog trip, a stop, a
    /// hardware fault.
    fn outputs_locked(&self) -> bool {
        self.latched.intersects(Status::SHUTDOWN | Status::WATCHDOG | Status::HARDWARE_FAULT)
    }

    /// Writes the DAC codes `dacs` holds (all 0 V once the outputs are locked or while the
    /// emergency stop is latched).
    fn write_dacs(&mut self) -> Status {
        if self.outputs_locked() || self.latched.intersects(Status::ESTOP) {
            self.dacs = [0; MAX_MOTORS];
        }
        if self.backend.write_dacs(&self.dacs).is_err() {
            return self.hardware_failed();
        }
        Status::OK
    }

    /// Reads the inputs, extends the counters into the positions (a physically impossible
    /// jump latches an encoder fault instead) and latches limit bits while monitoring. A
    /// failed read changes nothing.
    fn read(&mut self) -> Status {
        let mut fresh = Inputs::default();
        if self.backend.read_inputs(&mut fresh).is_err() {
            return self.hardware_failed();
        }
        let now = self.backend.now_ns();
        let dt_s = now.saturating_sub(self.last_read_ns) as f64 * 1e-9;
        // `as` saturates: an unchecked (infinite) limit gives i64::MAX.
        let bound =
            ((self.max_counts_per_s * dt_s).ceil() as i64).saturating_add(ENCODER_SLACK_COUNTS);
        for m in 0..self.n_motors {
            let step = i64::from(counter_delta(self.inputs.counters[m], fresh.counters[m]));
            if step.abs() > bound {
                self.latched |= Status::encoder_overflow(m);
            } else {
                self.position[m] += step;
            }
        }
        // The belt moves on its own, enabled or not: every step counts.
        self.belt += i64::from(counter_delta(self.inputs.belt, fresh.belt));
        self.inputs = fresh;
        self.last_read_ns = now;
        // The emergency stop is watched always, homing or not: the motors go off in this read,
        // whatever the controller does next.
        if self.inputs.estop_open && !self.latched.intersects(Status::ESTOP) {
            self.safe_state();
            self.latched |= Status::ESTOP;
        }
        if self.monitoring {
            let tripped = self.inputs.limits & Status::LIMIT_MASK;
            if !tripped.is_ok() {
                // Thesis 3.10.1: latch which switch it was and stop watching until cleared.
                self.latched |= tripped;
                self.monitoring = false;
            }
        }
        Status::OK
    }

    /// Enables `motor`'s amplifier, unless a watchdog trip, a stop or a hardware fault
    /// forbids it for good.
    fn enable(&mut self, motor: usize) -> Status {
        if self.latched.intersects(Status::HARDWARE_FAULT) {
            Status::HARDWARE_FAULT
        } else if self.outputs_locked() {
            Status::SHUTDOWN
        } else if self.latched.intersects(Status::ESTOP) {
            Status::ESTOP
        } else if self.backend.set_amp_enable(motor, true).is_ok() {
            self.enabled[motor] = true;
            Status::OK
        } else {
            self.hardware_failed()
        }
    }

    /// Message 13: the outputs of `mask` to `values`, unless the mask holds a channel the
    /// backend keeps, or the emergency stop or a fault that ends the server holds the outputs.
    fn write_outputs(&mut self, mask: u32, values: u32) -> Status {
        let held = self.outputs_locked() || self.latched.intersects(Status::ESTOP);
        if mask & !self.backend.free_outputs() != 0 || held {
            return Status::PROTECTED_OUTPUT;
        }
        if self.backend.write_outputs(mask, values & mask).is_err() {
            return self.hardware_failed();
        }
        self.outputs = (self.outputs & !mask) | (values & mask);
        self.gripper.set(self.outputs, self.backend.now_ns());
        Status::OK
    }

    /// Zeroes `motor`'s DAC and disables its amplifier (both tried, whatever fails).
    fn disable(&mut self, motor: usize) -> Status {
        self.dacs[motor] = 0;
        let dac_ok = self.backend.write_dacs(&self.dacs).is_ok();
        let amp_ok = self.backend.set_amp_enable(motor, false).is_ok();
        self.enabled[motor] = false;
        if dac_ok && amp_ok { Status::OK } else { self.hardware_failed() }
    }

    /// Presets `motor`'s position to `value` counts (rounded, within the counter's ±2²²)
    /// and marks its frame homed: homing's `ResetEncoderZero`.
    fn preset(&mut self, motor: usize, value: f64) -> Status {
        let preset = value.round().clamp(-f64::from(1 << 22), f64::from(1 << 22)) as i64;
        let raw = COUNTER_ZERO.wrapping_add(preset as u32) & qmarc_proto::COUNTER_MASK;
        if self.backend.load_counter(motor, raw).is_err() {
            // The counter holds who knows what: the frame is not homed, and is not kept.
            self.homed[motor] = false;
            return self.hardware_failed();
        }
        self.inputs.counters[motor] = raw;
        self.position[motor] = preset;
        // A frame that cannot be kept is a failed home: the next run would find it unhomed.
        if let Err(why) = self.backend.set_homed(motor) {
            self.not_kept = Some(why);
            self.homed[motor] = false;
            return Status::NOT_KEPT;
        }
        self.homed[motor] = true;
        Status::OK
    }

    /// Why the last homed frame the backend was told of could not be kept, once (the
    /// response said `NOT_KEPT`).
    pub fn take_not_kept(&mut self) -> Option<FrameNotKept> {
        self.not_kept.take()
    }

    /// Answers one request. Unknown types and bad motor indices are answered with a status
    /// bit, never a crash.
    pub fn handle(&mut self, req: &HwMsg) -> HwMsg {
        self.backend.kick_charge_pump();
        let mut resp = req.response();
        let motor = req.motor as usize;
        let single = motor < self.n_motors;
        let mut status = Status::OK;
        match req.msg_type() {
            Err(_) => status |= Status::UNKNOWN_MESSAGE,
            Ok(MsgType::ReadAllEncoders | MsgType::ReadEncoder) => {
                status |= self.read();
                if req.msg_type == MsgType::ReadEncoder as u32 && !single {
                    status |= Status::BAD_MOTOR;
                }
                for m in 0..self.n_motors {
                    resp.data[m] = self.position[m] as f64;
                    resp.aux[m] = self.flags(m);
                }
                resp.outputs = self.outputs;
                resp.gripper = self.gripper.state(self.backend.now_ns()).0;
                resp.belt = self.belt;
            }
            Ok(MsgType::WriteAllDacs) => {
                for m in 0..self.n_motors {
                    self.dacs[m] = req.aux[m].clamp(-DAC_MAX, DAC_MAX);
                }
                status |= self.write_dacs();
            }
            Ok(MsgType::WriteDac) if single => {
                self.dacs[motor] = req.aux[motor].clamp(-DAC_MAX, DAC_MAX);
                status |= self.write_dacs();
            }
            Ok(MsgType::EnableMotor) if single => status |= self.enable(motor),
            Ok(MsgType::DisableMotor) if single => status |= self.disable(motor),
            Ok(MsgType::DisableAll) => self.safe_state(),
            Ok(MsgType::ResetEncoderZero) if single || req.motor == HwMsg::ALL_MOTORS => {
                let range = if single { motor..motor + 1 } else { 0..self.n_motors };
                for m in range {
                    status |= self.preset(m, req.data[m]);
                }
            }
            Ok(MsgType::EnableSafety) => self.monitoring = true,
            Ok(MsgType::DisableSafety) => self.monitoring = false,
            Ok(MsgType::ClearSafetyStatus) => {
                // Limit and encoder bits; the emergency stop only if its chain reads closed
                // now (a fresh read, the switches not latched by it); a watchdog or shutdown
                // stays for good.
                let monitoring = std::mem::replace(&mut self.monitoring, false);
                status |= self.read();
                self.monitoring = monitoring;
                let mut cleared = Status::LIMIT_MASK | Status::ENCODER_MASK;
                if !self.inputs.estop_open {
                    cleared |= Status::ESTOP;
                }
                self.latched = self.latched & !cleared;
            }
            Ok(MsgType::WriteDigitalOutputs) => {
                status |= self.write_outputs(req.aux[0] as u32, req.aux[1] as u32);
            }
            Ok(MsgType::Exit) => {
                self.safe_state();
                self.exit_requested = true;
            }
            Ok(_) => status |= Status::BAD_MOTOR,
        }
        resp.status = (status | self.latched).0;
        resp.time_ns = self.backend.now_ns();
        resp
    }
}

/// The core is the link inside one process (tuning's evaluations, tests, benchmarks): a
/// request is handled where the iceoryx2 exchange would carry it, so the exchange never fails.
impl HwLink for HwCore {
    fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, LinkError> {
        let resp = self.handle(req);
        if let Some(why) = self.take_not_kept() {
            eprintln!("qmarc-hwserver: {why}");
        }
        Ok(resp)
    }
}

#[cfg(test)]
mod tests;
