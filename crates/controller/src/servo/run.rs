//! Running a whole move: [`Servo::run`] prepares it, paces the cycles by the ticker until the
//! path ends (then settles), a fault or a stop request, and answers each way out by disabling
//! the motors; the holds after a starved stream and at the end of a path live here too.

use super::{CycleEnd, MoveError, Phase, Servo, server_gone};
use crate::fault::{Fault, FaultKind};
use crate::link::HwLink;
use qmarc_config::Mode;
use qmarc_proto::{HwMsg, MsgType};
use qmarc_timer::{Tick, Ticker};
use std::sync::atomic::{AtomicBool, Ordering};

impl Servo {
    /// Waits for the next tick. A timer failure disables every motor and is the move's error;
    /// a stop request (Ctrl-C, the starter dying) is the `aborted` fault: `None`.
    fn next_tick(
        &mut self,
        link: &mut dyn HwLink,
        ticker: &mut dyn Ticker,
        stop: &AtomicBool,
    ) -> Result<Option<Tick>, MoveError> {
        let tick = match ticker.wait() {
            Ok(t) => t,
            Err(e) => {
                self.disable_all(link);
                return Err(e.into());
            }
        };
        if stop.load(Ordering::Relaxed) {
            let fault = Fault {
                signal: qmarc_timer::stop::signal().unwrap_or(0),
                ..Fault::new(FaultKind::Aborted, self.m.last_sample)
            };
            self.handle_fault(link, fault);
            return Ok(None);
        }
        Ok(Some(tick))
    }

    /// The fault handler for a fault a cycle reported. A stop signal (Ctrl-C, the starter
    /// dying) reaches both processes: a hwserver that shut down because of it is our abort,
    /// not a hwserver fault. Our own signal may land a moment after its response.
    fn cycle_fault(&mut self, link: &mut dyn HwLink, f: Fault, stop: &AtomicBool) {
        let f = match f.kind {
            FaultKind::HwserverShutdown => match stop_arrives(stop) {
                Some(signal) => Fault { kind: FaultKind::Aborted, signal, ..f },
                None => f,
            },
            FaultKind::Aborted => Fault { signal: qmarc_timer::stop::signal().unwrap_or(0), ..f },
            _ => f,
        };
        self.handle_fault(link, f);
    }

    /// The trajectory starved: keep servoing on the last command for the plan's hold time
    /// (the robot decelerates under control instead of coasting), then disable. Any other
    /// fault during the hold ends it at once.
    fn hold(
        &mut self,
        link: &mut dyn HwLink,
        ticker: &mut dyn Ticker,
        stop: &AtomicBool,
        starved: Fault,
    ) {
        self.m.holding = true;
        self.enter(Phase::Holding);
        let mut fault = starved;
        for _ in 0..self.plan.starve_hold_cycles {
            if stop.load(Ordering::Relaxed) {
                break;
            }
            let Ok(tick) = ticker.wait() else { break };
            if let CycleEnd::Fault(f) = self.cycle(link, &tick) {
                fault = f;
                break;
            }
        }
        self.m.holding = false;
        self.handle_fault(link, fault);
    }

    /// The path ended: hold its last command with the loop closed for the plan's settle
    /// time, so that a path that ends moving stops under control instead of coasting. Every
    /// check goes on; a fault ends the settle as it would the move.
    fn settle(
        &mut self,
        link: &mut dyn HwLink,
        ticker: &mut dyn Ticker,
        stop: &AtomicBool,
    ) -> Result<(), MoveError> {
        self.m.holding = true;
        self.m.settling = true;
        self.enter(Phase::Settling);
        for _ in 0..self.plan.settle_cycles {
            let Some(tick) = self.next_tick(link, ticker, stop)? else { break };
            if let CycleEnd::Fault(f) = self.cycle(link, &tick) {
                self.cycle_fault(link, f, stop);
                break;
            }
        }
        self.m.holding = false;
        self.m.settling = false;
        Ok(())
    }

    /// Runs the whole move: prepare, tick until the path ends (then settle), a fault or
    /// `stop`, then disable every motor and stop the safety monitoring.
    pub fn run(
        &mut self,
        link: &mut dyn HwLink,
        ticker: &mut dyn Ticker,
        stop: &AtomicBool,
    ) -> Result<(), MoveError> {
        self.prepare(link)?;
        let t0 = match ticker.start() {
            Ok(t0) => t0,
            Err(e) => {
                self.disable_all(link);
                return Err(e.into());
            }
        };
        self.set_t0(t0);
        self.enter(if self.plan.mode == Mode::Home { Phase::Homing } else { Phase::Moving });
        while let Some(tick) = self.next_tick(link, ticker, stop)? {
            match self.cycle(link, &tick) {
                CycleEnd::Continue => {}
                CycleEnd::Done => {
                    self.settle(link, ticker, stop)?;
                    break;
                }
                CycleEnd::Fault(f) if f.kind == FaultKind::TrajectoryStarved => {
                    self.hold(link, ticker, stop, f);
                    break;
                }
                CycleEnd::Fault(f) => {
                    self.cycle_fault(link, f, stop);
                    break;
                }
            }
        }
        if !server_gone(self.m.fault) {
            self.disable_all(link);
            let _ = link.exchange(&HwMsg::request(MsgType::DisableSafety));
        }
        if self.m.fault.is_none() {
            self.enter(Phase::Done);
        }
        self.end_telemetry();
        Ok(())
    }
}

/// The stop signal that arrived or is pending for this process, waiting up to 1 s for one
/// (off the loop's fast path: only after the hwserver shut down, the motors already off).
/// The starter forwards a stop to the controller before the hwserver, so its signal is
/// normally pending by then; the wait covers two signals sent at once (the kernel's
/// parent-death signal), whose handler may run late on a loaded machine.
fn stop_arrives(stop: &AtomicBool) -> Option<i32> {
    for _ in 0..1_000 {
        if let Some(signal) = qmarc_timer::stop::arrived_or_pending() {
            return Some(signal);
        }
        if stop.load(Ordering::Relaxed) {
            return Some(qmarc_timer::stop::signal().unwrap_or(0));
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
    stop.load(Ordering::Relaxed).then(|| qmarc_timer::stop::signal().unwrap_or(0))
}

impl Servo {
    /// Homing's last step (thesis 3.10.1.1), after a move that defines a homed frame ended
    /// without a fault: each motor's counter is preset to where it stands relative to home,
    /// so home reads 0 from now on whatever the settle left. Returns the read right after the
    /// preset (`None` without one). A preset the hwserver refused is a failed home, one it
    /// did not answer the hwserver lost: either is the move's fault, every motor disabled —
    /// the move's results are still written, as after any fault.
    pub fn preset_home(&mut self, link: &mut dyn HwLink) -> Option<HwMsg> {
        let home = self.homed_frame().filter(|_| self.m.fault.is_none())?;
        let n = self.plan.n_motors;
        let mut preset_all = || {
            let now = link.exchange(&HwMsg::read_all_encoders())?;
            let mut preset = HwMsg::for_motor(MsgType::ResetEncoderZero, HwMsg::ALL_MOTORS);
            for ((p, now), home) in preset.data.iter_mut().zip(now.data).zip(home).take(n) {
                *p = now - home;
            }
            let done = link.exchange(&preset)?;
            Ok::<_, crate::link::LinkError>((link.exchange(&HwMsg::read_all_encoders())?, done))
        };
        let cycle = self.cycles();
        match preset_all() {
            Ok((read, done)) if done.status().is_ok() => Some(read),
            Ok((read, done)) => {
                let f = Fault::new(FaultKind::HomingFailed, cycle);
                self.handle_fault(link, Fault { status: done.status(), ..f });
                Some(read)
            }
            Err(e) => {
                self.handle_fault(link, Fault::from_link(e, cycle));
                None
            }
        }
    }
}
