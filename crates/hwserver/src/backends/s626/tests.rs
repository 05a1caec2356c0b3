//! Unit tests of the 626 backend over the fake of its driver: what goes to the card, in which
//! lists, and what never does.

use super::*;
use crate::HwCore;
use qmarc_comedi::fake::{Failure, FakeS626};
use qmarc_comedi::uapi::INSN_BITS;
use qmarc_proto::{COUNTER_ZERO, HwMsg, MsgType};
use std::path::Path;
use std::sync::{Arc, Mutex};

/// The backend over a fake wired as the thesis' robot, and the fake.
fn card(n_motors: usize) -> (S626, Arc<Mutex<FakeS626>>) {
    let w = S626Settings::default();
    let fake = Arc::new(Mutex::new(wired_fake(&w, n_motors, &FakePlant::ideal(6_250.0), 400e-6)));
    let transport = Box::new(SharedFake(fake.clone()));
    (S626::with_transport(transport, "fake", &w, n_motors, None).unwrap(), fake)
}

fn locked(fake: &Arc<Mutex<FakeS626>>) -> std::sync::MutexGuard<'_, FakeS626> {
    fake.lock().unwrap()
}

#[test]
fn a_cycle_is_two_lists_in_the_thesis_order() {
    let (mut s, fake) = card(3);
    let before = locked(&fake).runs();
    let mut inputs = Inputs::default();
    s.read_inputs(&mut inputs).unwrap();
    assert_eq!(
        locked(&fake).last_list(),
        [(INSN_READ, 5, 0), (INSN_READ, 5, 1), (INSN_READ, 5, 2), (INSN_BITS, 2, 0)],
        "counters 0A 1A 2A, then DIO bank 0"
    );
    s.write_dacs(&[100, -100, 0, 0]).unwrap();
    assert_eq!(
        locked(&fake).last_list(),
        [(INSN_WRITE, 1, 0), (INSN_WRITE, 1, 1), (INSN_WRITE, 1, 2), (INSN_BITS, 2, 0)],
        "DACs 0‥2, then DIO bank 0"
    );
    assert_eq!(locked(&fake).runs() - before, 2, "one ioctl each");
    assert_eq!(s.write.data(0)[0], 0x1fff + 100);
    assert_eq!(s.write.data(1)[0], 0x1fff - 100);
    assert_eq!(s.write.data(2)[0], 0x1fff, "0 V is exactly 0x1fff");
}

#[test]
fn the_belts_counter_is_read_in_the_same_list_and_counts_across_its_wrap() {
    let (s, fake) = card(3);
    let mut s = s.with_belt_counter(3);
    let mut inputs = Inputs::default();
    s.read_inputs(&mut inputs).unwrap();
    assert_eq!(
        locked(&fake).last_list(),
        [
            (INSN_READ, 5, 0),
            (INSN_READ, 5, 1),
            (INSN_READ, 5, 2),
            (INSN_READ, 5, 3),
            (INSN_BITS, 2, 0)
        ],
        "the motors' counters, the belt's (0B), then DIO bank 0: still one list"
    );
    // The core widens it like a motor's: a belt running forward through the 24-bit wrap.
    locked(&fake).set_counter(3, qmarc_proto::COUNTER_MASK - 9);
    let mut core = HwCore::new(Box::new(s));
    let runs = locked(&fake).runs();
    let mut belt = Vec::new();
    for step in [0, 5, 20, 1_000] {
        locked(&fake)
            .set_counter(3, (qmarc_proto::COUNTER_MASK - 9 + step) & qmarc_proto::COUNTER_MASK);
        belt.push(core.handle(&HwMsg::read_all_encoders()).belt);
    }
    let start = i64::from(qmarc_proto::counter_delta(COUNTER_ZERO, qmarc_proto::COUNTER_MASK - 9));
    let since: Vec<i64> = belt.iter().map(|b| b - start).collect();
    assert_eq!(since, [0, 5, 20, 1_000], "from its distance from COUNTER_ZERO at the start");
    assert_eq!(locked(&fake).runs() - runs, 4, "one list per read");
}

#[test]
fn inputs_and_reserved_channels_are_never_written_nor_dio_configured() {
    let (s, fake) = card(3);
    let mut core = HwCore::new(Box::new(s));
    for m in 0..3 {
        core.handle(&HwMsg::for_motor(MsgType::EnableMotor, m));
    }
    for _ in 0..10 {
        core.handle(&HwMsg::read_all_encoders());
        core.handle(&HwMsg::write_all_dacs(&[500, 500, 500, 0]));
    }
    let mut preset = HwMsg::for_motor(MsgType::ResetEncoderZero, HwMsg::ALL_MOTORS);
    preset.data[..3].copy_from_slice(&[1.0, 2.0, 3.0]);
    core.handle(&preset);
    core.trip_watchdog();
    let w = S626Settings::default();
    let fake = locked(&fake);
    let inputs: Vec<u32> = w.limit_top_dio.iter().chain(&w.limit_bottom_dio).copied().collect();
    for chan in inputs.iter().chain(&w.reserved_dio) {
        assert_eq!(fake.masks_written() >> chan & 1, 0, "DIO{chan} was in a write mask");
    }
    assert_eq!(fake.masks_written(), 0b1_1011, "the enables DIO0, 1, 3 and the pump DIO4");
    assert_eq!(fake.dio_configs(), 0, "never INSN_CONFIG on DIO");
}

#[test]
fn no_motor_is_enabled_before_a_read_and_a_write_succeeded() {
    let (mut s, fake) = card(1);
    assert!(s.set_amp_enable(0, true).is_err(), "nothing answered yet");
    s.run_read_list().unwrap();
    assert!(s.set_amp_enable(0, true).is_err(), "a read alone");
    locked(&fake).fail_next(Failure::Short(1));
    assert!(s.run_write_list().is_err());
    assert!(s.set_amp_enable(0, true).is_err(), "a write that failed");
    s.run_write_list().unwrap();
    s.set_amp_enable(0, true).unwrap();
    assert!(locked(&fake).pin_low(0), "DIO0 written 1: the buffer board enables motor 1");
}

#[test]
fn a_driver_error_mid_move_makes_everything_safe_at_once_and_for_good() {
    let (s, fake) = card(3);
    let mut core = HwCore::new(Box::new(s));
    core.handle(&HwMsg::for_motor(MsgType::EnableMotor, 0));
    core.handle(&HwMsg::write_all_dacs(&[800, 0, 0, 0]));
    assert!(locked(&fake).pin_low(0) && locked(&fake).dac_volts(0) > 0.9);
    // The kernel runs the counters, then the DIO read fails: no count, an errno.
    locked(&fake).fail_next(Failure::ErrnoAfter { done: 2, errno: nix::errno::Errno::EIO });
    let st = core.handle(&HwMsg::read_all_encoders()).status();
    assert!(st.contains(Status::HARDWARE_FAULT), "{st}");
    {
        let fake = locked(&fake);
        assert!((0..4).all(|c| fake.dac_volts(c) == 0.0), "DACs at 0 V without a DisableAll");
        assert!(!fake.pin_low(0), "motor 1's enable off without a DisableAll");
    }
    // Latched: every response says so, nothing is enabled or driven again.
    let st = core.handle(&HwMsg::for_motor(MsgType::EnableMotor, 0)).status();
    assert!(st.contains(Status::HARDWARE_FAULT), "{st}");
    core.handle(&HwMsg::write_all_dacs(&[800, 0, 0, 0]));
    assert!(!locked(&fake).pin_low(0) && locked(&fake).dac_volts(0) == 0.0);
    assert!(core.handle(&HwMsg::read_all_encoders()).status().contains(Status::HARDWARE_FAULT));
}

#[test]
fn a_safe_list_that_fails_part_way_still_drops_every_enable_and_dac() {
    let (s, fake) = card(3);
    let mut core = HwCore::new(Box::new(s));
    core.handle(&HwMsg::for_motor(MsgType::EnableMotor, 2));
    core.handle(&HwMsg::write_all_dacs(&[0, 0, -900, 0]));
    // The safe list's first instruction fails: its singles run one by one.
    locked(&fake).fail_next(Failure::ErrnoAfter { done: 0, errno: nix::errno::Errno::EIO });
    core.handle(&HwMsg::request(MsgType::DisableAll));
    let fake = locked(&fake);
    assert!(!fake.pin_low(3), "motor 3's enable (DIO3) off");
    assert!((0..4).all(|c| fake.dac_volts(c) == 0.0));
    assert_eq!(fake.last_list()[0].1, 1, "the last single was a DAC: all of them ran");
}

#[test]
fn a_failed_preset_leaves_the_motor_unhomed() {
    let (s, fake) = card(2);
    let mut core = HwCore::new(Box::new(s));
    locked(&fake).fail_next(Failure::ErrnoAfter { done: 0, errno: nix::errno::Errno::EIO });
    let mut preset = HwMsg::for_motor(MsgType::ResetEncoderZero, 1);
    preset.data[1] = 10.0;
    let st = core.handle(&preset).status();
    assert!(st.contains(Status::HARDWARE_FAULT), "{st}");
    let flags = qmarc_proto::MotorFlags(core.handle(&HwMsg::read_all_encoders()).aux[1]);
    assert!(!flags.homed(), "a counter that may hold anything is no homed frame");
}

#[test]
fn a_stop_signal_stills_the_pump_and_holds_the_dacs_at_zero() {
    let (s, fake) = card(3);
    let mut core = HwCore::new(Box::new(s));
    core.handle(&HwMsg::write_all_dacs(&[0; MAX_MOTORS]));
    core.shut_down();
    let pump = locked(&fake).pin_low(4);
    for _ in 0..3 {
        core.handle(&HwMsg::write_all_dacs(&[700, 700, 700, 0]));
        let fake = locked(&fake);
        assert_eq!(fake.pin_low(4), pump, "no more edges: the relay drops");
        assert!((0..4).all(|c| fake.dac_volts(c) == 0.0), "0 V once stopped");
    }
}

#[test]
fn a_homed_frame_that_cannot_be_kept_is_refused_before_the_run() {
    let s = crate::backends::test_settings(
        "[general]\ncounts_per_rev = 1024\n[hwserver]\nbackend = \"s626\"\n[s626]\n\
         state_dir = \"/proc/qmarc\"\n",
    );
    let e = check_state_dir(&s).unwrap_err().to_string();
    assert!(e.starts_with("/proc/qmarc: cannot keep the homed frame there ("), "{e}");
    assert!(e.contains("or set [s626] state_dir"), "{e}");
}

#[test]
fn the_charge_pump_toggles_once_per_write_and_stops_with_the_watchdog() {
    let (s, fake) = card(3);
    let mut core = HwCore::new(Box::new(s));
    let mut levels = Vec::new();
    for _ in 0..4 {
        core.handle(&HwMsg::read_all_encoders());
        core.handle(&HwMsg::write_all_dacs(&[0; MAX_MOTORS]));
        levels.push(locked(&fake).pin_low(4));
    }
    assert_eq!(levels, [true, false, true, false], "one edge per servo cycle");
    core.trip_watchdog();
    for _ in 0..3 {
        core.handle(&HwMsg::write_all_dacs(&[0; MAX_MOTORS]));
        assert!(!locked(&fake).pin_low(4), "the relay drops for good");
    }
}

#[test]
fn a_reversed_counter_presets_and_counts_the_other_way() {
    let w = S626Settings { counter_sign: vec![-1, 1, 1], ..S626Settings::default() };
    let fake = Arc::new(Mutex::new(wired_fake(&w, 1, &FakePlant::ideal(6_250.0), 400e-6)));
    let s = S626::with_transport(Box::new(SharedFake(fake.clone())), "fake", &w, 1, None).unwrap();
    let mut core = HwCore::new(Box::new(s));
    let mut preset = HwMsg::for_motor(MsgType::ResetEncoderZero, 0);
    preset.data[0] = 250.0;
    core.handle(&preset);
    assert_eq!(core.handle(&HwMsg::read_all_encoders()).data[0], 250.0);
    let raw = locked(&fake).counter(0);
    assert_eq!(raw, COUNTER_ZERO.wrapping_add(250).wrapping_neg() & COUNTER_MASK);
    core.handle(&HwMsg::for_motor(MsgType::EnableMotor, 0));
    core.handle(&HwMsg::write_all_dacs(&[2_000, 0, 0, 0]));
    for _ in 0..50 {
        core.handle(&HwMsg::read_all_encoders());
    }
    assert!(core.position(0) > 300, "a positive command still counts up: {}", core.position(0));
}

#[test]
fn a_device_that_is_not_a_626_is_refused_naming_it() {
    let w = S626Settings::default();
    let open = |fake: FakeS626| {
        S626::with_transport(Box::new(fake), "/dev/comedi3", &w, 3, None).map(drop).unwrap_err()
    };
    assert_eq!(
        open(FakeS626::new().with_driver("comedi_test")).to_string(),
        "/dev/comedi3 is driven by `comedi_test` (fake), not `s626`: give the Sensoray 626's \
         device (`cat /proc/comedi` lists them)"
    );
    let odd = qmarc_comedi::SubdInfo { kind: qmarc_comedi::uapi::SUBD_DIO, n_chan: 8, maxdata: 1 };
    assert!(open(FakeS626::new().with_subdevice(2, odd)).to_string().starts_with(
        "/dev/comedi3: subdevice 2 is 8 digital I/O of maxdata 0x1, the 626 has 16 digital I/O"
    ));
    let e = Comedi::open(Path::new("/dev/comedi-none")).map(drop).unwrap_err();
    assert!(e.to_string().starts_with("/dev/comedi-none: no such device"), "{e}");
    let e = Comedi::open(Path::new("/dev/null")).map(drop).unwrap_err();
    assert!(e.to_string().starts_with("/dev/null is not a comedi device"), "{e}");
}

/// The thesis' wiring with an emergency-stop chain on DIO5, and two others the conformance
/// suite must hold for too: active-low amplifiers with switches closed to +5 V (they read 0),
/// and every channel moved, with motors that count and drive the other way.
fn wirings() -> [S626Settings; 3] {
    let thesis = S626Settings { estop_dio: Some(5), ..S626Settings::default() };
    let inverted = S626Settings { enable_bit: 0, switch_closed_bit: 0, ..thesis.clone() };
    let moved = S626Settings {
        enable_dio: vec![3, 0, 1],
        limit_top_dio: vec![15, 9, 12],
        limit_bottom_dio: vec![13, 10, 11],
        estop_dio: Some(6),
        dac_channels: vec![3, 1, 0],
        counter_channels: vec![3, 0, 1],
        dac_sign: vec![-1, 1, -1],
        counter_sign: vec![1, -1, -1],
        ..thesis.clone()
    };
    [thesis, inverted, moved]
}

/// The backend of `n_motors` over a fake wired as `w` says (switches and chain closed), and
/// the fake.
fn wired_card(w: &S626Settings, n_motors: usize) -> (S626, Arc<Mutex<FakeS626>>) {
    let fake = Arc::new(Mutex::new(wired_fake(w, n_motors, &FakePlant::ideal(6_250.0), 400e-6)));
    let transport = Box::new(SharedFake(fake.clone()));
    (S626::with_transport(transport, "fake", w, n_motors, None).unwrap(), fake)
}

/// Issue 32: every conformance check on the card wired otherwise than the thesis' robot.
#[test]
fn the_conformance_suite_holds_for_other_wirings() {
    for w in wirings() {
        for check in crate::conformance::CHECKS {
            let mut rig = FakeRig::wired(w.clone());
            if let Err(e) = (check.run)(&mut rig) {
                panic!("{} with {w:?}: {e}", check.name);
            }
        }
    }
}

/// Issue 32: a read sees the switches that are open and nothing else — none when all are
/// closed, exactly the one that opens, the chain apart — in either polarity, whatever the
/// card's other inputs do.
#[test]
fn a_read_sees_exactly_the_switch_that_opens_in_either_polarity() {
    for w in wirings() {
        let (mut s, fake) = wired_card(&w, 3);
        let closed_low = w.switch_closed_bit == 1;
        let mut read = || {
            let mut i = Inputs::default();
            s.read_inputs(&mut i).unwrap();
            (i.limits, i.estop_open)
        };
        assert_eq!(read(), (Status::OK, false), "all closed: {w:?}");
        // The pins no switch is on, either way: nothing.
        let used: Vec<u32> = w
            .limit_top_dio
            .iter()
            .chain(&w.limit_bottom_dio)
            .chain(&w.estop_dio)
            .copied()
            .collect();
        for low in [true, false] {
            for chan in (0..16).filter(|c| !used.contains(c)) {
                locked(&fake).set_input_low(chan, low);
            }
            assert_eq!(read(), (Status::OK, false), "other pins {low}: {w:?}");
        }
        for m in 0..3 {
            for (top, chan) in [(true, w.limit_top_dio[m]), (false, w.limit_bottom_dio[m])] {
                locked(&fake).set_input_low(chan, !closed_low);
                let bit = if top { Status::limit_top(m) } else { Status::limit_bottom(m) };
                assert_eq!(read(), (bit, false), "DIO{chan} open: {w:?}");
                locked(&fake).set_input_low(chan, closed_low);
            }
        }
        let chain = w.estop_dio.unwrap();
        locked(&fake).set_input_low(chain, !closed_low);
        assert_eq!(read(), (Status::OK, true), "the chain open: {w:?}");
        for &chan in &used {
            locked(&fake).set_input_low(chan, !closed_low);
        }
        let all =
            (0..3).fold(Status::OK, |a, m| a | Status::limit_top(m) | Status::limit_bottom(m));
        assert_eq!(read(), (all, true), "all open: {w:?}");
    }
}

/// Issue 32: the enable pins as the amplifiers see them, in either polarity: off from the
/// moment the card is opened, each amplifier's own pin on when it is enabled and no other,
/// off after the safe state and after the backend is dropped — which also zeroes every DAC.
#[test]
fn the_enable_pins_follow_each_amplifier_in_either_polarity() {
    for w in wirings() {
        let (mut s, fake) = wired_card(&w, 3);
        let on = |fake: &Arc<Mutex<FakeS626>>| -> [bool; 3] {
            let out = locked(fake).outputs();
            std::array::from_fn(|m| (out >> w.enable_dio[m]) & 1 == w.enable_bit)
        };
        let dacs_at_zero =
            |fake: &Arc<Mutex<FakeS626>>| (0..4).all(|c| locked(fake).dac_volts(c) == 0.0);
        assert_eq!(on(&fake), [false; 3], "when opened: {w:?}");
        s.run_read_list().unwrap();
        s.run_write_list().unwrap();
        for m in 0..3 {
            s.set_amp_enable(m, true).unwrap();
            let only = std::array::from_fn(|k| k == m);
            assert_eq!(on(&fake), only, "motor {} enabled: {w:?}", m + 1);
            s.write_dacs(&[100, 200, 300, 0]).unwrap();
            assert_eq!(on(&fake), only, "after a write: {w:?}");
            assert_eq!(
                s.outputs(),
                Some(Outputs { dac: [100, 200, 300, 0], enabled: [m == 0, m == 1, m == 2, false] })
            );
            s.set_amp_enable(m, false).unwrap();
            assert_eq!(on(&fake), [false; 3], "motor {} disabled: {w:?}", m + 1);
        }
        for m in 0..3 {
            s.set_amp_enable(m, true).unwrap();
        }
        assert_eq!(on(&fake), [true; 3]);
        s.safe_state();
        assert_eq!((on(&fake), dacs_at_zero(&fake)), ([false; 3], true), "safe: {w:?}");
        assert_eq!(s.outputs(), Some(Outputs::default()));
        s.run_write_list().unwrap();
        for m in 0..3 {
            s.set_amp_enable(m, true).unwrap();
        }
        s.write_dacs(&[-900, 900, 500, 0]).unwrap();
        assert!(!dacs_at_zero(&fake));
        drop(s);
        assert_eq!((on(&fake), dacs_at_zero(&fake)), ([false; 3], true), "dropped: {w:?}");
        if let Some(pump) = w.charge_pump_dio {
            assert!(!locked(&fake).pin_low(pump), "the pump held still, its relay dropped");
        }
    }
}

/// Settings for the card `device`, its homed frame kept in `state_dir`.
fn card_settings(device: &Path, state_dir: &Path, extra: &str) -> Settings {
    crate::backends::test_settings(&format!(
        "[general]\ncounts_per_rev = 1024\n[hwserver]\nbackend = \"s626\"\n[s626]\n\
         device = \"{}\"\nstate_dir = \"{}\"\n{extra}",
        device.display(),
        state_dir.display()
    ))
}

/// Issue 32: the homed frame is kept in `<state_dir>/s626-<device>.state` and belongs to
/// that card as it was when homed: the same node and counters find it again; a node made
/// anew (the driver reloaded, the counters reset) or counters counting the other way do not.
#[test]
fn the_homed_frame_is_kept_for_that_card_only() {
    let dir = std::env::temp_dir().join(format!("qmarc-frame-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let device = dir.join("comedi7"); // a file standing for the device node
    std::fs::write(&device, b"").unwrap();
    let s = card_settings(&device, &dir, "");
    let file = state_file(&s);
    assert_eq!(file, dir.join("s626-comedi7.state"));
    let open = |s: &Settings| {
        let fake = wired_fake(&s.s626, 3, &FakePlant::ideal(6_250.0), 400e-6);
        let d = s.s626.device.display().to_string();
        S626::with_transport(Box::new(fake), &d, &s.s626, 3, Some(state_file(s))).unwrap()
    };
    let homed = |c: &S626| [c.homed(0), c.homed(1), c.homed(2)];
    let mut card = open(&s);
    assert_eq!(homed(&card), [false; 3], "nothing kept yet");
    card.set_homed(1).unwrap();
    assert_eq!(homed(&card), [false, true, false]);
    drop(card);
    assert!(file.exists());
    assert_eq!(homed(&open(&s)), [false, true, false], "the same card, kept");
    let other = card_settings(&device, &dir, "counter_sign = [1, -1, 1]\n");
    assert_eq!(homed(&open(&other)), [false; 3], "counters the other way");
    // The driver reloaded: a new node where the old one was.
    let new = dir.join("comedi7.new");
    std::fs::write(&new, b"").unwrap();
    std::fs::rename(&new, &device).unwrap();
    assert_eq!(homed(&open(&s)), [false; 3], "a new node");
    // Issue 28, item 4: a frame that cannot be kept (a file where its folder should be)
    // is a failed home, saying where: not homed, and the caller told.
    let blocked = card_settings(&device, &dir.join("comedi7"), "");
    let mut blocked_card = open(&blocked);
    let e = blocked_card.set_homed(0).unwrap_err().to_string();
    assert!(e.starts_with("cannot keep the homed frame in "), "{e}");
    assert!(e.contains(" (s626.state_dir): "), "{e}");
    assert!(e.ends_with("the next run would find motor 1 unhomed"), "{e}");
    assert_eq!(homed(&blocked_card), [false; 3]);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Issue 32: `open` drives the fake for `fake` (homed, in process) and the device otherwise;
/// `check` refuses what `open` would, before anything is spawned; neither runs lock-step.
#[test]
fn open_and_check_take_the_device_the_settings_name() {
    let dir = std::env::temp_dir().join(format!("qmarc-open-{}", std::process::id()));
    let fake = card_settings(Path::new(FAKE_DEVICE), &dir, "");
    let card = S626::open(&fake, false).unwrap();
    assert_eq!((card.name(), card.n_motors(), card.homed(2)), ("s626", 3, true));
    drop(card);
    S626::check(&fake, false).unwrap();
    let e = S626::open(&fake, true).map(drop).unwrap_err().to_string();
    assert!(e.starts_with("--deterministic runs the simulated robot only"), "{e}");
    let e = S626::check(&fake, true).unwrap_err().to_string();
    assert!(e.starts_with("--deterministic runs the simulated robot only"), "{e}");
    let none = card_settings(Path::new("/dev/comedi-none"), &dir, "");
    let e = S626::open(&none, false).map(drop).unwrap_err().to_string();
    assert!(e.starts_with("/dev/comedi-none: no such device"), "{e}");
    let e = S626::check(&none, false).unwrap_err().to_string();
    assert!(e.starts_with("/dev/comedi-none: no such device"), "{e}");
    let null = card_settings(Path::new("/dev/null"), &dir, "");
    let e = S626::check(&null, false).unwrap_err().to_string();
    assert!(e.starts_with("/dev/null is not a comedi device"), "{e}");
    let other_counts = card_settings(Path::new(FAKE_DEVICE), &dir, "counts_per_rev = 4096\n");
    let e = S626::check(&other_counts, false).unwrap_err().to_string();
    assert!(e.contains("but the 626 counts 4096"), "{e}");
    assert!(!dir.exists(), "the fake keeps no frame");
}

/// Issue 42, item 8: the simulator's fault injection is the fake card's too — and none of it
/// on a card that drives a robot; the fake's e-stop needs the chain's input wired.
#[test]
fn fault_injection_is_the_fake_cards_only() {
    let dir = std::env::temp_dir().join(format!("qmarc-inject-{}", std::process::id()));
    let real = Path::new("/dev/comedi-none");
    for (key, value) in [
        ("stall_motor", "2"),
        ("stuck_top_motor", "1"),
        ("reversed_motor", "3"),
        ("estop_open_s", "[0.5, 0.6]"),
    ] {
        let sim = format!("[sim]\n{key} = {value}\n");
        let on_card = card_settings(real, &dir, &format!("estop_dio = 5\n{sim}"));
        let e = S626::check(&on_card, false).unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("sim.{key} is the simulator's fault injection")),
            "{key}: {e}"
        );
        assert!(e.contains("not on the card /dev/comedi-none"), "{e}");
        let fake = card_settings(Path::new(FAKE_DEVICE), &dir, &format!("estop_dio = 5\n{sim}"));
        S626::check(&fake, false).unwrap_or_else(|e| panic!("{key} on the fake: {e}"));
    }
    let unwired = card_settings(
        Path::new(FAKE_DEVICE),
        &dir,
        "estop_dio = -1\n[sim]\nestop_open_s = [0.5, 0.6]\n",
    );
    let e = S626::check(&unwired, false).unwrap_err().to_string();
    assert!(e.starts_with("sim.estop_open_s: the fake card sees the emergency-stop chain"), "{e}");
    let plain = card_settings(Path::new(FAKE_DEVICE), &dir, "estop_dio = -1\n");
    S626::check(&plain, false).unwrap();
    // What the fake plays: a stalled motor's amplifier moves nothing, a stuck switch sticks.
    let p = FakePlant::of(&card_settings(
        Path::new(FAKE_DEVICE),
        &dir,
        "[sim]\nstall_motor = 2\nstuck_top_motor = 3\nestop_open_s = [1.0, 2.0]\n",
    ));
    assert_eq!((p.stalled, p.stuck_top, p.estop_open_s), (Some(1), Some(2), Some([1.0, 2.0])));
}

/// Issue 32: an ioctl's answer as a fault: a list that ran short says how far it got
/// (−(instructions run) − 1), an errno is itself; the operation is named.
#[test]
fn a_short_list_or_an_errno_is_a_fault_of_that_operation() {
    assert_eq!(ran(Ok(4), 4, HwOp::WriteDacs), Ok(()));
    assert_eq!(ran(Ok(2), 4, HwOp::WriteDacs), Err(HwFault { op: HwOp::WriteDacs, code: -3 }));
    assert_eq!(ran(Ok(0), 1, HwOp::LoadCounter), Err(HwFault { op: HwOp::LoadCounter, code: -1 }));
    let eio = nix::errno::Errno::EIO;
    assert_eq!(
        ran(Err(eio), 4, HwOp::ReadInputs),
        Err(HwFault { op: HwOp::ReadInputs, code: eio as i32 })
    );
}

/// Issue 32: the backend's clock is the monotonic clock, in nanoseconds.
#[test]
fn the_clock_is_monotonic_nanoseconds() {
    let (s, _) = card(1);
    let a = s.now_ns();
    std::thread::sleep(std::time::Duration::from_millis(2));
    let b = s.now_ns();
    let c = qmarc_timer::clock::monotonic_now_ns();
    assert!(b >= a + 2_000_000 && c >= b, "{a} {b} {c}");
}

/// Issue 32: disabling a motor zeroes its DAC and drops its enable; if the DAC write fails
/// the hardware is in doubt even though the enable dropped — a fault, made safe, latched.
#[test]
fn a_disable_whose_dac_write_fails_is_a_hardware_fault() {
    let (s, fake) = card(3);
    let mut core = HwCore::new(Box::new(s));
    core.handle(&HwMsg::read_all_encoders());
    core.handle(&HwMsg::write_all_dacs(&[0; MAX_MOTORS]));
    core.handle(&HwMsg::for_motor(MsgType::EnableMotor, 1));
    core.handle(&HwMsg::write_all_dacs(&[0, 600, 0, 0]));
    // The disable runs the write list (it fails), then the enables list.
    locked(&fake).fail_next(Failure::ErrnoAfter { done: 0, errno: nix::errno::Errno::EIO });
    let st = core.handle(&HwMsg::for_motor(MsgType::DisableMotor, 1)).status();
    assert!(st.contains(Status::HARDWARE_FAULT), "{st}");
    {
        let fake = locked(&fake);
        assert!((0..4).all(|c| fake.dac_volts(c) == 0.0));
        assert!(!fake.pin_low(1), "motor 2's enable off");
    }
    let st = core.handle(&HwMsg::read_all_encoders()).status();
    assert!(st.contains(Status::HARDWARE_FAULT), "latched: {st}");
}

/// Issue 30: the gripper on the card is one `INSN_BITS` under its own bit, once per change;
/// the enables and the charge pump written every cycle leave it as it is, the pins read it
/// back, and a mask with a channel the server keeps reaches nothing.
#[test]
fn the_gripper_output_is_one_masked_write_that_the_cycle_leaves_alone() {
    let w = S626Settings { gripper_dio: Some(6), ..S626Settings::default() };
    let fake = Arc::new(Mutex::new(wired_fake(&w, 3, &FakePlant::ideal(6_250.0), 400e-6)));
    let transport = Box::new(SharedFake(fake.clone()));
    let s = S626::with_transport(transport, "fake", &w, 3, None).unwrap();
    let mut core = HwCore::new(Box::new(s)).with_gripper(1 << 6, 0.05);
    for m in 0..3 {
        core.handle(&HwMsg::for_motor(MsgType::EnableMotor, m));
    }
    let before = locked(&fake).runs();
    let r = core.handle(&HwMsg::write_outputs(1 << 6, 1 << 6));
    assert_eq!(r.status(), Status::OK);
    assert_eq!(locked(&fake).runs() - before, 1, "one ioctl");
    assert_eq!(locked(&fake).last_list(), [(INSN_BITS, 2, 0)]);
    assert!(locked(&fake).pin_low(6), "on: the pin at 0 V");
    for _ in 0..5 {
        let r = core.handle(&HwMsg::read_all_encoders());
        assert_eq!(r.outputs, 1 << 6);
        core.handle(&HwMsg::write_all_dacs(&[100, 100, 100, 0]));
        assert!(locked(&fake).pin_low(6), "the cycle's enable write keeps it");
    }
    for kept in [0, 2, 4, 9] {
        let runs = locked(&fake).runs();
        let r = core.handle(&HwMsg::write_outputs(1 << kept | 1 << 6, 0));
        assert_eq!(r.status(), Status::PROTECTED_OUTPUT, "DIO{kept}");
        assert_eq!(locked(&fake).runs(), runs, "nothing reached the card");
    }
    assert!(locked(&fake).pin_low(6) && locked(&fake).pin_low(0), "gripper and enable on");
    // Another free output, on: the gripper's write leaves it as it is.
    core.handle(&HwMsg::write_outputs(1 << 7, 1 << 7));
    core.handle(&HwMsg::write_outputs(1 << 6, 0));
    assert!(!locked(&fake).pin_low(6));
    assert!(locked(&fake).pin_low(7), "DIO7 kept");
    assert!(locked(&fake).pin_low(0), "motor 1 still enabled");
    core.handle(&HwMsg::write_outputs(1 << 7, 0));
    // A new server finds the gripper where the card holds it (an earlier one closed it).
    let mut card = wired_fake(&w, 3, &FakePlant::ideal(6_250.0), 400e-6);
    let mut close = InsnList::new(&[Insn::bits(SUBDEV_DIO0)]);
    close.data_mut(0).copy_from_slice(&[1 << 6, 1 << 6]);
    assert_eq!(card.run(&mut close), Ok(1));
    let s = S626::with_transport(Box::new(card), "fake", &w, 3, None).unwrap();
    let mut core = HwCore::new(Box::new(s)).with_gripper(1 << 6, 0.05);
    let r = core.handle(&HwMsg::read_all_encoders());
    assert_eq!((r.outputs, qmarc_proto::Gripper(r.gripper).name()), (1 << 6, "closed"));
}
