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
    let names = qmarc_config::Names::backends_only(crate::backends::names());
    let text = "[general]\ncounts_per_rev = 1024\n[hwserver]\nbackend = \"s626\"\n[s626]\n\
                state_dir = \"/proc/qmarc\"\n"
        .to_string()
        + &"[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n".repeat(3);
    let s = qmarc_config::Settings::parse(Path::new("q.toml"), &text, &names).unwrap();
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
