//! The conformance suite: what every backend must do, checked through the server's core the
//! way the controller uses it. `tests/conformance.rs` runs every check on every registered
//! backend ([`crate::backends::BACKENDS`]) that has a [`Rig`] at hand — the simulator always,
//! a card when an environment variable names its device.
//!
//! The checks: amplifiers enable and disable one by one and all at once; every way out of a
//! move (disable one, disable all, the exit message, the watchdog, a stop signal, an error
//! path) leaves the DACs at 0 V and the amplifiers off; a limit switch is reported by the
//! first read after it trips; the software position runs on through the 24-bit counter's
//! wrap; after the watchdog enabling is refused; homing's preset makes the position read what
//! it asks and the frame homed; an open emergency-stop chain disables every motor in the read
//! that sees it and refuses every enable until it is closed and the status cleared.

use crate::backend::Backend;
use crate::core::HwCore;
use qmarc_proto::{COUNTER_BITS, HwMsg, MAX_MOTORS, MotorFlags, MsgType, Status};

/// What the suite needs besides the backend itself: fresh instances, and a way to act on the
/// world around the hardware.
pub trait Rig {
    /// A fresh backend of `n_motors` motors whose positions start `start_counts` from zero,
    /// in a homed frame, amplifiers off.
    fn backend(&mut self, n_motors: usize, start_counts: f64) -> Box<dyn Backend>;

    /// Makes `motor`'s top (or bottom) limit switch active and leaves the motor stopped and
    /// disabled. The simulator drives the motor into the switch; a card's rig sets the input.
    fn trip_switch(&mut self, core: &mut HwCore, motor: usize, top: bool);

    /// What the hardware outputs now, seen from outside it (a card's rig reads its fake's
    /// registers); by default what the backend says it wrote.
    fn outputs(&mut self, core: &HwCore) -> Option<crate::backend::Outputs> {
        core.backend().outputs()
    }

    /// Opens (`open`) or closes the emergency-stop chain of the last backend made; false if
    /// the rig has no chain to open (the check is then skipped, and says so).
    fn estop(&mut self, open: bool) -> bool {
        let _ = open;
        false
    }
}

/// One check of the suite.
#[derive(Clone, Copy)]
pub struct Check {
    /// Its name in reports.
    pub name: &'static str,
    /// Runs it; `Err` says what the backend did wrong.
    pub run: fn(&mut dyn Rig) -> Result<(), String>,
}

/// Every check.
pub const CHECKS: &[Check] = &[
    Check { name: "enable_and_disable", run: enable_and_disable },
    Check { name: "dacs_zero_on_every_exit_path", run: dacs_zero_on_every_exit_path },
    Check { name: "limit_switch_within_one_read", run: limit_switch_within_one_read },
    Check { name: "counter_wraps_at_24_bits", run: counter_wraps_at_24_bits },
    Check { name: "watchdog_makes_safe_and_refuses", run: watchdog_makes_safe_and_refuses },
    Check { name: "homing_preset", run: homing_preset },
    Check { name: "estop_disables_at_once_and_latches", run: estop_disables_at_once_and_latches },
];

fn ask(core: &mut HwCore, req: HwMsg) -> HwMsg {
    core.handle(&req)
}

fn enabled(core: &mut HwCore, motor: usize) -> bool {
    MotorFlags(ask(core, HwMsg::read_all_encoders()).aux[motor]).enabled()
}

fn expect(ok: bool, what: impl FnOnce() -> String) -> Result<(), String> {
    if ok { Ok(()) } else { Err(what()) }
}

/// The amplifiers that are on, as the hardware's outputs say (a card's rig: its pins) and
/// as the server's flags say; an error if the two disagree.
fn amplifiers(rig: &mut dyn Rig, core: &mut HwCore) -> Result<[bool; MAX_MOTORS], String> {
    let n = core.n_motors();
    let flags: Vec<bool> = (0..n).map(|m| enabled(core, m)).collect();
    let o = rig.outputs(core).ok_or("the backend cannot read its outputs back")?;
    expect(o.enabled[..n] == flags[..], || {
        format!("the outputs enable {:?}, the server says {flags:?}", &o.enabled[..n])
    })?;
    Ok(o.enabled)
}

fn enable_and_disable(rig: &mut dyn Rig) -> Result<(), String> {
    let mut core = HwCore::new(rig.backend(3, 0.0));
    let none = [false; MAX_MOTORS];
    expect(amplifiers(rig, &mut core)? == none, || "enabled at start".into())?;
    // Each motor alone, on and off: its amplifier and no other.
    for m in 0..3 {
        let st = ask(&mut core, HwMsg::for_motor(MsgType::EnableMotor, m as u32)).status();
        expect(st.is_ok(), || format!("enabling motor {}: {st}", m + 1))?;
        let on = amplifiers(rig, &mut core)?;
        expect(on == std::array::from_fn(|k| k == m), || {
            format!("motor {} alone enabled, the amplifiers on: {on:?}", m + 1)
        })?;
        ask(&mut core, HwMsg::for_motor(MsgType::DisableMotor, m as u32));
        let on = amplifiers(rig, &mut core)?;
        expect(on == none, || format!("after DisableMotor {}: {on:?}", m + 1))?;
    }
    for m in 0..3 {
        ask(&mut core, HwMsg::for_motor(MsgType::EnableMotor, m));
    }
    let on = amplifiers(rig, &mut core)?;
    expect(on[..3] == [true; 3], || format!("all enabled: {on:?}"))?;
    ask(&mut core, HwMsg::request(MsgType::DisableAll));
    expect(!core.any_enabled(), || "a motor enabled after DisableAll".into())?;
    let on = amplifiers(rig, &mut core)?;
    expect(on == none, || format!("after DisableAll: {on:?}"))
}

/// A way out of a move, by name.
type ExitPath = (&'static str, fn(&mut HwCore));

/// Every way out of a move, applied to a core whose motors are enabled and driven.
fn exit_paths() -> [ExitPath; 6] {
    [
        ("DisableMotor", |c| {
            for m in 0..c.n_motors() {
                c.handle(&HwMsg::for_motor(MsgType::DisableMotor, m as u32));
            }
        }),
        ("DisableAll", |c| {
            c.handle(&HwMsg::request(MsgType::DisableAll));
        }),
        ("the exit message", |c| {
            c.handle(&HwMsg::request(MsgType::Exit));
        }),
        ("the watchdog", HwCore::trip_watchdog),
        ("a stop signal", HwCore::shut_down),
        ("an error path", HwCore::safe_state),
    ]
}

fn dacs_zero_on_every_exit_path(rig: &mut dyn Rig) -> Result<(), String> {
    for (name, exit) in exit_paths() {
        let mut core = HwCore::new(rig.backend(2, 0.0));
        for m in 0..2 {
            ask(&mut core, HwMsg::for_motor(MsgType::EnableMotor, m));
        }
        ask(&mut core, HwMsg::write_all_dacs(&[1000, -1000, 0, 0]));
        let driven = rig.outputs(&core).ok_or("the backend cannot read its outputs back")?;
        expect(driven.dac[..2] == [1000, -1000], || format!("DACs not written: {driven:?}"))?;
        exit(&mut core);
        let o = rig.outputs(&core).ok_or("the backend cannot read its outputs back")?;
        expect(o.dac == [0; MAX_MOTORS] && o.enabled == [false; MAX_MOTORS], || {
            format!("after {name}: outputs {o:?}, not 0 V with the amplifiers off")
        })?;
    }
    Ok(())
}

fn limit_switch_within_one_read(rig: &mut dyn Rig) -> Result<(), String> {
    for motor in [0, 2] {
        for top in [true, false] {
            let bit = if top { Status::limit_top(motor) } else { Status::limit_bottom(motor) };
            let mut core = HwCore::new(rig.backend(3, 0.0));
            ask(&mut core, HwMsg::request(MsgType::EnableSafety));
            let st = ask(&mut core, HwMsg::read_all_encoders()).status();
            expect(st.is_ok(), || format!("no switch tripped yet, the read says {st}"))?;
            rig.trip_switch(&mut core, motor, top);
            ask(&mut core, HwMsg::request(MsgType::ClearSafetyStatus));
            ask(&mut core, HwMsg::request(MsgType::EnableSafety));
            // That switch and no other, in the status word and in each motor's flags.
            let r = ask(&mut core, HwMsg::read_all_encoders());
            let st = r.status();
            expect(st == bit, || format!("the first read after the switch says {st}, not {bit}"))?;
            for k in 0..3 {
                let f = MotorFlags(r.aux[k]);
                let want = if k == motor { (top, !top) } else { (false, false) };
                expect((f.top(), f.bottom()) == want, || {
                    format!("motor {}'s flags say top {}, bottom {}", k + 1, f.top(), f.bottom())
                })?;
            }
            let st = ask(&mut core, HwMsg::write_all_dacs(&[0; MAX_MOTORS])).status();
            expect(st == bit, || format!("the trip is not latched as {bit}: {st}"))?;
        }
    }
    Ok(())
}

fn counter_wraps_at_24_bits(rig: &mut dyn Rig) -> Result<(), String> {
    let wrap = f64::from(1u32 << (COUNTER_BITS - 1));
    let start = wrap - 200.0;
    let mut core = HwCore::new(rig.backend(1, start));
    let first = ask(&mut core, HwMsg::read_all_encoders()).data[0];
    expect((first - start).abs() < 2.0, || format!("starts at {first}, not {start}"))?;
    ask(&mut core, HwMsg::for_motor(MsgType::EnableMotor, 0));
    ask(&mut core, HwMsg::write_all_dacs(&[400, 0, 0, 0]));
    let mut last = first;
    for _ in 0..100_000 {
        let r = ask(&mut core, HwMsg::read_all_encoders());
        let st = r.status() & !Status::LIMIT_MASK;
        expect(st.is_ok(), || format!("at {}: {st}", r.data[0]))?;
        expect(r.data[0] >= last, || format!("went back from {last} to {}", r.data[0]))?;
        last = r.data[0];
        if last > wrap + 200.0 {
            ask(&mut core, HwMsg::request(MsgType::DisableAll));
            return Ok(());
        }
    }
    Err(format!("never crossed the wrap at {wrap}: at {last}"))
}

fn watchdog_makes_safe_and_refuses(rig: &mut dyn Rig) -> Result<(), String> {
    let mut core = HwCore::new(rig.backend(2, 0.0));
    ask(&mut core, HwMsg::for_motor(MsgType::EnableMotor, 0));
    core.trip_watchdog();
    expect(!core.any_enabled(), || "enabled after the watchdog".into())?;
    let st = ask(&mut core, HwMsg::for_motor(MsgType::EnableMotor, 0)).status();
    expect(st.contains(Status::WATCHDOG), || format!("enabling after the watchdog: {st}"))?;
    expect(!core.any_enabled(), || "an enable was obeyed after the watchdog".into())
}

fn homing_preset(rig: &mut dyn Rig) -> Result<(), String> {
    let mut core = HwCore::new(rig.backend(2, 123.0));
    let mut preset = HwMsg::for_motor(MsgType::ResetEncoderZero, HwMsg::ALL_MOTORS);
    preset.data[..2].copy_from_slice(&[-37.0, 5.4]);
    ask(&mut core, preset);
    let r = ask(&mut core, HwMsg::read_all_encoders());
    expect(r.data[..2] == [-37.0, 5.0], || format!("reads {:?} after the preset", &r.data[..2]))?;
    expect((0..2).all(|m| MotorFlags(r.aux[m]).homed()), || "not homed after the preset".into())?;
    ask(&mut core, HwMsg::for_motor(MsgType::ResetEncoderZero, 1));
    let r = ask(&mut core, HwMsg::read_all_encoders());
    expect(r.data[..2] == [-37.0, 0.0], || {
        format!("reads {:?} after zeroing motor 2", &r.data[..2])
    })
}

fn estop_disables_at_once_and_latches(rig: &mut dyn Rig) -> Result<(), String> {
    let mut core = HwCore::new(rig.backend(2, 0.0));
    let enable = |core: &mut HwCore| {
        (0..2).fold(Status::OK, |st, m| {
            st | ask(core, HwMsg::for_motor(MsgType::EnableMotor, m)).status()
        })
    };
    expect(enable(&mut core).is_ok(), || "enabling with the chain closed".into())?;
    ask(&mut core, HwMsg::write_all_dacs(&[1000, -1000, 0, 0]));
    if !rig.estop(true) {
        eprintln!("the rig has no emergency-stop chain to open: check skipped");
        return Ok(());
    }
    let st = ask(&mut core, HwMsg::read_all_encoders()).status();
    expect(st == Status::ESTOP, || format!("the read after the chain opened says {st}"))?;
    let off = |rig: &mut dyn Rig, core: &HwCore, when: &str| {
        let o = rig.outputs(core).ok_or("the backend cannot read its outputs back")?;
        expect(o.dac == [0; MAX_MOTORS] && o.enabled == [false; MAX_MOTORS], || {
            format!("{when}: outputs {o:?}, not 0 V with the amplifiers off")
        })
    };
    off(rig, &core, "in the read that saw the chain open")?;
    for (open, when) in [(true, "with the chain open"), (false, "closed again but not cleared")] {
        rig.estop(open);
        let st = enable(&mut core);
        ask(&mut core, HwMsg::write_all_dacs(&[1000, -1000, 0, 0]));
        expect(st.contains(Status::ESTOP), || format!("enabling {when}: {st}"))?;
        off(rig, &core, when)?;
        if open {
            let st = ask(&mut core, HwMsg::request(MsgType::ClearSafetyStatus)).status();
            expect(st.contains(Status::ESTOP), || format!("cleared {when}: {st}"))?;
        }
    }
    let st = ask(&mut core, HwMsg::request(MsgType::ClearSafetyStatus)).status();
    expect(st.is_ok(), || format!("clearing with the chain closed: {st}"))?;
    expect(enable(&mut core).is_ok(), || "enabling after the chain closed and cleared".into())?;
    ask(&mut core, HwMsg::request(MsgType::DisableAll));
    Ok(())
}
