//! [`Fault`]: what ended a move, as the loop records it — a `Copy` value of numbers, decided
//! in the cycle and put into words ([`Fault::message`]) after the move.

use crate::link::LinkError;
use qmarc_proto::Status;
pub use qmarc_proto::state::FaultKind;

/// A fault, as the loop records it: numbers only, `Copy`, formatted after the move.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fault {
    /// What happened.
    pub kind: FaultKind,
    /// 0-based motor, if it concerns one.
    pub motor: Option<usize>,
    /// Servo sample index at which it was seen.
    pub cycle: u64,
    /// The hwserver status word of the response that reported it.
    pub status: Status,
    /// The link failure, for [`FaultKind::HwserverLost`] and IPC errors.
    pub link: Option<LinkError>,
    /// The signal, for [`FaultKind::Aborted`].
    pub signal: i32,
    /// Whether the hwserver acknowledged disabling every motor afterwards.
    pub disabled: bool,
    /// The offending value (following error, command, missed periods), counts.
    pub value: f64,
    /// The limit it broke.
    pub limit: f64,
    /// A following error that is the integrated one (Σ), not the instantaneous one.
    pub integrated: bool,
    /// The hwserver's timestamp of the read that showed the fault (its own clock: simulated
    /// time in lock-step), 0 if none.
    pub hw_time_ns: u64,
    /// A host stall shortly before it (real-time runs): the loop could not act meanwhile.
    pub stall: Option<HostStall>,
}

/// Servo periods that went by without a cycle, some cycles before a fault.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct HostStall {
    /// Periods missed in a row.
    pub missed: u64,
    /// Cycles between the stall and the fault.
    pub cycles_before: u64,
}

impl Fault {
    /// A fault of `kind` at sample `cycle` with nothing else known.
    #[inline]
    pub fn new(kind: FaultKind, cycle: u64) -> Fault {
        Fault {
            kind,
            motor: None,
            cycle,
            status: Status::OK,
            link: None,
            signal: 0,
            disabled: false,
            value: 0.0,
            limit: 0.0,
            integrated: false,
            hw_time_ns: 0,
            stall: None,
        }
    }

    /// The fault a non-zero status word means, most severe first; `None` for a clean status.
    #[inline]
    pub fn from_status(status: Status, cycle: u64) -> Option<Fault> {
        if status.is_ok() {
            return None;
        }
        let (kind, motor) = if status.contains(Status::WATCHDOG) {
            (FaultKind::Watchdog, None)
        } else if status.contains(Status::SHUTDOWN) {
            (FaultKind::HwserverShutdown, None)
        } else if status.contains(Status::HARDWARE_FAULT) {
            (FaultKind::HardwareFault, None)
        } else if status.contains(Status::ESTOP) {
            (FaultKind::EmergencyStop, None)
        } else if let Some((m, _)) = status.first_limit() {
            (FaultKind::LimitSwitch, Some(m))
        } else if let Some(m) = status.first_encoder_overflow() {
            (FaultKind::EncoderFault, Some(m))
        } else {
            (FaultKind::ProtocolError, None)
        };
        Some(Fault { motor, status, ..Fault::new(kind, cycle) })
    }

    /// A lost or failed link at sample `cycle`; a wait a stop signal ended is an abort.
    #[inline]
    pub fn from_link(e: LinkError, cycle: u64) -> Fault {
        let kind = match e {
            LinkError::Stopped { .. } => FaultKind::Aborted,
            _ => FaultKind::HwserverLost,
        };
        Fault { link: Some(e), ..Fault::new(kind, cycle) }
    }

    /// The message for the terminal and `summary.json`, motors 1-based.
    pub fn message(&self) -> String {
        let what = match self.kind {
            FaultKind::LimitSwitch
            | FaultKind::HwserverLost
            | FaultKind::HwserverShutdown
            | FaultKind::Watchdog
            | FaultKind::HardwareFault
            | FaultKind::EncoderFault
            | FaultKind::ProtocolError
            | FaultKind::EmergencyStop
            | FaultKind::Aborted => self.what_of_the_hardware(),
            _ => self.what_of_the_motion(),
        };
        let after = if self.disabled {
            "all motors disabled"
        } else {
            "the hwserver did not acknowledge disabling the motors (on hardware the charge-pump \
             relay drops them when the hwserver stops)"
        };
        // Only where a stall can be why: the plant ran on its last output (an error, a
        // switch or a limit passed), or a process waited too long for the other. Not for a
        // stop signal, the emergency stop or the hardware's own faults — nor an overrun,
        // which is the stall itself.
        let stall_can_cause = matches!(
            self.kind,
            FaultKind::FollowingError
                | FaultKind::SoftwareLimit
                | FaultKind::LimitSwitch
                | FaultKind::TooMuchTravel
                | FaultKind::HomingFailed
                | FaultKind::Watchdog
                | FaultKind::HwserverLost
        );
        let stall = match self.stall {
            Some(st) if stall_can_cause => format!(
                " ({} servo periods went by without a cycle {} cycles before: a host stall, the \
                 motors running on their last output meanwhile; without PREEMPT_RT a loaded \
                 host stalls like that)",
                st.missed, st.cycles_before
            ),
            _ => String::new(),
        };
        format!("{what} at cycle {}{stall}; {after}", self.cycle)
    }

    /// What went wrong with the hardware, the hwserver or the run (a stop signal).
    fn what_of_the_hardware(&self) -> String {
        match self.kind {
            // Seen by a generator watching the switches itself (jog): it says which.
            FaultKind::LimitSwitch if self.status.is_ok() => "a limit switch tripped".to_string(),
            FaultKind::LimitSwitch => {
                let m = self.motor.unwrap_or(0);
                let side =
                    if self.status.contains(Status::limit_top(m)) { "top" } else { "bottom" };
                format!("motor {} hit its {side} limit switch", m + 1)
            }
            FaultKind::HwserverLost => match self.link {
                Some(e @ LinkError::Lost { server_alive: true, .. }) => format!(
                    "lost the hwserver: {e} (without PREEMPT_RT, host stalls can do that: raise \
                     hwserver.response_timeout_periods)"
                ),
                Some(e) => format!("lost the hwserver: {e}"),
                None => "lost the hwserver".to_string(),
            },
            FaultKind::HwserverShutdown => {
                "the hwserver was stopped and disabled the motors".to_string()
            }
            FaultKind::Watchdog => "the hwserver's watchdog fired: the controller was silent for \
                longer than hwserver.watchdog_periods with motors enabled (without PREEMPT_RT, \
                host stalls of a few ms can do that: raise the limit)"
                .to_string(),
            FaultKind::HardwareFault => "the hardware reported an error".to_string(),
            FaultKind::EmergencyStop => "EMERGENCY STOP: the emergency-stop chain opened \
                (pressed, or a broken wire) and the hwserver disabled every motor in the read \
                that saw it; every move is refused until the chain is closed again"
                .to_string(),
            FaultKind::EncoderFault => format!(
                "motor {} encoder fault: its count jumped further than the motor can move",
                self.motor.map_or(0, |m| m + 1)
            ),
            FaultKind::ProtocolError => format!("the hwserver refused a request: {}", self.status),
            FaultKind::Aborted => format!(
                "aborted by {}",
                if self.signal == 0 {
                    "a stop signal"
                } else {
                    qmarc_timer::stop::signal_name(self.signal)
                }
            ),
            _ => String::new(),
        }
    }

    /// What went wrong with the motion: the path, the law, the limits, the controller.
    fn what_of_the_motion(&self) -> String {
        match self.kind {
            FaultKind::TrajectoryStarved => {
                "the knot stream ran dry before it ended (motors held, then disabled)".to_string()
            }
            FaultKind::TrajectoryError => "the trajectory failed".to_string(),
            FaultKind::FollowingError => format!(
                "motor {} {} following error {:.1} counts passed its limit {}",
                self.motor.map_or(0, |m| m + 1),
                if self.integrated { "integrated" } else { "instantaneous" },
                self.value,
                self.limit
            ),
            FaultKind::SoftwareLimit => format!(
                "motor {} was commanded to {:.1} counts, past its software limit {}",
                self.motor.map_or(0, |m| m + 1),
                self.value,
                self.limit
            ),
            FaultKind::Overrun => format!(
                "{} servo periods in a row went by without a cycle (limit {}: without \
                 PREEMPT_RT, host stalls of a few ms can do that; raise safety.max_missed_in_row)",
                self.value, self.limit
            ),
            FaultKind::HomingFailed if self.status.contains(Status::NOT_KEPT) => {
                "homing set the frame, but it could not be kept (the hwserver says where and \
                 why): the next run would find the robot unhomed"
                    .to_string()
            }
            FaultKind::HomingFailed if self.status.contains(Status::HARDWARE_FAULT) => {
                "homing could not preset the counters: hardware fault".to_string()
            }
            FaultKind::HomingFailed => "homing failed".to_string(),
            FaultKind::TooMuchTravel => {
                "the open-loop check stopped: a motor moved too far".to_string()
            }
            FaultKind::ControllerLost => "the controller died".to_string(),
            FaultKind::BadCommand => format!(
                "the trajectory commanded motor {} to {} counts, not a finite number: the \
                 command never reached the law",
                self.motor.map_or(0, |m| m + 1),
                self.value
            ),
            FaultKind::BadOutput => format!(
                "the servo law's output for motor {} was not a finite number or not a DAC code \
                 (±{}): it never reached the DAC",
                self.motor.map_or(0, |m| m + 1),
                qmarc_proto::DAC_MAX
            ),
            _ => String::new(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_words_map_to_fault_kinds() {
        let check = |s: Status, kind: FaultKind, motor: Option<usize>| {
            let f = Fault::from_status(s, 7).unwrap();
            assert_eq!((f.kind, f.motor, f.cycle), (kind, motor, 7), "{s}");
        };
        assert_eq!(Fault::from_status(Status::OK, 1), None);
        check(Status::limit_bottom(2), FaultKind::LimitSwitch, Some(2));
        check(Status::limit_top(0) | Status::WATCHDOG, FaultKind::Watchdog, None);
        check(Status::SHUTDOWN, FaultKind::HwserverShutdown, None);
        check(Status::encoder_overflow(1), FaultKind::EncoderFault, Some(1));
        check(Status::UNKNOWN_MESSAGE, FaultKind::ProtocolError, None);
        let mut f = Fault::from_status(Status::limit_top(0), 1234).unwrap();
        assert!(f.message().ends_with(
            "the hwserver did not acknowledge disabling the motors (on hardware the charge-pump \
             relay drops them when the hwserver stops)"
        ));
        f.disabled = true;
        assert_eq!(
            f.message(),
            "motor 1 hit its top limit switch at cycle 1234; all motors disabled"
        );
        assert_eq!(f.kind.to_string(), "limit_switch");
    }

    /// Issue 32: a stop signal that ended a wait for the hwserver is an abort (exit code
    /// INTERRUPTED), every other link failure is a lost hwserver, and the link is kept.
    #[test]
    fn a_stop_during_a_wait_is_an_abort_and_any_other_link_failure_a_lost_hwserver() {
        let stopped = LinkError::Stopped { waited_ns: 2_000_000 };
        let f = Fault::from_link(stopped, 11);
        assert_eq!((f.kind, f.cycle, f.link), (FaultKind::Aborted, 11, Some(stopped)));
        for e in [
            LinkError::Lost { waited_ns: 1, server_alive: false },
            LinkError::Ipc { op: "send" },
            LinkError::Sequence { expected: 3, got: 4 },
        ] {
            let f = Fault::from_link(e, 12);
            assert_eq!((f.kind, f.cycle, f.link), (FaultKind::HwserverLost, 12, Some(e)));
        }
    }

    /// Issue 32: the most severe condition of a status word names the fault — the watchdog,
    /// a stop, the hardware, the emergency stop, then a switch (the first motor's), then an
    /// encoder; the word itself is kept.
    #[test]
    fn the_most_severe_condition_names_the_fault() {
        let kind = |s: Status| Fault::from_status(s, 0).map(|f| (f.kind, f.motor, f.status));
        let every = Status::WATCHDOG
            | Status::SHUTDOWN
            | Status::HARDWARE_FAULT
            | Status::ESTOP
            | Status::limit_top(1)
            | Status::encoder_overflow(0);
        let mut s = every;
        for (dropped, next) in [
            (Status::WATCHDOG, FaultKind::HwserverShutdown),
            (Status::SHUTDOWN, FaultKind::HardwareFault),
            (Status::HARDWARE_FAULT, FaultKind::EmergencyStop),
            (Status::ESTOP, FaultKind::LimitSwitch),
            (Status::limit_top(1), FaultKind::EncoderFault),
        ] {
            let before = kind(s).unwrap().0;
            s = s & !dropped;
            let (k, _, status) = kind(s).unwrap();
            assert_eq!(k, next, "after dropping {dropped} from a word that gave {before}");
            assert_eq!(status, s);
        }
        assert_eq!(kind(every).unwrap().0, FaultKind::Watchdog);
        assert_eq!(kind(Status::ESTOP), Some((FaultKind::EmergencyStop, None, Status::ESTOP)));
        let two = Status::limit_bottom(2) | Status::limit_top(1);
        assert_eq!(kind(two), Some((FaultKind::LimitSwitch, Some(1), two)));
        let enc = Status::encoder_overflow(2);
        assert_eq!(kind(enc), Some((FaultKind::EncoderFault, Some(2), enc)));
    }

    /// Issue 32: every kind says what happened in words of its own, naming the motor
    /// (1-based) where it concerns one, and whether the motors were disabled.
    #[test]
    fn every_kind_says_what_happened() {
        let mut seen = std::collections::BTreeMap::new();
        for kind in FaultKind::ALL {
            let f = Fault {
                motor: Some(1),
                value: 1234.5,
                limit: 1000.0,
                disabled: true,
                ..Fault::new(kind, 77)
            };
            let m = f.message();
            assert!(m.ends_with(" at cycle 77; all motors disabled"), "{kind}: {m}");
            let what = m.trim_end_matches(" at cycle 77; all motors disabled").to_string();
            assert!(what.len() > 10, "{kind}: {m}");
            assert!(seen.insert(what.clone(), kind).is_none(), "{kind} and another say {what}");
        }
        let says = |f: Fault, what: &str| {
            let m = f.message();
            assert!(m.starts_with(what), "{m}");
        };
        let on2 =
            |kind| Fault { motor: Some(1), value: 1234.5, limit: 1000.0, ..Fault::new(kind, 1) };
        says(
            on2(FaultKind::FollowingError),
            "motor 2 instantaneous following error 1234.5 counts passed its limit 1000",
        );
        says(
            Fault { integrated: true, ..on2(FaultKind::FollowingError) },
            "motor 2 integrated following error",
        );
        says(
            on2(FaultKind::SoftwareLimit),
            "motor 2 was commanded to 1234.5 counts, past its software limit 1000",
        );
        says(on2(FaultKind::BadCommand), "the trajectory commanded motor 2 to 1234.5 counts");
        says(on2(FaultKind::BadOutput), "the servo law's output for motor 2 was not");
        says(on2(FaultKind::EncoderFault), "motor 2 encoder fault");
        says(on2(FaultKind::EmergencyStop), "EMERGENCY STOP: the emergency-stop chain opened");
        says(
            Fault::from_status(Status::limit_bottom(2), 1).unwrap(),
            "motor 3 hit its bottom limit switch",
        );
        says(Fault::new(FaultKind::LimitSwitch, 1), "a limit switch tripped");
        says(Fault { signal: 15, ..Fault::new(FaultKind::Aborted, 1) }, "aborted by SIGTERM");
        says(Fault::new(FaultKind::Aborted, 1), "aborted by a stop signal");
        says(
            Fault::from_link(LinkError::Ipc { op: "send" }, 1),
            "lost the hwserver: iceoryx2 send failed",
        );
        says(Fault::new(FaultKind::HwserverLost, 1), "lost the hwserver at cycle 1");
        says(
            Fault::from_status(Status::UNKNOWN_MESSAGE, 1).unwrap(),
            "the hwserver refused a request: ",
        );
    }

    /// Issue 9, item 7: a timing fault that a host stall can cause says which setting to
    /// raise; a dead hwserver does not (no setting helps).
    #[test]
    fn timing_faults_name_the_setting_to_raise() {
        let overrun = Fault { value: 300.0, limit: 250.0, ..Fault::new(FaultKind::Overrun, 9) };
        assert!(overrun.message().starts_with(
            "300 servo periods in a row went by without a cycle (limit 250: without PREEMPT_RT, \
             host stalls of a few ms can do that; raise safety.max_missed_in_row) at cycle 9"
        ));
        let lost = |server_alive| {
            Fault::from_link(LinkError::Lost { waited_ns: 100_000_000, server_alive }, 5).message()
        };
        assert!(
            lost(true).starts_with(
                "lost the hwserver: no response from the hwserver for 100.0 ms (server process \
                 alive) (without PREEMPT_RT, host stalls can do that: raise \
                 hwserver.response_timeout_periods) at cycle 5"
            ),
            "{}",
            lost(true)
        );
        assert!(!lost(false).contains("raise"), "{}", lost(false));
        let watchdog = Fault::from_status(Status::WATCHDOG, 3).unwrap().message();
        assert!(watchdog.contains("raise the limit"), "{watchdog}");
        assert!(watchdog.contains("hwserver.watchdog_periods"), "{watchdog}");
    }

    /// Issue 28: a fault after a host stall says so, except an overrun (which is the stall);
    /// a failed homing says whether its frame could not be kept or its preset failed.
    #[test]
    fn stalls_and_homing_presets_are_said() {
        let stall = Some(HostStall { missed: 7, cycles_before: 40 });
        let said = "(7 servo periods went by without a cycle 40 cycles before: a host stall";
        let fe = Fault { stall, ..Fault::new(FaultKind::FollowingError, 9) };
        assert!(fe.message().contains(said), "{}", fe.message());
        let overrun =
            Fault { stall, value: 30.0, limit: 25.0, ..Fault::new(FaultKind::Overrun, 9) };
        assert!(!overrun.message().contains("host stall 40"), "{}", overrun.message());
        assert!(!overrun.message().contains(said), "{}", overrun.message());
        // Issue 42: only a fault a stall can cause says it; a stop signal, the emergency stop
        // or the hardware's own faults are no stall's doing.
        let caused = [
            FaultKind::FollowingError,
            FaultKind::SoftwareLimit,
            FaultKind::LimitSwitch,
            FaultKind::TooMuchTravel,
            FaultKind::HomingFailed,
            FaultKind::Watchdog,
            FaultKind::HwserverLost,
        ];
        for kind in FaultKind::ALL {
            let f = Fault { stall, ..Fault::new(kind, 9) };
            let says = f.message().contains("servo periods went by");
            assert_eq!(says, caused.contains(&kind), "{kind:?}: {}", f.message());
        }
        let homing = |status| Fault { status, ..Fault::new(FaultKind::HomingFailed, 3) }.message();
        assert!(
            homing(Status::NOT_KEPT).starts_with("homing set the frame, but it could not be kept")
        );
        assert!(homing(Status::HARDWARE_FAULT).starts_with("homing could not preset the counters"));
        assert!(
            homing(Status::OK).starts_with("homing failed at cycle 3"),
            "{}",
            homing(Status::OK)
        );
    }
}
