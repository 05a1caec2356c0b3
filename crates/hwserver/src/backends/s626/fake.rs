//! The 626 backend without a card: the fake of its driver ([`FakeS626`]) wired as the settings
//! say and driving the simulated robot's plant ([`FakePlant`]) — `--device fake` — and the
//! conformance suite's rig over it ([`FakeRig`]).

use super::{FAKE_DEVICE, S626};
use crate::backend::{Backend, Outputs};
use qmarc_comedi::Transport;
use qmarc_comedi::fake::{FakeS626, SwitchWire, Wire};
use qmarc_comedi::list::InsnList;
use qmarc_config::{S626Settings, Settings};
use qmarc_proto::{COUNTER_ZERO, MAX_MOTORS};
use std::sync::{Arc, Mutex};

/// The plant a fake card drives ([`wired_fake`]): the simulated robot's amplifiers, motors and
/// switches, in the settings' counts.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FakePlant {
    /// Amplifier gain: counts/s per volt.
    pub kv: f64,
    /// The amplifiers' velocity loop as a first-order lag, s (0: none).
    pub lag_s: f64,
    /// Where each motor starts, counts of the homed frame (its counter reads it).
    pub start_counts: [f64; MAX_MOTORS],
    /// Where the top and bottom switches trip, counts of the homed frame; `None`: the
    /// switches stay closed and are the caller's to open (the conformance rig's).
    pub switches: Option<(f64, f64)>,
    /// A motor (0-based) whose amplifier is wired the other way round (`sim.reversed_motor`).
    pub reversed: Option<usize>,
    /// A motor (0-based) that does not move, whatever it is told (`sim.stall_motor`).
    pub stalled: Option<usize>,
    /// A motor (0-based) whose top switch sticks once tripped (`sim.stuck_top_motor`).
    pub stuck_top: Option<usize>,
    /// The emergency-stop chain is open from the first to the second time, s of the plant's
    /// time (`sim.estop_open_s`; on `[s626] estop_dio`).
    pub estop_open_s: Option<[f64; 2]>,
}

impl FakePlant {
    /// The simulated robot of `s` (`[sim]`: `kv`, `tau_s` as the lag, `start_counts`, the
    /// switches), so `--device fake` moves as the card would on that robot.
    pub fn of(s: &Settings) -> FakePlant {
        let mut start_counts = [0.0; MAX_MOTORS];
        for (c, v) in start_counts.iter_mut().zip(&s.sim.start_counts) {
            *c = *v;
        }
        FakePlant {
            kv: s.sim.plant.kv,
            lag_s: s.sim.plant.tau_s,
            start_counts,
            switches: Some((s.sim.plant.top_switch_counts, s.sim.plant.bottom_switch_counts)),
            reversed: s.sim.plant.reversed_motor.and_then(|m| m.checked_sub(1)),
            stalled: s.sim.plant.stall_motor.and_then(|m| m.checked_sub(1)),
            stuck_top: s.sim.plant.stuck_top_motor.and_then(|m| m.checked_sub(1)),
            estop_open_s: s.sim.plant.estop_open_s,
        }
    }

    /// Amplifiers of `kv` counts/s per volt followed at once, motors at 0, switches closed.
    pub fn ideal(kv: f64) -> FakePlant {
        FakePlant {
            kv,
            lag_s: 0.0,
            start_counts: [0.0; MAX_MOTORS],
            switches: None,
            reversed: None,
            stalled: None,
            stuck_top: None,
            estop_open_s: None,
        }
    }
}

/// The fake card of the settings: [`wired_fake`] with the simulated robot's plant
/// ([`FakePlant::of`]).
pub fn fake_card(s: &Settings) -> FakeS626 {
    wired_fake(&s.s626, s.n_motors, &FakePlant::of(s), s.period_s())
}

/// A fake 626 wired as `w` says, driving `plant` (advancing `period_s` per read): each
/// counter reads its motor's position in the homed frame.
pub fn wired_fake(w: &S626Settings, n_motors: usize, plant: &FakePlant, period_s: f64) -> FakeS626 {
    let mut fake = FakeS626::new();
    let closed_low = w.switch_closed_bit == 1;
    for m in 0..n_motors.min(MAX_MOTORS) {
        let at = |v: &[u32]| v.get(m).copied().unwrap_or(0);
        let switch = |dio: u32, at_counts: f64, toward: f64, sticks: bool| {
            Some(SwitchWire { dio, at_counts, toward, closed_low, sticks })
        };
        let (top, bottom) = match plant.switches {
            Some((top, bottom)) => {
                let toward_top = if top < bottom { -1.0 } else { 1.0 };
                (
                    switch(at(&w.limit_top_dio), top, toward_top, plant.stuck_top == Some(m)),
                    switch(at(&w.limit_bottom_dio), bottom, -toward_top, false),
                )
            }
            None => (None, None),
        };
        let wire = Wire {
            dac: at(&w.dac_channels),
            counter: at(&w.counter_channels),
            enable_dio: at(&w.enable_dio),
            enable_bit: w.enable_bit,
            counts_per_s_per_volt: plant.kv
                * if plant.reversed == Some(m) { -1.0 } else { 1.0 }
                * if plant.stalled == Some(m) { 0.0 } else { 1.0 }
                * f64::from(w.dac_sign.get(m).copied().unwrap_or(1))
                * f64::from(w.counter_sign.get(m).copied().unwrap_or(1)),
            lag_s: plant.lag_s,
            top,
            bottom,
        };
        let chan = wire.counter as usize;
        fake.place(chan, plant.start_counts[m]);
        fake.set_counter(
            chan,
            COUNTER_ZERO.wrapping_add(plant.start_counts[m].floor() as i64 as u32),
        );
        fake.wire(m, wire, period_s);
        if plant.switches.is_none() {
            for chan in [at(&w.limit_top_dio), at(&w.limit_bottom_dio)] {
                fake.set_input_low(chan, closed_low);
            }
        }
    }
    // The emergency-stop chain, closed — or opened for a while (fault injection).
    if let Some(chan) = w.estop_dio {
        fake.set_input_low(chan, closed_low);
        if let Some(during) = plant.estop_open_s {
            fake.open_input_during(chan, closed_low, during);
        }
    }
    fake
}

/// A transport over a fake the conformance rig shares, to act on the world around the card.
pub(super) struct SharedFake(pub(super) Arc<Mutex<FakeS626>>);

impl SharedFake {
    fn card(&self) -> std::sync::MutexGuard<'_, FakeS626> {
        self.0.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl Transport for SharedFake {
    fn devinfo(&mut self) -> Result<qmarc_comedi::DevInfo, nix::errno::Errno> {
        self.card().devinfo()
    }
    fn subdinfo(&mut self, n: usize) -> Result<Vec<qmarc_comedi::SubdInfo>, nix::errno::Errno> {
        self.card().subdinfo(n)
    }
    fn lock(&mut self, subdev: u32) -> Result<(), nix::errno::Errno> {
        self.card().lock(subdev)
    }
    fn run(&mut self, list: &mut InsnList) -> Result<usize, nix::errno::Errno> {
        self.card().run(list)
    }
}

/// The 626's rig for the conformance suite: the backend over a fake of the driver wired as
/// the thesis' robot (`[s626]` defaults) with an emergency-stop chain on DIO5, its switches,
/// chain and outputs seen from outside the card.
pub struct FakeRig {
    fake: Arc<Mutex<FakeS626>>,
    wiring: S626Settings,
}

impl Default for FakeRig {
    fn default() -> FakeRig {
        let wiring = S626Settings { estop_dio: Some(5), ..S626Settings::default() };
        FakeRig { fake: Arc::default(), wiring }
    }
}

impl FakeRig {
    /// The rig with the card wired as `wiring` says (polarities, channels, directions).
    pub fn wired(wiring: S626Settings) -> FakeRig {
        FakeRig { fake: Arc::default(), wiring }
    }

    fn card(&self) -> std::sync::MutexGuard<'_, FakeS626> {
        self.fake.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }
}

impl crate::conformance::Rig for FakeRig {
    fn backend(&mut self, n_motors: usize, start_counts: f64) -> Box<dyn Backend> {
        let w = &self.wiring;
        let mut fake = wired_fake(w, n_motors, &FakePlant::ideal(25_000.0 / 4.0), 400e-6);
        for m in 0..n_motors {
            // The count the backend reads, as the counter holds it in the motor's direction.
            let count = COUNTER_ZERO.wrapping_add(start_counts as i64 as u32);
            fake.set_counter(
                w.counter_channels[m] as usize,
                super::oriented(w.counter_sign[m], count),
            );
        }
        self.fake = Arc::new(Mutex::new(fake));
        let transport = Box::new(SharedFake(self.fake.clone()));
        let card = S626::with_transport(transport, FAKE_DEVICE, w, n_motors, None)
            .expect("the rig's card is a 626");
        Box::new(card.all_homed())
    }

    fn estop(&mut self, open: bool) -> bool {
        let Some(chan) = self.wiring.estop_dio else { return false };
        // Closed, the chain pulls its input low (normally closed to ground, as the switches).
        let closed_low = self.wiring.switch_closed_bit == 1;
        self.card().set_input_low(chan, closed_low != open);
        true
    }

    fn trip_switch(&mut self, _core: &mut crate::HwCore, motor: usize, top: bool) {
        let w = &self.wiring;
        let chan = if top { w.limit_top_dio[motor] } else { w.limit_bottom_dio[motor] };
        // A tripped normally-closed switch opens: nothing pulls its input low any more.
        let closed_low = w.switch_closed_bit == 1;
        self.card().set_input_low(chan, !closed_low);
    }

    fn outputs(&mut self, core: &crate::HwCore) -> Option<Outputs> {
        let card = self.card();
        let w = &self.wiring;
        let mut o = Outputs::default();
        for m in 0..core.n_motors() {
            let volts = card.dac_volts(w.dac_channels[m] as usize);
            o.dac[m] = (volts * f64::from(qmarc_comedi::s626::DAC_SPAN) / 10.0).round() as i32
                * w.dac_sign[m];
            let written = (card.outputs() >> w.enable_dio[m]) & 1;
            o.enabled[m] = written == w.enable_bit;
        }
        // The DACs of no motor must be at 0 V too.
        let others = (0..4).filter(|c| !w.dac_channels[..core.n_motors()].contains(c));
        if others.into_iter().any(|c| card.dac_volts(c as usize) != 0.0) {
            o.dac = [i32::MAX; MAX_MOTORS];
        }
        Some(o)
    }
}
