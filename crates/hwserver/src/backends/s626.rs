//! [`S626`]: the Sensoray 626 through the kernel's comedi `s626` driver (thesis A.4,
//! `docs/hardware.md`, `../shared/notes/s626-comedi.md`).
//!
//! Per servo cycle two instruction lists, each one `COMEDI_INSNLIST` ioctl, built once at open
//! and reused: the read list (every motor's counter, then the DIO bank with the switches) and
//! the write list (every motor's DAC, then the DIO bank: amplifier enables and the charge
//! pump, which toggles once per write). Nothing else touches the card during a move but message
//! 13, one `INSN_BITS` under the free outputs' mask (the gripper) in a cycle it changes. DIO is
//! only ever `INSN_BITS` (never `INSN_CONFIG`, which would switch on the bank's other outputs),
//! and a write mask holds outputs only. DAC samples are computed around the exact zero
//! `0x1fff`; counters are preset with `INSN_WRITE`. An amplifier is enabled only after a read
//! and a write have both succeeded. Every way out zeroes all four DACs and drops every enable.
//!
//! `--device fake` drives [`qmarc_comedi::fake::FakeS626`] in process: the same lists against
//! a fake of the driver with a velocity-mode plant, to try the backend without a card.

use crate::backend::{Backend, BackendOpenError, FrameNotKept, HwFault, HwOp, Inputs, Outputs};
use crate::backends::state::{load_homed, save_homed};
use qmarc_comedi::list::{Insn, InsnList};
use qmarc_comedi::s626::{
    COUNTER_MASK, SUBDEV_AO, SUBDEV_COUNTER, SUBDEV_DIO0, dac_sample, layout_problem,
};
use qmarc_comedi::uapi::{INSN_READ, INSN_WRITE};
use qmarc_comedi::{Comedi, ComediOpenError, Transport};
use qmarc_config::{S626Settings, Settings};
use qmarc_proto::{MAX_MOTORS, Status};
use std::path::PathBuf;

/// The `--device` that drives the in-process fake of the card.
pub const FAKE_DEVICE: &str = "fake";

/// DAC channels of the card: all four are zeroed on every way out.
const DAC_CHANNELS: u32 = 4;

/// The wiring of the settings, per motor, resolved once.
#[derive(Debug, Clone, Copy)]
struct Wiring {
    n_motors: usize,
    dac: [u32; MAX_MOTORS],
    dac_sign: [i32; MAX_MOTORS],
    counter: [u32; MAX_MOTORS],
    counter_sign: [i32; MAX_MOTORS],
    /// The belt encoder's counter (`conveyor.counter_channel`), if one is read.
    belt: Option<u32>,
    enable: [u32; MAX_MOTORS],
    enable_bit: u32,
    top: [u32; MAX_MOTORS],
    bottom: [u32; MAX_MOTORS],
    closed_bit: u32,
    pump: Option<u32>,
    estop: Option<u32>,
    /// The outputs message 13 may write ([`S626Settings::free_outputs`]).
    free: u32,
}

impl Wiring {
    fn of(s: &S626Settings, n_motors: usize) -> Result<Wiring, BackendOpenError> {
        if let Some((key, message)) = s.wiring_problem(n_motors) {
            return Err(BackendOpenError::Invalid(format!("s626.{key}: {message}")));
        }
        let pick = |v: &[u32]| std::array::from_fn(|m| v.get(m).copied().unwrap_or(0));
        let sign = |v: &[i32]| std::array::from_fn(|m| v.get(m).copied().unwrap_or(1));
        Ok(Wiring {
            n_motors,
            dac: pick(&s.dac_channels),
            dac_sign: sign(&s.dac_sign),
            counter: pick(&s.counter_channels),
            counter_sign: sign(&s.counter_sign),
            belt: None,
            enable: pick(&s.enable_dio),
            enable_bit: s.enable_bit,
            top: pick(&s.limit_top_dio),
            bottom: pick(&s.limit_bottom_dio),
            closed_bit: s.switch_closed_bit,
            pump: s.charge_pump_dio,
            estop: s.estop_dio,
            free: s.free_outputs(n_motors),
        })
    }

    /// The DIO channels the backend writes: the enables (and the charge pump).
    fn enable_mask(&self) -> u32 {
        self.enable[..self.n_motors].iter().fold(0, |m, &c| m | 1 << c)
    }

    /// The enable bits for `enabled`, under [`Wiring::enable_mask`].
    fn enable_bits(&self, enabled: &[bool; MAX_MOTORS]) -> u32 {
        (0..self.n_motors).fold(0, |bits, m| {
            let on = if enabled[m] { self.enable_bit } else { 1 - self.enable_bit };
            bits | on << self.enable[m]
        })
    }
}

/// The Sensoray 626 backend.
pub struct S626 {
    transport: Box<dyn Transport>,
    w: Wiring,
    read: InsnList,
    write: InsnList,
    enables: InsnList,
    /// Message 13's list: DIO bank 0 under the free outputs' mask.
    outputs: InsnList,
    safe: InsnList,
    /// The safe list's instructions one by one, for when the list fails part-way.
    safe_singles: Vec<InsnList>,
    presets: Vec<InsnList>,
    enabled: [bool; MAX_MOTORS],
    dac: [i32; MAX_MOTORS],
    pump_level: u32,
    pump_running: bool,
    read_ok: bool,
    write_ok: bool,
    homed: [bool; MAX_MOTORS],
    state_file: Option<PathBuf>,
    /// What the kept frame belongs to ([`card_identity`]).
    identity: String,
}

/// What an ioctl error or a short list becomes: a [`HwFault`] of operation `op`.
fn ran(result: Result<usize, nix::errno::Errno>, len: usize, op: HwOp) -> Result<(), HwFault> {
    match result {
        Ok(n) if n == len => Ok(()),
        Ok(n) => Err(HwFault { op, code: -(n as i32) - 1 }),
        Err(e) => Err(HwFault { op, code: e as i32 }),
    }
}

impl S626 {
    /// The card of the settings `s` (`s626.device`; [`FAKE_DEVICE`] for the fake), checked to
    /// be a 626 as its driver presents it, its subdevices locked for this process.
    pub fn open(s: &Settings, lockstep: bool) -> Result<S626, BackendOpenError> {
        if lockstep {
            return Err(lockstep_refused());
        }
        let device = s.s626.device.display().to_string();
        if device == FAKE_DEVICE {
            let fake = fake_card(s);
            return S626::with_transport(Box::new(fake), &device, &s.s626, s.n_motors, None)
                .map(|c| c.all_homed().with_belt_counter(s.conveyor.counter_channel));
        }
        let card = Comedi::open(&s.s626.device).map_err(open_error)?;
        S626::with_transport(Box::new(card), &device, &s.s626, s.n_motors, Some(state_file(s)))
            .map(|c| c.with_belt_counter(s.conveyor.counter_channel))
    }

    /// Reads the belt's encoder on `channel` too, in the same instruction list as the motors'
    /// counters (the settings' check keeps it off theirs).
    pub fn with_belt_counter(mut self, channel: u32) -> S626 {
        self.w.belt = Some(channel);
        self.read = read_list(&self.w);
        self
    }

    /// Checks, without writing anything or keeping the card, that the settings can drive it
    /// (the starter's check before it spawns anything, so a bad set-up fails at once): the
    /// wiring holds, the device opens and is a 626, the homed frame can be kept, and the
    /// settings are in the card's counts ([`Settings::s626_counts_problem`]).
    pub fn check(s: &Settings, lockstep: bool) -> Result<(), BackendOpenError> {
        if lockstep {
            return Err(lockstep_refused());
        }
        Wiring::of(&s.s626, s.n_motors)?;
        let device = s.s626.device.display().to_string();
        if device != FAKE_DEVICE {
            if let Some(key) = injected_fault(s) {
                return Err(BackendOpenError::Invalid(format!(
                    "sim.{key} is the simulator's fault injection, for the simulated robot and \
                     the fake card (--device fake): not on the card {device}; set it off"
                )));
            }
            S626::check_card(s, &device)?;
        } else if s.sim.plant.estop_open_s.is_some() && s.s626.estop_dio.is_none() {
            return Err(BackendOpenError::Invalid(
                "sim.estop_open_s: the fake card sees the emergency-stop chain only on its \
                 input, [s626] estop_dio, which is -1 (none): wire it (config/s626.toml has \
                 DIO5) to rehearse the e-stop"
                    .into(),
            ));
        }
        match s.s626_counts_problem() {
            Some(problem) => Err(BackendOpenError::Invalid(problem)),
            None => Ok(()),
        }
    }

    /// The card of `device` opens, is a 626, and its homed frame can be kept.
    fn check_card(s: &Settings, device: &str) -> Result<(), BackendOpenError> {
        let mut card = Comedi::open(&s.s626.device).map_err(open_error)?;
        let io = |e: nix::errno::Errno| BackendOpenError::Device {
            device: device.to_string(),
            reason: e.to_string(),
        };
        let info = card.devinfo().map_err(io)?;
        let subs = card.subdinfo(info.n_subdevs).map_err(io)?;
        if let Some(problem) = layout_problem(device, &info, &subs) {
            return Err(BackendOpenError::Invalid(problem));
        }
        check_state_dir(s)
    }

    /// The backend over `transport`, which must present a 626; the homed frame is read from
    /// `state_file` (none: nothing homed, nothing kept).
    pub fn with_transport(
        mut transport: Box<dyn Transport>,
        device: &str,
        settings: &S626Settings,
        n_motors: usize,
        state_file: Option<PathBuf>,
    ) -> Result<S626, BackendOpenError> {
        let w = Wiring::of(settings, n_motors)?;
        let io = |e: nix::errno::Errno| BackendOpenError::Device {
            device: device.to_string(),
            reason: e.to_string(),
        };
        let info = transport.devinfo().map_err(io)?;
        let subs = transport.subdinfo(info.n_subdevs).map_err(io)?;
        if let Some(problem) = layout_problem(device, &info, &subs) {
            return Err(BackendOpenError::Invalid(problem));
        }
        for subdev in [SUBDEV_AO, SUBDEV_DIO0, SUBDEV_COUNTER] {
            transport.lock(subdev).map_err(|e| BackendOpenError::Device {
                device: device.to_string(),
                reason: format!(
                    "cannot lock subdevice {subdev} ({e}): another process uses the card"
                ),
            })?;
        }
        let identity = card_identity(device, settings);
        let homed = state_file
            .as_deref()
            .map_or([false; MAX_MOTORS], |p| load_homed(p, n_motors, &identity));
        let mut card = S626 {
            transport,
            read: read_list(&w),
            write: write_list(&w),
            enables: InsnList::new(&[Insn::bits(SUBDEV_DIO0)]),
            outputs: InsnList::new(&[Insn::bits(SUBDEV_DIO0)]),
            safe: safe_list(),
            safe_singles: safe_singles(),
            presets: (0..n_motors)
                .map(|m| InsnList::new(&[Insn::one(INSN_WRITE, SUBDEV_COUNTER, w.counter[m])]))
                .collect(),
            w,
            enabled: [false; MAX_MOTORS],
            dac: [0; MAX_MOTORS],
            pump_level: 0,
            pump_running: true,
            read_ok: false,
            write_ok: false,
            homed,
            state_file,
            identity,
        };
        // The driver leaves the outputs at 0 after attach: active-low amplifiers
        // (`enable_bit` 0) would read that as enabled. Off and at 0 V from the start.
        card.safe_state();
        card.write_ok = false; // the write list itself has not answered yet
        Ok(card)
    }

    fn all_homed(mut self) -> S626 {
        self.homed = [true; MAX_MOTORS];
        self
    }

    /// Runs the read list once (counters and switches): the selftest's unit of work.
    pub fn run_read_list(&mut self) -> Result<(), HwFault> {
        let mut inputs = Inputs::default();
        self.read_inputs(&mut inputs)
    }

    /// Runs the write list once with every DAC at 0 V and every amplifier as it is (off in
    /// the selftest): its other unit of work.
    pub fn run_write_list(&mut self) -> Result<(), HwFault> {
        self.write_dacs(&[0; MAX_MOTORS])
    }

    /// [`oriented`] for `motor`'s counting direction.
    fn oriented(&self, motor: usize, raw: u32) -> u32 {
        oriented(self.w.counter_sign[motor], raw)
    }
}

/// The counter sample of a raw 24-bit count, or the count of a sample, for a counter that
/// counts in direction `sign` (the same map both ways).
fn oriented(sign: i32, raw: u32) -> u32 {
    if sign < 0 { raw.wrapping_neg() & COUNTER_MASK } else { raw }
}

/// Why `--deterministic` cannot drive the card: lock-step time is the simulator's.
fn lockstep_refused() -> BackendOpenError {
    BackendOpenError::Invalid(
        "--deterministic runs the simulated robot only: the 626 moves in real time".into(),
    )
}

/// The read list: every motor's counter, the belt's, then DIO bank 0 read (mask 0: nothing
/// written).
fn read_list(w: &Wiring) -> InsnList {
    let mut items: Vec<Insn> =
        (0..w.n_motors).map(|m| Insn::one(INSN_READ, SUBDEV_COUNTER, w.counter[m])).collect();
    items.extend(w.belt.map(|c| Insn::one(INSN_READ, SUBDEV_COUNTER, c)));
    items.push(Insn::bits(SUBDEV_DIO0));
    InsnList::new(&items)
}

/// The write list: every motor's DAC, then DIO bank 0 with the enables and the charge pump.
fn write_list(w: &Wiring) -> InsnList {
    let mut items: Vec<Insn> =
        (0..w.n_motors).map(|m| Insn::one(INSN_WRITE, SUBDEV_AO, w.dac[m])).collect();
    items.push(Insn::bits(SUBDEV_DIO0));
    InsnList::new(&items)
}

/// The safe list's instructions, one list each (the DACs' samples set: 0 V).
fn safe_singles() -> Vec<InsnList> {
    let mut singles = vec![InsnList::new(&[Insn::bits(SUBDEV_DIO0)])];
    singles.extend((0..DAC_CHANNELS).map(|c| {
        let mut one = InsnList::new(&[Insn::one(INSN_WRITE, SUBDEV_AO, c)]);
        one.data_mut(0)[0] = dac_sample(0);
        one
    }));
    singles
}

/// The safe list: DIO bank 0 with every enable off first (the kernel stops a list at the
/// first instruction that fails: the enables must not wait behind a DAC), then all four DACs
/// at 0 V.
fn safe_list() -> InsnList {
    let mut items = vec![Insn::bits(SUBDEV_DIO0)];
    items.extend((0..DAC_CHANNELS).map(|c| Insn::one(INSN_WRITE, SUBDEV_AO, c)));
    let mut list = InsnList::new(&items);
    for c in 1..=DAC_CHANNELS as usize {
        list.data_mut(c)[0] = dac_sample(0);
    }
    list
}

/// Where the settings' card keeps its homed frame: `<state_dir>/s626-<device name>.state`.
pub fn state_file(s: &Settings) -> PathBuf {
    let device = &s.s626.device;
    let name = device.file_name().map_or_else(|| "card".into(), |n| n.to_string_lossy());
    s.s626.state_dir.join(format!("s626-{name}.state"))
}

/// What a kept frame belongs to: the device node (a reloaded driver makes a new one, with
/// counters reset) and the counters and their directions.
pub fn card_identity(device: &str, w: &S626Settings) -> String {
    use std::os::unix::fs::MetadataExt;
    let node = std::fs::metadata(device).map_or_else(
        |_| "?".into(),
        |m| format!("ino {} ctime {}.{}", m.ino(), m.ctime(), m.ctime_nsec()),
    );
    format!("{device} {node} counters {:?} signs {:?}", w.counter_channels, w.counter_sign)
}

/// Checks that the homed frame can be kept in `[s626] state_dir` (made if missing): without
/// it a homing would be forgotten at once and every move refused as unhomed.
fn check_state_dir(s: &Settings) -> Result<(), BackendOpenError> {
    let dir = &s.s626.state_dir;
    crate::backends::state::check_folder(dir).map_err(|e| {
        BackendOpenError::Invalid(format!(
            "{}: cannot keep the homed frame there ({e}): create it for the card's group \
             (`sudo install -d -m 2770 -g iocard {}`, or the tmpfiles.d line of \
             docs/hardware.md), or set [s626] state_dir",
            dir.display(),
            dir.display()
        ))
    })
}

/// The open error of a device (its message names the device and says what to do).
fn open_error(e: ComediOpenError) -> BackendOpenError {
    BackendOpenError::Invalid(e.to_string())
}

impl Backend for S626 {
    fn name(&self) -> &'static str {
        "s626"
    }

    fn n_motors(&self) -> usize {
        self.w.n_motors
    }

    fn read_inputs(&mut self, inputs: &mut Inputs) -> Result<(), HwFault> {
        let n = self.w.n_motors;
        let belt = usize::from(self.w.belt.is_some());
        let done = ran(self.transport.run(&mut self.read), n + belt + 1, HwOp::ReadInputs);
        self.read_ok = done.is_ok();
        done?;
        for m in 0..n {
            inputs.counters[m] = self.oriented(m, self.read.data(m)[0] & COUNTER_MASK);
        }
        if belt == 1 {
            inputs.belt = self.read.data(n)[0] & COUNTER_MASK;
        }
        let pins = self.read.data(n + belt)[1];
        let tripped = |chan: u32| (pins >> chan) & 1 != self.w.closed_bit;
        let mut limits = Status::OK;
        for m in 0..n {
            if tripped(self.w.top[m]) {
                limits |= Status::limit_top(m);
            }
            if tripped(self.w.bottom[m]) {
                limits |= Status::limit_bottom(m);
            }
        }
        inputs.limits = limits;
        inputs.estop_open = self.w.estop.is_some_and(tripped);
        inputs.outputs = pins & self.w.free;
        Ok(())
    }

    fn write_dacs(&mut self, codes: &[i32; MAX_MOTORS]) -> Result<(), HwFault> {
        let n = self.w.n_motors;
        for (m, &code) in codes.iter().enumerate().take(n) {
            self.write.data_mut(m)[0] = dac_sample(self.w.dac_sign[m] * code);
        }
        let mut mask = self.w.enable_mask();
        let mut bits = self.w.enable_bits(&self.enabled);
        if let Some(pump) = self.w.pump {
            self.pump_level ^= u32::from(self.pump_running);
            mask |= 1 << pump;
            bits |= (self.pump_level & u32::from(self.pump_running)) << pump;
        }
        self.write.data_mut(n).copy_from_slice(&[mask, bits]);
        let done = ran(self.transport.run(&mut self.write), n + 1, HwOp::WriteDacs);
        self.write_ok = done.is_ok();
        done?;
        self.dac[..n].copy_from_slice(&codes[..n]);
        Ok(())
    }

    fn set_amp_enable(&mut self, motor: usize, on: bool) -> Result<(), HwFault> {
        if on && !(self.read_ok && self.write_ok) {
            // Never power a motor before the card has answered a read and a write.
            return Err(HwFault { op: HwOp::Enable, code: nix::errno::Errno::EAGAIN as i32 });
        }
        self.enabled[motor] = on;
        let mask = self.w.enable_mask();
        let bits = self.w.enable_bits(&self.enabled);
        self.enables.data_mut(0).copy_from_slice(&[mask, bits]);
        let result = self.transport.run(&mut self.enables);
        if result != Ok(1) {
            self.enabled[motor] = false;
        }
        ran(result, 1, HwOp::Enable)
    }

    fn load_counter(&mut self, motor: usize, raw: u32) -> Result<(), HwFault> {
        let sample = self.oriented(motor, raw & COUNTER_MASK);
        let preset = &mut self.presets[motor];
        preset.data_mut(0)[0] = sample;
        ran(self.transport.run(preset), 1, HwOp::LoadCounter)
    }

    fn free_outputs(&self) -> u32 {
        self.w.free
    }

    /// One `INSN_BITS` under `mask` (free outputs only: never an input, an enable or the
    /// pump); the driver keeps the bank's other outputs as they are.
    fn write_outputs(&mut self, mask: u32, values: u32) -> Result<(), HwFault> {
        let mask = mask & self.w.free;
        self.outputs.data_mut(0).copy_from_slice(&[mask, values & mask]);
        ran(self.transport.run(&mut self.outputs), 1, HwOp::WriteOutputs)
    }

    fn safe_state(&mut self) {
        self.enabled = [false; MAX_MOTORS];
        self.dac = [0; MAX_MOTORS];
        let mut mask = self.w.enable_mask();
        if let Some(pump) = self.w.pump {
            mask |= 1 << pump; // the pump pin held low: the relay drops
            self.pump_level = 0;
        }
        let bits = self.w.enable_bits(&self.enabled);
        self.safe.data_mut(0).copy_from_slice(&[mask, bits]);
        let whole = self.transport.run(&mut self.safe) == Ok(self.safe.len());
        if !whole {
            // Part of it failed: every instruction on its own, each as far as it goes.
            self.safe_singles[0].data_mut(0).copy_from_slice(&[mask, bits]);
            for one in &mut self.safe_singles {
                let _ = self.transport.run(one);
            }
        }
        self.write_ok = whole;
    }

    fn now_ns(&self) -> u64 {
        qmarc_timer::clock::monotonic_now_ns()
    }

    fn stop_charge_pump(&mut self) {
        self.pump_running = false;
    }

    fn homed(&self, motor: usize) -> bool {
        self.homed[motor]
    }

    fn set_homed(&mut self, motor: usize) -> Result<(), FrameNotKept> {
        self.homed[motor] = true;
        if let Some(path) = &self.state_file
            && let Err(e) = save_homed(path, &self.homed[..self.w.n_motors], &self.identity)
        {
            // Rare (the starter checked the folder): a failed home, not a hidden one.
            self.homed[motor] = false;
            return Err(FrameNotKept {
                motor: motor + 1,
                path: path.clone(),
                key: "s626.state_dir",
                reason: e.to_string(),
            });
        }
        Ok(())
    }

    /// What the backend last wrote (the card reads the DACs back the same).
    fn outputs(&self) -> Option<Outputs> {
        Some(Outputs { dac: self.dac, enabled: self.enabled })
    }
}

impl Drop for S626 {
    fn drop(&mut self) {
        // Best effort: nothing resets the DACs when the process is gone.
        self.safe_state();
    }
}

/// The simulator's fault injection the settings turn on, if any (its `[sim]` key): the fake
/// card plays each; a real card can play none.
fn injected_fault(s: &Settings) -> Option<&'static str> {
    let p = &s.sim.plant;
    [
        ("stall_motor", p.stall_motor.is_some()),
        ("stuck_top_motor", p.stuck_top_motor.is_some()),
        ("reversed_motor", p.reversed_motor.is_some()),
        ("estop_open_s", p.estop_open_s.is_some()),
    ]
    .into_iter()
    .find_map(|(key, on)| on.then_some(key))
}

mod fake;
#[cfg(test)]
use fake::SharedFake;
pub use fake::{FakePlant, FakeRig, fake_card, wired_fake};

#[cfg(test)]
mod tests;
