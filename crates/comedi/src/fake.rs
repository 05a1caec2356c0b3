//! [`FakeS626`]: the Sensoray 626 and its `s626` driver in process, following the driver's
//! rules (`../shared/notes/s626-comedi.md`), for the tests and for trying the backend without
//! a card (`--device fake`).
//!
//! - The subdevices of [`crate::s626::LAYOUT`]; devinfo says `s626`.
//! - AO: `INSN_WRITE` stores the sample, the output is `sample − 0x1fff` sign-magnitude with
//!   its magnitude clamped to `0x1fff`; `INSN_READ` reads back the last sample written.
//! - Counters: 24 bits; `INSN_READ` returns the live count, `INSN_WRITE` preloads it.
//!   `INSN_CONFIG` is refused (`EINVAL`), as the driver does for many values.
//! - DIO: `INSN_BITS` writes `data[1]` under the mask `data[0]` into the output register and
//!   returns in `data[1]` the state of every pin, a pin pulled to 0 V reading 1 (an output
//!   written 1 drives its pin to 0 V; a switch closed to ground pulls an input low). The
//!   driver's hazard is there too: `INSN_CONFIG` writes the direction mask (initially all
//!   ones) into the output register, turning on the bank's other outputs — and is counted.
//! - Errors on demand ([`FakeS626::fail_next`]): an errno, or a list cut short.
//! - A plant, when motors are wired to it ([`FakeS626::wire`]): a velocity-mode amplifier per
//!   motor, whose motor follows `counts_per_s_per_volt` × its DAC's volts while its enable
//!   output is on — at once, or through a first-order velocity lag — and coasts to rest
//!   when it is off, advancing one servo period per list that reads counters. The motor has a
//!   position of its own, in counts; its counter reads the position plus what a preload set,
//!   so a preload moves the counter's frame, not the motor. Limit switches wired to the plant
//!   ([`SwitchWire`]) open where the motor passes them, as normally-closed switches do.
//!
//! Nothing here allocates after construction.

use crate::device::{DevInfo, SubdInfo, Transport};
use crate::list::InsnList;
use crate::s626::{COUNTER_MASK, LAYOUT, SUBDEV_AO, SUBDEV_COUNTER, SUBDEV_DIO0, dac_volts};
use crate::uapi::{INSN_BITS, INSN_CONFIG, INSN_READ, INSN_WRITE};
use nix::errno::Errno;

/// How a motor of the plant is wired.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Wire {
    /// Its DAC channel.
    pub dac: u32,
    /// Its counter channel.
    pub counter: u32,
    /// Its amplifier's enable output (DIO bank 0).
    pub enable_dio: u32,
    /// The output bit that enables it.
    pub enable_bit: u32,
    /// Counting speed per volt of command while enabled, counts/s.
    pub counts_per_s_per_volt: f64,
    /// The amplifier's velocity loop as a first-order lag, s; 0: the motor follows its
    /// command at once.
    pub lag_s: f64,
    /// The motor's top limit switch, if the plant drives it.
    pub top: Option<SwitchWire>,
    /// The motor's bottom limit switch, if the plant drives it.
    pub bottom: Option<SwitchWire>,
}

/// A limit switch on a motor's travel: closed until the motor reaches `at_counts` going
/// `toward` (+1: up in counts, −1: down), open beyond, as a normally-closed switch is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SwitchWire {
    /// Its input, DIO bank 0.
    pub dio: u32,
    /// Where it trips, counts of the motor's position.
    pub at_counts: f64,
    /// The direction of travel that trips it: +1 or −1.
    pub toward: f64,
    /// A closed switch pulls its input to 0 V (wired to ground, reading 1); else it leaves
    /// it open when closed and pulls it low when tripped.
    pub closed_low: bool,
    /// Once tripped it stays open, wherever the motor goes (a stuck switch: fault injection).
    pub sticks: bool,
}

impl SwitchWire {
    /// Whether a motor at `position` holds it open (tripped).
    pub fn tripped(&self, position: f64) -> bool {
        (position - self.at_counts) * self.toward >= 0.0
    }
}

/// How long a disabled motor of the plant takes to coast to rest, s (its time constant).
const COAST_TAU_S: f64 = 0.05;

/// A failure the next list meets.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Failure {
    /// The first `done` instructions complete, then the ioctl fails with `errno` — what the
    /// kernel's `do_insnlist_ioctl` does when an instruction fails (it reports no count).
    ErrnoAfter {
        /// Instructions that complete before the failure.
        done: usize,
        /// The errno the ioctl returns.
        errno: Errno,
    },
    /// Only the first `n` instructions complete and the ioctl returns `n` (not what this
    /// kernel does; a backend must treat it as a failure all the same).
    Short(usize),
}

/// Most instructions of one list the fake remembers ([`FakeS626::last_list`]).
pub const REMEMBERED: usize = 16;

/// The fake card and driver.
#[derive(Debug, Clone)]
pub struct FakeS626 {
    driver: &'static str,
    layout: [SubdInfo; 6],
    ao: [u32; 4],
    dio_out: [u32; 3],
    dio_dir: [u32; 3],
    external_low: [u32; 3],
    /// What each counter adds to its motor's whole counts (a preload sets it).
    counter_base: [u32; 6],
    /// Each counter channel's motor: position (counts) and velocity (counts/s).
    position: [f64; 6],
    velocity: [f64; 6],
    locked: u32,
    fail: Option<Failure>,
    runs: u64,
    dio_configs: u64,
    masks_written: u32,
    last: [(u32, u32, u32); REMEMBERED],
    last_len: usize,
    plant: [Option<Wire>; 4],
    period_s: f64,
    /// The plant's time, s: one period per list that reads counters.
    elapsed_s: f64,
    /// Inputs of sticking switches that have tripped (DIO bank 0 bits).
    stuck_open: u32,
    /// An input opened for a while (fault injection): its DIO, whether closed pulls it low,
    /// and from when to when of the plant's time it is open, s.
    opens: Option<(u32, bool, [f64; 2])>,
}

impl Default for FakeS626 {
    fn default() -> FakeS626 {
        FakeS626::new()
    }
}

impl FakeS626 {
    /// A 626 as the driver leaves it after attach: DACs at 0 V, outputs off, counters at 0,
    /// every switch input open (nothing pulls a pin low), no motor wired.
    pub fn new() -> FakeS626 {
        let layout = LAYOUT.map(|(_, kind, n_chan, maxdata)| SubdInfo { kind, n_chan, maxdata });
        FakeS626 {
            driver: crate::s626::DRIVER,
            layout,
            ao: [crate::s626::DAC_ZERO; 4],
            dio_out: [0; 3],
            dio_dir: [0xffff; 3],
            external_low: [0; 3],
            counter_base: [0; 6],
            position: [0.0; 6],
            velocity: [0.0; 6],
            locked: 0,
            fail: None,
            runs: 0,
            dio_configs: 0,
            masks_written: 0,
            last: [(0, 0, 0); REMEMBERED],
            last_len: 0,
            plant: [None; 4],
            period_s: 400e-6,
            elapsed_s: 0.0,
            stuck_open: 0,
            opens: None,
        }
    }

    /// Opens input `chan` (a normally-closed chain: closed, it is pulled low if
    /// `closed_low`) from `during[0]` to `during[1]` s of the plant's time, closed before and
    /// after — an emergency-stop button pressed, then released.
    pub fn open_input_during(&mut self, chan: u32, closed_low: bool, during: [f64; 2]) {
        self.opens = Some((chan, closed_low, during));
        self.update_inputs();
    }

    /// The same, but its devinfo names `driver` (a device that is not a 626).
    pub fn with_driver(mut self, driver: &'static str) -> FakeS626 {
        self.driver = driver;
        self
    }

    /// The same, with subdevice `idx` described as `info`.
    pub fn with_subdevice(mut self, idx: usize, info: SubdInfo) -> FakeS626 {
        self.layout[idx] = info;
        self
    }

    /// Wires `motor` (0‥3) of the plant; the plant advances `period_s` per list that reads
    /// counters. Its switches are set for where the motor is.
    pub fn wire(&mut self, motor: usize, wire: Wire, period_s: f64) {
        self.plant[motor] = Some(wire);
        self.period_s = period_s;
        self.update_inputs();
    }

    /// Puts the motor of counter `chan` at `position` counts, at rest, its counter reading
    /// what it read (the frame moves with it: as if it had been moved with the card off).
    pub fn place(&mut self, chan: usize, position: f64) {
        let count = self.counter(chan);
        self.position[chan] = position;
        self.velocity[chan] = 0.0;
        self.set_counter(chan, count);
        self.update_inputs();
    }

    /// Where the motor of counter `chan` is, counts.
    pub fn position(&self, chan: usize) -> f64 {
        self.position[chan]
    }

    /// Sets whether something outside pulls DIO `chan` of bank 0 to 0 V (a switch closed to
    /// ground) or leaves it open (a tripped normally-closed switch, a broken wire).
    pub fn set_input_low(&mut self, chan: u32, low: bool) {
        let bit = 1 << chan;
        if low { self.external_low[0] |= bit } else { self.external_low[0] &= !bit }
    }

    /// Sets counter `chan` to `count` (24 bits), wherever its motor is.
    pub fn set_counter(&mut self, chan: usize, count: u32) {
        self.counter_base[chan] = count.wrapping_sub(self.whole_counts(chan));
    }

    /// The whole counts of the motor of counter `chan`, as a counter adds them (wrapping).
    fn whole_counts(&self, chan: usize) -> u32 {
        self.position[chan].floor() as i64 as u32
    }

    /// The next list meets `failure`.
    pub fn fail_next(&mut self, failure: Failure) {
        self.fail = Some(failure);
    }

    /// Lists run so far (one system call each on the real device).
    pub fn runs(&self) -> u64 {
        self.runs
    }

    /// `INSN_CONFIG` instructions on a DIO subdevice so far (the driver's hazard).
    pub fn dio_configs(&self) -> u64 {
        self.dio_configs
    }

    /// Every DIO bank 0 channel any `INSN_BITS` mask ever wrote.
    pub fn masks_written(&self) -> u32 {
        self.masks_written
    }

    /// `(insn, subdev, channel)` of the last list's instructions, in order.
    pub fn last_list(&self) -> &[(u32, u32, u32)] {
        &self.last[..self.last_len]
    }

    /// The volts DAC `chan` outputs now.
    pub fn dac_volts(&self, chan: usize) -> f64 {
        dac_volts(self.ao[chan])
    }

    /// Whether DIO `chan` of bank 0 is at 0 V now (an output written 1, or pulled low).
    pub fn pin_low(&self, chan: u32) -> bool {
        ((self.dio_out[0] | self.external_low[0]) >> chan) & 1 == 1
    }

    /// The output register of DIO bank 0.
    pub fn outputs(&self) -> u32 {
        self.dio_out[0]
    }

    /// Counter `chan` now.
    pub fn counter(&self, chan: usize) -> u32 {
        self.counter_base[chan].wrapping_add(self.whole_counts(chan)) & COUNTER_MASK
    }

    /// The plant: one period of every wired motor. Enabled, it follows its amplifier's
    /// command (through the lag, if any); disabled, it coasts to rest. Both are the exact
    /// first-order solution for a command held over the period.
    fn advance(&mut self) {
        let dt = self.period_s;
        for w in self.plant.iter().flatten() {
            let on = (self.dio_out[0] >> w.enable_dio) & 1 == w.enable_bit;
            let (target, tau) = match on {
                true => (w.counts_per_s_per_volt * dac_volts(self.ao[w.dac as usize]), w.lag_s),
                false => (0.0, COAST_TAU_S),
            };
            let c = w.counter as usize;
            if tau > 0.0 {
                // v → target with time constant τ; x gains ∫v over the period.
                let decay = (-dt / tau).exp();
                let dv = self.velocity[c] - target;
                self.position[c] += target * dt + dv * tau * (1.0 - decay);
                self.velocity[c] = target + dv * decay;
            } else {
                self.position[c] += target * dt;
                self.velocity[c] = target;
            }
        }
        self.elapsed_s += dt;
        self.update_inputs();
    }

    /// Opens and closes the switches the plant drives, for where their motors are (a
    /// sticking one stays open once tripped), and an input opened for a while.
    fn update_inputs(&mut self) {
        for w in self.plant {
            let Some(w) = w else { continue };
            for s in [w.top, w.bottom].into_iter().flatten() {
                let bit = 1 << s.dio;
                if s.sticks && s.tripped(self.position[w.counter as usize]) {
                    self.stuck_open |= bit;
                }
                let closed =
                    !s.tripped(self.position[w.counter as usize]) && self.stuck_open & bit == 0;
                self.set_input_low(s.dio, closed == s.closed_low);
            }
        }
        if let Some((chan, closed_low, [from, to])) = self.opens {
            let open = (from..to).contains(&self.elapsed_s);
            self.set_input_low(chan, closed_low != open);
        }
    }

    /// One instruction (`data`: its samples).
    fn execute(
        &mut self,
        insn: u32,
        subdev: u32,
        chan: u32,
        data: &mut [u32],
    ) -> Result<(), Errno> {
        let info = self.layout.get(subdev as usize).ok_or(Errno::EINVAL)?;
        if chan >= info.n_chan || data.is_empty() {
            return Err(Errno::EINVAL);
        }
        let c = chan as usize;
        // The comedi core refuses a sample above the subdevice's largest.
        if insn == INSN_WRITE && data[0] > info.maxdata {
            return Err(Errno::EINVAL);
        }
        match (subdev, insn) {
            (SUBDEV_AO, INSN_WRITE) => self.ao[c] = data[0],
            (SUBDEV_AO, INSN_READ) => data[0] = self.ao[c],
            (SUBDEV_COUNTER, INSN_READ) => data[0] = self.counter(c),
            (SUBDEV_COUNTER, INSN_WRITE) => self.set_counter(c, data[0]),
            (2..=4, INSN_BITS) if data.len() == 2 => {
                let bank = (subdev - SUBDEV_DIO0) as usize;
                let mask = data[0] & 0xffff;
                self.dio_out[bank] = (self.dio_out[bank] & !mask) | (data[1] & mask);
                if bank == 0 {
                    self.masks_written |= mask;
                }
                data[1] = self.dio_out[bank] | self.external_low[bank];
            }
            (2..=4, INSN_CONFIG) => {
                // s626_dio_insn_config: the direction mask goes into the output register.
                let bank = (subdev - SUBDEV_DIO0) as usize;
                match data[0] {
                    0 => self.dio_dir[bank] &= !(1 << chan),
                    1 => self.dio_dir[bank] |= 1 << chan,
                    _ => return Err(Errno::EINVAL),
                }
                self.dio_out[bank] = self.dio_dir[bank];
                self.dio_configs += 1;
            }
            _ => return Err(Errno::EINVAL),
        }
        Ok(())
    }
}

impl Transport for FakeS626 {
    fn devinfo(&mut self) -> Result<DevInfo, Errno> {
        Ok(DevInfo { driver: self.driver.to_string(), board: "fake".into(), n_subdevs: 6 })
    }

    fn subdinfo(&mut self, n_subdevs: usize) -> Result<Vec<SubdInfo>, Errno> {
        Ok(self.layout.iter().take(n_subdevs).copied().collect())
    }

    fn lock(&mut self, subdev: u32) -> Result<(), Errno> {
        let bit = 1u32.checked_shl(subdev).ok_or(Errno::EINVAL)?;
        if self.locked & bit != 0 {
            return Err(Errno::EBUSY);
        }
        self.locked |= bit;
        Ok(())
    }

    fn run(&mut self, list: &mut InsnList) -> Result<usize, Errno> {
        self.runs += 1;
        let (limit, then) = match self.fail.take() {
            Some(Failure::ErrnoAfter { done, errno }) => (done.min(list.len()), Some(errno)),
            Some(Failure::Short(n)) => (n.min(list.len()), None),
            None => (list.len(), None),
        };
        let reads_counters = (0..list.len())
            .any(|i| list.insn(i).subdev == SUBDEV_COUNTER && list.insn(i).insn == INSN_READ);
        if reads_counters {
            self.advance();
        }
        self.last_len = list.len().min(REMEMBERED);
        for i in 0..limit {
            let (insn, subdev, chan) = {
                let h = list.insn(i);
                (h.insn, h.subdev, h.chanspec & 0xffff)
            };
            if i < REMEMBERED {
                self.last[i] = (insn, subdev, chan);
            }
            self.execute(insn, subdev, chan, list.data_mut(i))?;
        }
        match then {
            Some(errno) => Err(errno),
            None => Ok(limit),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::list::Insn;

    #[test]
    fn configuring_one_dio_input_turns_on_the_other_outputs_of_its_bank() {
        let mut fake = FakeS626::new();
        let mut config = InsnList::new(&[Insn::one(INSN_CONFIG, SUBDEV_DIO0, 9)]);
        config.data_mut(0)[0] = 0; // COMEDI_INPUT
        fake.run(&mut config).unwrap();
        assert_eq!(fake.outputs(), 0xffff & !(1 << 9), "15 outputs on: the hazard");
        assert_eq!(fake.dio_configs(), 1);
    }

    #[test]
    fn bits_write_under_the_mask_and_read_pins_pulled_low_as_one() {
        let mut fake = FakeS626::new();
        fake.set_input_low(9, true); // a closed switch to ground
        let mut bits = InsnList::new(&[Insn::bits(SUBDEV_DIO0)]);
        bits.data_mut(0).copy_from_slice(&[0b1011, 0b0011]);
        assert_eq!(fake.run(&mut bits), Ok(1));
        assert_eq!(fake.outputs(), 0b0011, "bit 3 written 0 under the mask");
        assert_eq!(bits.data(0)[1], 0b0011 | 1 << 9);
        bits.data_mut(0).copy_from_slice(&[0, 0]);
        fake.run(&mut bits).unwrap();
        assert_eq!(fake.outputs(), 0b0011, "a zero mask reads only");
    }

    #[test]
    fn counters_wrap_at_24_bits_and_preload_with_write() {
        let mut fake = FakeS626::new();
        let mut list = InsnList::new(&[
            Insn::one(INSN_WRITE, SUBDEV_COUNTER, 1),
            Insn::one(INSN_READ, SUBDEV_COUNTER, 1),
        ]);
        list.data_mut(0)[0] = 0x0100_0005; // beyond 24 bits: refused, as by the comedi core
        assert_eq!(fake.run(&mut list), Err(Errno::EINVAL));
        list.data_mut(0)[0] = 0x00ff_fffb;
        fake.run(&mut list).unwrap();
        assert_eq!(list.data(1)[0], 0x00ff_fffb);
        let mut config = InsnList::new(&[Insn::one(INSN_CONFIG, SUBDEV_COUNTER, 1)]);
        assert_eq!(fake.run(&mut config), Err(Errno::EINVAL));
    }

    /// The plant: an enabled motor follows its DAC (through the lag), a preload moves the
    /// counter's frame and not the motor, and a switch opens where the motor passes it.
    #[test]
    fn a_wired_motor_moves_its_counter_and_opens_its_switch_where_it_passes() {
        let mut fake = FakeS626::new();
        let top =
            SwitchWire { dio: 9, at_counts: -100.0, toward: -1.0, closed_low: true, sticks: false };
        let wire = Wire {
            dac: 0,
            counter: 0,
            enable_dio: 0,
            enable_bit: 1,
            counts_per_s_per_volt: 10_000.0,
            lag_s: 0.004,
            top: Some(top),
            bottom: None,
        };
        fake.wire(0, wire, 0.001);
        assert!(fake.pin_low(9), "closed where the motor starts");
        let mut list = InsnList::new(&[
            Insn::one(INSN_WRITE, SUBDEV_AO, 0),
            Insn::bits(SUBDEV_DIO0),
            Insn::one(INSN_READ, SUBDEV_COUNTER, 0),
        ]);
        list.data_mut(0)[0] = crate::s626::dac_sample(-819); // ≈ −1 V: ≈ −10 000 counts/s
        list.data_mut(1).copy_from_slice(&[1, 1]); // enable
        fake.run(&mut list).unwrap();
        assert!(fake.position(0) > -1e-9, "one period of lag: barely moving yet");
        for _ in 0..20 {
            fake.run(&mut list).unwrap();
        }
        let x = fake.position(0);
        assert!((-210.0..-100.0).contains(&x), "{x}");
        assert!(!fake.pin_low(9), "open beyond -100 counts: tripped");
        assert_eq!(list.data(2)[0], (x.floor() as i64 as u32) & COUNTER_MASK);
        // A preload sets what the counter reads, not where the motor is.
        fake.set_counter(0, 5);
        assert_eq!((fake.position(0), fake.counter(0)), (x, 5));
        // Disabled, it coasts to rest: the velocity decays, the position settles.
        list.data_mut(1).copy_from_slice(&[1, 0]);
        for _ in 0..1000 {
            fake.run(&mut list).unwrap();
        }
        let rest = fake.position(0);
        fake.run(&mut list).unwrap();
        assert!((fake.position(0) - rest).abs() < 1e-6, "at rest");
    }

    /// Fault injection on the card's path (issue 42): a sticking switch stays open once
    /// tripped, wherever its motor goes; an input opened for a while of the plant's time
    /// (the e-stop chain) is open then only.
    #[test]
    fn a_stuck_switch_stays_open_and_an_input_opens_for_its_while() {
        let mut fake = FakeS626::new();
        let top =
            SwitchWire { dio: 9, at_counts: 50.0, toward: 1.0, closed_low: true, sticks: true };
        let wire = Wire {
            dac: 0,
            counter: 0,
            enable_dio: 0,
            enable_bit: 1,
            counts_per_s_per_volt: 10_000.0,
            lag_s: 0.0,
            top: Some(top),
            bottom: None,
        };
        fake.wire(0, wire, 0.001);
        fake.open_input_during(5, true, [0.010, 0.020]);
        let mut list = InsnList::new(&[
            Insn::one(INSN_WRITE, SUBDEV_AO, 0),
            Insn::bits(SUBDEV_DIO0),
            Insn::one(INSN_READ, SUBDEV_COUNTER, 0),
        ]);
        list.data_mut(0)[0] = crate::s626::dac_sample(819); // ≈ +1 V: ≈ +10 000 counts/s
        list.data_mut(1).copy_from_slice(&[1, 1]);
        let mut chain = Vec::new();
        for _ in 0..25 {
            fake.run(&mut list).unwrap();
            chain.push(fake.pin_low(5));
        }
        // Closed (low) for 10 ms, open for 10, closed again: one list per millisecond.
        let open: Vec<usize> = (0..25).filter(|&k| !chain[k]).collect();
        assert_eq!((open.first(), open.last(), open.len()), (Some(&9), Some(&18), 10), "{chain:?}");
        assert!(fake.position(0) > 50.0 && !fake.pin_low(9), "tripped");
        // Back below the switch: it stays open.
        list.data_mut(0)[0] = crate::s626::dac_sample(-819 * 4);
        for _ in 0..20 {
            fake.run(&mut list).unwrap();
        }
        assert!(fake.position(0) < 0.0, "{}", fake.position(0));
        assert!(!fake.pin_low(9), "a stuck switch stays open");
    }

    #[test]
    fn failures_come_on_demand() {
        let mut fake = FakeS626::new();
        let mut list = InsnList::new(&[
            Insn::one(INSN_WRITE, SUBDEV_AO, 0),
            Insn::one(INSN_WRITE, SUBDEV_AO, 1),
        ]);
        list.data_mut(0)[0] = 0x3000;
        list.data_mut(1)[0] = 0x3000;
        fake.fail_next(Failure::Short(1));
        assert_eq!(fake.run(&mut list), Ok(1));
        assert!(fake.dac_volts(0) > 4.0 && fake.dac_volts(1) == 0.0);
        list.data_mut(0)[0] = 0x1fff;
        fake.fail_next(Failure::ErrnoAfter { done: 1, errno: Errno::EIO });
        assert_eq!(fake.run(&mut list), Err(Errno::EIO));
        assert_eq!(fake.dac_volts(0), 0.0, "the instructions before the failure ran");
        assert_eq!(fake.run(&mut list), Ok(2));
        assert_eq!(fake.runs(), 3);
    }
}
