//! Tests of [`super::HwCore`]: every request, the latches and the faults.

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
    for raw in [0, 14, 1000, u32::MAX] {
        let resp = send(&mut c, HwMsg { msg_type: raw, seq: 9, ..HwMsg::default() });
        assert_eq!(resp.status(), Status::UNKNOWN_MESSAGE);
    }
    // The bit is per response, not latched.
    assert!(send(&mut c, HwMsg::read_all_encoders()).status().is_ok());
}

#[test]
fn bad_motor_indices_get_a_status_bit() {
    let mut c = core(3);
    for t in [MsgType::ReadEncoder, MsgType::WriteDac, MsgType::EnableMotor, MsgType::DisableMotor]
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
        assert_eq!(send(&mut c, HwMsg::for_motor(MsgType::ReadEncoder, m)).status(), Status::OK);
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

/// Issue 30 (thesis 6.2.2): message 13 sets free outputs only; a mask with a channel the
/// server keeps is refused whole and writes nothing; the outputs hold while the emergency
/// stop or a fault that ends the server holds.
#[test]
fn message_13_writes_free_outputs_only() {
    let sim = SimDeltabot::new(SimParams { n_motors: 3, lockstep: true, ..SimParams::default() })
        .unwrap();
    let button = sim.estop_button();
    let mut c = HwCore::new(Box::new(sim));
    let free = c.backend().free_outputs();
    assert_eq!(free, 1 << 5 | 1 << 6 | 1 << 7, "the 626's free outputs as the thesis wires it");
    let ok = send(&mut c, HwMsg::write_outputs(1 << 6 | 1 << 7, 1 << 6));
    assert_eq!(ok.status(), Status::OK);
    assert_eq!(send(&mut c, HwMsg::read_all_encoders()).outputs, 1 << 6);
    // Every channel the server keeps, each alone and beside a free one.
    for kept in (0..32).filter(|c| free & 1 << c == 0) {
        for mask in [1u32 << kept, 1 << kept | 1 << 7] {
            let r = send(&mut c, HwMsg::write_outputs(mask, mask));
            assert_eq!(r.status(), Status::PROTECTED_OUTPUT, "DIO{kept}");
        }
    }
    assert_eq!(send(&mut c, HwMsg::read_all_encoders()).outputs, 1 << 6, "nothing written");
    // Off again, under its own mask only.
    send(&mut c, HwMsg::write_outputs(1 << 6, 0));
    assert_eq!(send(&mut c, HwMsg::read_all_encoders()).outputs, 0);
    // The emergency stop holds them, until it is cleared.
    button.store(true, std::sync::atomic::Ordering::Relaxed);
    send(&mut c, HwMsg::read_all_encoders());
    let r = send(&mut c, HwMsg::write_outputs(1 << 6, 1 << 6));
    assert_eq!(r.status(), Status::PROTECTED_OUTPUT | Status::ESTOP);
    button.store(false, std::sync::atomic::Ordering::Relaxed);
    send(&mut c, HwMsg::request(MsgType::ClearSafetyStatus));
    assert_eq!(send(&mut c, HwMsg::write_outputs(1 << 6, 1 << 6)).status(), Status::OK);
    // A watchdog trip holds them for good.
    c.trip_watchdog();
    let r = send(&mut c, HwMsg::write_outputs(1 << 6, 0));
    assert_eq!(r.status(), Status::PROTECTED_OUTPUT | Status::WATCHDOG);
    assert_eq!(send(&mut c, HwMsg::read_all_encoders()).outputs, 1 << 6);
}

/// Issue 30: the gripper of the settings closes in its travel time after message 13 turns
/// its output on, and every read response says where it is; without one it is absent.
#[test]
fn the_gripper_closes_in_its_time_and_reads_back() {
    let s = crate::backends::test_settings("[s626]\ngripper_dio = 6\ngripper_close_s = 0.01\n");
    let mut c = HwCore::for_settings(Box::new(SimDeltabot::open(&s, true).unwrap()), &s);
    let state =
        |c: &mut HwCore| qmarc_proto::Gripper(send(c, HwMsg::read_all_encoders()).gripper).name();
    assert_eq!(state(&mut c), "open");
    send(&mut c, HwMsg::write_outputs(1 << 6, 1 << 6));
    // 10 ms is 25 lock-step reads of 400 µs: closing through the 24th, closed at the 25th.
    let names: Vec<&str> = (0..25).map(|_| state(&mut c)).collect();
    assert!(names[..24].iter().all(|n| *n == "closing"), "{names:?}");
    assert_eq!(names[24], "closed");
    send(&mut c, HwMsg::write_outputs(1 << 6, 0));
    assert_eq!(state(&mut c), "opening");
    // A free output that is not the gripper's leaves it as it is.
    send(&mut c, HwMsg::write_outputs(1 << 7, 1 << 7));
    let names: Vec<&str> = (0..25).map(|_| state(&mut c)).collect();
    assert_eq!(names[22..24], ["opening", "open"], "{names:?}");
    // A bit the backend keeps for itself (an amplifier enable) is no gripper, nor is none.
    for mask in [1 << 0, 0] {
        let s = SimParams { n_motors: 3, lockstep: true, ..SimParams::default() };
        let mut c = core_with(s).with_gripper(mask, 0.01);
        let r = send(&mut c, HwMsg::read_all_encoders());
        assert_eq!(qmarc_proto::Gripper(r.gripper).name(), "none", "{mask:#x}");
    }
    let mut none = core(3);
    assert_eq!(
        qmarc_proto::Gripper(send(&mut none, HwMsg::read_all_encoders()).gripper).name(),
        "none"
    );
}
