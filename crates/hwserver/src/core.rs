//! [`HwCore`]: what the server does with each request, independent of IPC and hardware.

use crate::backend::{Backend, Inputs};
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
            enabled: [false; MAX_MOTORS],
            dacs: [0; MAX_MOTORS],
            monitoring: false,
            latched: Status::OK,
            exit_requested: false,
            homed: [false; MAX_MOTORS],
            max_counts_per_s: f64::INFINITY,
            last_read_ns: 0,
        };
        // The kept frame holds only where the counters could be read: their distance from
        // COUNTER_ZERO is the position. Without that read no motor counts as homed.
        if core.backend.read_inputs(&mut core.inputs).is_ok() {
            for m in 0..n_motors {
                core.homed[m] = core.backend.homed(m);
                core.position[m] = i64::from(counter_delta(COUNTER_ZERO, core.inputs.counters[m]));
            }
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
            eprintln!("qmarc-hwserver: {why}");
            self.homed[motor] = false;
            return Status::NOT_KEPT;
        }
        self.homed[motor] = true;
        Status::OK
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
        Ok(self.handle(req))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backends::sim::{SimDeltabot, SimParams};

    fn core_with(p: SimParams) -> HwCore {
        HwCore::new(Box::new(SimDeltabot::new(p).unwrap()))
    }

    fn core(n_motors: usize) -> HwCore {
        core_with(SimParams { n_motors, lockstep: true, ..SimParams::default() })
    }

    fn send(core: &mut HwCore, req: HwMsg) -> HwMsg {
        let resp = core.handle(&req);
        assert_eq!((resp.msg_type, resp.seq, resp.motor), (req.msg_type, req.seq, req.motor));
        resp
    }

    /// Issue 32: when the server ends, what the backend keeps is written (the simulator's
    /// event log, which the fault tests read), and a failure to write it is an error naming
    /// the file.
    #[test]
    fn finishing_writes_what_the_backend_keeps() {
        let dir = std::env::temp_dir().join(format!("qmarc-finish-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let core_logging_to = |events: &std::path::Path| {
            let s = crate::backends::test_settings(&format!(
                "[sim]\nevents_file = \"{}\"\n",
                events.display()
            ));
            HwCore::new(Box::new(SimDeltabot::open(&s, true).unwrap()))
        };
        let events = dir.join("events.csv");
        let mut core = core_logging_to(&events);
        send(&mut core, HwMsg::for_motor(MsgType::EnableMotor, 0));
        send(&mut core, HwMsg::request(MsgType::DisableAll));
        core.finish().unwrap();
        assert!(std::fs::metadata(&events).unwrap().len() > 0, "the event log written");
        let nowhere = dir.join("no-such-dir/events.csv");
        let e = core_logging_to(&nowhere).finish().unwrap_err().to_string();
        assert!(e.starts_with(&nowhere.display().to_string()), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn unknown_message_types_get_a_status_bit() {
        let mut c = core(3);
        for raw in [0, 13, 1000, u32::MAX] {
            let resp = send(&mut c, HwMsg { msg_type: raw, seq: 9, ..HwMsg::default() });
            assert_eq!(resp.status(), Status::UNKNOWN_MESSAGE);
        }
        // The bit is per response, not latched.
        assert!(send(&mut c, HwMsg::read_all_encoders()).status().is_ok());
    }

    #[test]
    fn bad_motor_indices_get_a_status_bit() {
        let mut c = core(3);
        for t in
            [MsgType::ReadEncoder, MsgType::WriteDac, MsgType::EnableMotor, MsgType::DisableMotor]
        {
            let resp = send(&mut c, HwMsg::for_motor(t, 3));
            assert_eq!(resp.status(), Status::BAD_MOTOR, "{t:?}");
        }
        assert!(!c.any_enabled());
        // Issue 32: a preset of a motor that is not there (and not "all") presets nothing.
        let before: Vec<i64> = (0..3).map(|m| c.position(m)).collect();
        let mut preset = HwMsg::for_motor(MsgType::ResetEncoderZero, 3);
        preset.data = [1234.0; MAX_MOTORS];
        assert_eq!(send(&mut c, preset).status(), Status::BAD_MOTOR);
        send(&mut c, HwMsg::read_all_encoders());
        assert_eq!((0..3).map(|m| c.position(m)).collect::<Vec<_>>(), before);
        // And a motor that is there is read and written as asked.
        for m in 0..3u32 {
            assert_eq!(
                send(&mut c, HwMsg::for_motor(MsgType::ReadEncoder, m)).status(),
                Status::OK
            );
        }
        for (code, written) in [(100, 100), (-100, -100), (-9_000, -DAC_MAX), (9_000, DAC_MAX)] {
            let mut w = HwMsg::for_motor(MsgType::WriteDac, 2);
            w.aux[2] = code;
            assert_eq!(send(&mut c, w).status(), Status::OK);
            assert_eq!(c.dacs[2], written, "WriteDac {code}");
        }
    }

    #[test]
    fn step_response_moves_the_software_position() {
        let mut c = core(2);
        send(&mut c, HwMsg::for_motor(MsgType::EnableMotor, 1));
        let mut codes = [0; MAX_MOTORS];
        codes[1] = 1000;
        send(&mut c, HwMsg::write_all_dacs(&codes));
        let mut last = 0.0;
        for _ in 0..50 {
            let resp = send(&mut c, HwMsg::read_all_encoders());
            assert!(resp.data[1] >= last);
            last = resp.data[1];
            assert_eq!(resp.data[0], 0.0, "motor 1 is disabled");
        }
        assert!(last > 100.0, "{last}");
        let resp = send(&mut c, HwMsg::for_motor(MsgType::ReadEncoder, 1));
        assert!(resp.data[1] >= last);
        // 50 + 1 reads here and the one of HwCore::new, one period each.
        assert_eq!(resp.time_ns, 52 * 400_000);
    }

    #[test]
    fn software_position_survives_counter_wrap() {
        let mut p = SimParams { n_motors: 1, lockstep: true, ..SimParams::default() };
        p.start_counts[0] = 8_388_000.0;
        p.plant.top_switch_counts = -1e9;
        p.plant.bottom_switch_counts = 1e9;
        let mut c = core_with(p);
        assert_eq!(send(&mut c, HwMsg::read_all_encoders()).data[0], 8_388_000.0);
        send(&mut c, HwMsg::for_motor(MsgType::EnableMotor, 0));
        let mut codes = [0; MAX_MOTORS];
        codes[0] = 8191;
        send(&mut c, HwMsg::write_all_dacs(&codes));
        let mut pos = 0.0;
        for _ in 0..100 {
            pos = send(&mut c, HwMsg::read_all_encoders()).data[0];
        }
        assert!(pos > 8_388_608.0, "crossed the 24-bit wrap: {pos}");
        assert_eq!(pos, c.position(0) as f64);
    }

    #[test]
    fn a_counter_jump_faster_than_physically_possible_is_an_encoder_fault() {
        let mut p = SimParams { n_motors: 2, lockstep: true, ..SimParams::default() };
        p.plant.top_switch_counts = -1e9;
        p.plant.bottom_switch_counts = 1e9;
        // 400 µs at 250 000 counts/s is 100 counts per read: the bound is 100 + 16.
        let sim = SimDeltabot::new(p).unwrap();
        let mut c = HwCore::new(Box::new(sim)).with_encoder_limit(250_000.0);
        assert!(send(&mut c, HwMsg::read_all_encoders()).status().is_ok());
        // Full speed crosses nothing: the sim cannot exceed Kv·10 V = 250 000 counts/s.
        send(&mut c, HwMsg::for_motor(MsgType::EnableMotor, 0));
        let mut codes = [0; MAX_MOTORS];
        codes[0] = 8191;
        send(&mut c, HwMsg::write_all_dacs(&codes));
        for _ in 0..200 {
            assert!(send(&mut c, HwMsg::read_all_encoders()).status().is_ok());
        }
        let before = c.position(1);
        // A glitch: motor 2's counter is reloaded behind the core's back (a cable fault).
        c.backend.load_counter(1, COUNTER_ZERO + 5_000).unwrap();
        let r = send(&mut c, HwMsg::read_all_encoders());
        assert_eq!(r.status(), Status::encoder_overflow(1));
        assert_eq!(c.position(1), before, "the jump is not believed");
        // Latched until cleared.
        assert_eq!(send(&mut c, HwMsg::read_all_encoders()).status(), Status::encoder_overflow(1));
        send(&mut c, HwMsg::request(MsgType::ClearSafetyStatus));
        assert!(send(&mut c, HwMsg::read_all_encoders()).status().is_ok());
        // Issue 32: a jump of the bound exactly is believed, one count more is not (the bound
        // as the core computes it from the lock-step period, 400 000 ns).
        let bound = (250_000.0 * (400_000.0 * 1e-9f64)).ceil() as i64 + ENCODER_SLACK_COUNTS;
        let jump = |c: &mut HwCore, by: i64| {
            let raw = c.inputs.counters[1].wrapping_add(by as u32) & qmarc_proto::COUNTER_MASK;
            c.backend.load_counter(1, raw).unwrap();
            send(c, HwMsg::read_all_encoders()).status()
        };
        let before = c.position(1);
        assert_eq!(jump(&mut c, bound), Status::OK);
        assert_eq!(c.position(1), before + bound);
        assert_eq!(jump(&mut c, -bound - 1), Status::encoder_overflow(1));
    }

    #[test]
    fn reset_zero_sets_software_position_to_zero() {
        let mut p = SimParams { n_motors: 2, lockstep: true, ..SimParams::default() };
        p.start_counts = [123.0, -77.0, 0.0, 0.0];
        let mut c = core_with(p);
        let r = send(&mut c, HwMsg::read_all_encoders());
        assert_eq!(&r.data[..2], &[123.0, -77.0]);
        send(&mut c, HwMsg::for_motor(MsgType::ResetEncoderZero, 1));
        let r = send(&mut c, HwMsg::read_all_encoders());
        assert_eq!(&r.data[..2], &[123.0, 0.0]);
        send(&mut c, HwMsg::for_motor(MsgType::ResetEncoderZero, HwMsg::ALL_MOTORS));
        let r = send(&mut c, HwMsg::read_all_encoders());
        assert_eq!(&r.data[..2], &[0.0, 0.0]);
        // A preset: the position reads data[m] there (homing sets home to 0 this way).
        let mut preset = HwMsg::for_motor(MsgType::ResetEncoderZero, HwMsg::ALL_MOTORS);
        preset.data[0] = -37.0;
        preset.data[1] = 5.4;
        send(&mut c, preset);
        let r = send(&mut c, HwMsg::read_all_encoders());
        assert_eq!(&r.data[..2], &[-37.0, 5.0]);
        assert!(MotorFlags(r.aux[0]).homed() && MotorFlags(r.aux[1]).homed());
    }

    #[test]
    fn limit_trip_latches_until_cleared_and_only_while_monitoring() {
        let mut p = SimParams { n_motors: 2, lockstep: true, ..SimParams::default() };
        p.start_counts[1] = p.plant.top_switch_counts - 1.0;
        let mut c = core_with(p);
        assert!(send(&mut c, HwMsg::read_all_encoders()).status().is_ok(), "not monitoring");
        send(&mut c, HwMsg::request(MsgType::EnableSafety));
        let r = send(&mut c, HwMsg::read_all_encoders());
        assert_eq!(r.status(), Status::limit_top(1));
        // Latched in every response, including writes.
        assert_eq!(send(&mut c, HwMsg::write_all_dacs(&[0; 4])).status(), Status::limit_top(1));
        send(&mut c, HwMsg::request(MsgType::ClearSafetyStatus));
        // Monitoring stopped at the trip (thesis 3.10.1): still on the switch, but no new bit.
        assert!(send(&mut c, HwMsg::read_all_encoders()).status().is_ok());
        send(&mut c, HwMsg::request(MsgType::EnableSafety));
        assert_eq!(send(&mut c, HwMsg::read_all_encoders()).status(), Status::limit_top(1));
        send(&mut c, HwMsg::request(MsgType::DisableSafety));
        send(&mut c, HwMsg::request(MsgType::ClearSafetyStatus));
        assert!(send(&mut c, HwMsg::read_all_encoders()).status().is_ok());
    }

    #[test]
    fn watchdog_and_shutdown_disable_and_refuse_enable() {
        let mut c = core(3);
        for m in 0..3 {
            send(&mut c, HwMsg::for_motor(MsgType::EnableMotor, m));
        }
        assert!(c.any_enabled());
        c.trip_watchdog();
        assert!(!c.any_enabled());
        let r = send(&mut c, HwMsg::for_motor(MsgType::EnableMotor, 0));
        assert!(r.status().contains(Status::WATCHDOG | Status::SHUTDOWN));
        assert!(!c.any_enabled());
        let mut c = core(1);
        c.shut_down();
        assert_eq!(send(&mut c, HwMsg::read_all_encoders()).status(), Status::SHUTDOWN);
    }

    #[test]
    fn exit_and_disable_all_leave_the_safe_state() {
        let mut c = core(3);
        send(&mut c, HwMsg::for_motor(MsgType::EnableMotor, 2));
        send(&mut c, HwMsg::request(MsgType::DisableAll));
        assert!(!c.any_enabled());
        send(&mut c, HwMsg::for_motor(MsgType::EnableMotor, 0));
        assert!(!c.exit_requested());
        assert!(send(&mut c, HwMsg::request(MsgType::Exit)).status().is_ok());
        assert!(c.exit_requested());
        assert!(!c.any_enabled());
    }
}
