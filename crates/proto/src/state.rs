//! The words of a move that cross process boundaries: its [`Phase`] and the [`FaultKind`] that
//! ended it. Their numbers are part of the wire — the telemetry sample's `phase` and `fault`,
//! the progress page's phase — so each variant has its explicit discriminant: reordering or
//! inserting a variant cannot change what a v1 sample means, and a new one takes the next
//! free number.

/// Where a move is. The loop goes Idle → Preparing → Moving (or Homing) → Settling → Done, or
/// to Fault from Preparing onwards; Holding lies between Moving and Fault when a knot stream
/// runs dry. The number is [`Phase::wire`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u32)]
pub enum Phase {
    /// Nothing happened yet.
    Idle = 0,
    /// Reading the robot, starting the path, enabling the motors.
    Preparing = 1,
    /// Homing, one motor at a time.
    Homing = 2,
    /// Following the path.
    Moving = 3,
    /// Holding the last command after the trajectory starved.
    Holding = 4,
    /// The path ended: holding its last command with the loop closed for the settle time.
    Settling = 5,
    /// The path ended and settled; motors disabled.
    Done = 6,
    /// A fault ended the move; motors disabled where the hwserver could be reached.
    Fault = 7,
}

impl Phase {
    /// Every phase, in the order of their codes.
    pub const ALL: [Phase; 8] = [
        Phase::Idle,
        Phase::Preparing,
        Phase::Homing,
        Phase::Moving,
        Phase::Holding,
        Phase::Settling,
        Phase::Done,
        Phase::Fault,
    ];

    /// Its number on the wire (telemetry, the progress page).
    pub fn wire(self) -> u32 {
        self as u32
    }

    /// The phase of wire number `wire`, if one has it.
    pub fn from_wire(wire: u32) -> Option<Phase> {
        Phase::ALL.into_iter().find(|p| p.wire() == wire)
    }

    /// What it is called in messages.
    pub fn name(self) -> &'static str {
        match self {
            Phase::Idle => "not started",
            Phase::Preparing => "preparing",
            Phase::Homing => "homing",
            Phase::Moving => "moving",
            Phase::Holding => "holding (stream ran dry)",
            Phase::Settling => "settling at the end of the path",
            Phase::Done => "done",
            Phase::Fault => "fault",
        }
    }

    /// What it is called in a serving session's messages: its loop's moving phase is the
    /// session serving, whether the robot moves or rests.
    pub fn name_serving(self) -> &'static str {
        match self {
            Phase::Moving => "serving",
            p => p.name(),
        }
    }
}

/// What ended a move early. In `summary.json` it is the snake-case name
/// ([`FaultKind::name`]); on the wire [`FaultKind::wire`] of it (its number among
/// [`FaultKind::ALL`] + 1, 0 for none).
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[repr(u32)]
pub enum FaultKind {
    /// A limit switch tripped.
    LimitSwitch = 0,
    /// The hwserver stopped answering or died.
    HwserverLost = 1,
    /// The hwserver was stopped by a signal and refuses to drive.
    HwserverShutdown = 2,
    /// The hwserver's watchdog fired.
    Watchdog = 3,
    /// The hardware reported an error.
    HardwareFault = 4,
    /// An encoder count jumped further than the motor can move (a counter or cable fault).
    EncoderFault = 5,
    /// The hwserver did not understand a request (a bug on one side).
    ProtocolError = 6,
    /// A stop signal (Ctrl-C, SIGTERM) aborted the move.
    Aborted = 7,
    /// The trajectory generator had no command for a sample.
    TrajectoryStarved = 8,
    /// The trajectory generator could not go on (a bad knot in a stream).
    TrajectoryError = 9,
    /// |command − actual| or |Σ (command − actual)| went past its limit.
    FollowingError = 10,
    /// A command went outside the software position limits.
    SoftwareLimit = 11,
    /// Too many servo periods in a row went by without a cycle.
    Overrun = 12,
    /// Homing could not find, clear or leave a switch as it should.
    HomingFailed = 13,
    /// The controller process died or stopped responding (reported by the starter).
    ControllerLost = 14,
    /// The trajectory commanded a position that is not a finite number.
    BadCommand = 15,
    /// The servo law's output was not a finite number (or not a DAC code).
    BadOutput = 16,
    /// The emergency-stop chain opened (pressed, or a broken wire).
    EmergencyStop = 17,
    /// A motor moved further than a move with the loop open allows (`check`).
    TooMuchTravel = 18,
}

impl FaultKind {
    /// Every kind, in the order of their wire numbers ([`FaultKind::wire`]).
    pub const ALL: [FaultKind; 19] = [
        FaultKind::LimitSwitch,
        FaultKind::HwserverLost,
        FaultKind::HwserverShutdown,
        FaultKind::Watchdog,
        FaultKind::HardwareFault,
        FaultKind::EncoderFault,
        FaultKind::ProtocolError,
        FaultKind::Aborted,
        FaultKind::TrajectoryStarved,
        FaultKind::TrajectoryError,
        FaultKind::FollowingError,
        FaultKind::SoftwareLimit,
        FaultKind::Overrun,
        FaultKind::HomingFailed,
        FaultKind::ControllerLost,
        FaultKind::BadCommand,
        FaultKind::BadOutput,
        FaultKind::EmergencyStop,
        FaultKind::TooMuchTravel,
    ];

    /// Its number among [`FaultKind::ALL`].
    fn number(self) -> u32 {
        self as u32
    }

    /// The kind of number `n` among [`FaultKind::ALL`], if one has it.
    fn of_number(n: u32) -> Option<FaultKind> {
        FaultKind::ALL.into_iter().find(|k| k.number() == n)
    }

    /// A fault or none on the wire (a telemetry sample's, a command's answer's, the
    /// progress page's `fault`): its number + 1, 0 for no fault.
    pub fn wire(fault: Option<FaultKind>) -> u32 {
        fault.map_or(0, |k| k.number() + 1)
    }

    /// The fault wire number `wire` names (None for 0 and for unknown numbers).
    pub fn from_wire(wire: u32) -> Option<FaultKind> {
        wire.checked_sub(1).and_then(FaultKind::of_number)
    }

    /// The `kind` string of `summary.json`.
    pub fn name(self) -> &'static str {
        match self {
            FaultKind::LimitSwitch => "limit_switch",
            FaultKind::HwserverLost => "hwserver_lost",
            FaultKind::HwserverShutdown => "hwserver_shutdown",
            FaultKind::Watchdog => "watchdog",
            FaultKind::HardwareFault => "hardware_fault",
            FaultKind::EncoderFault => "encoder_fault",
            FaultKind::ProtocolError => "protocol_error",
            FaultKind::Aborted => "aborted",
            FaultKind::TrajectoryStarved => "trajectory_starved",
            FaultKind::TrajectoryError => "trajectory_error",
            FaultKind::FollowingError => "following_error",
            FaultKind::SoftwareLimit => "software_limit",
            FaultKind::Overrun => "overrun",
            FaultKind::HomingFailed => "homing_failed",
            FaultKind::ControllerLost => "controller_lost",
            FaultKind::BadCommand => "bad_command",
            FaultKind::BadOutput => "bad_output",
            FaultKind::EmergencyStop => "emergency_stop",
            FaultKind::TooMuchTravel => "too_much_travel",
        }
    }
}

impl std::fmt::Display for FaultKind {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The numbers of the v1 wire, written out: a change here changes what recorded samples
    /// mean, so it must be a new version of the sample, not an edit.
    #[test]
    fn the_wire_numbers_are_those_of_v1() {
        let phases: Vec<u32> = Phase::ALL.iter().map(|p| p.wire()).collect();
        assert_eq!(phases, (0..8).collect::<Vec<_>>());
        assert_eq!((Phase::Done.wire(), Phase::Fault.wire()), (6, 7));
        let kinds: Vec<u32> = FaultKind::ALL.iter().map(|k| k.number()).collect();
        assert_eq!(kinds, (0..19).collect::<Vec<_>>());
        assert_eq!(FaultKind::wire(Some(FaultKind::FollowingError)), 11);
        assert_eq!(FaultKind::wire(None), 0);
        assert_eq!(FaultKind::from_wire(0), None);
        assert_eq!(FaultKind::from_wire(14), Some(FaultKind::HomingFailed));
        assert_eq!(FaultKind::from_wire(20), None);
        assert_eq!(Phase::from_wire(8), None);
        for p in Phase::ALL {
            assert_eq!(Phase::from_wire(p.wire()), Some(p));
        }
    }

    /// The words of messages and of `summary.json`: a name per phase and per kind, each its
    /// own, and a kind shows as its name.
    #[test]
    fn every_phase_and_kind_has_its_own_name() {
        let phases: std::collections::BTreeSet<&str> =
            Phase::ALL.iter().map(|p| p.name()).collect();
        assert_eq!(phases.len(), Phase::ALL.len(), "two phases share a name");
        assert_eq!((Phase::Idle.name(), Phase::Homing.name()), ("not started", "homing"));
        assert_eq!(FaultKind::LimitSwitch.to_string(), "limit_switch");
        for k in FaultKind::ALL {
            assert_eq!(k.to_string(), k.name());
        }
    }

    /// A code is a kind's one number both ways, every kind its own (telemetry's
    /// `fault` is the code + 1), and nothing past the last kind is one.
    #[test]
    fn codes_map_both_ways_one_per_kind() {
        for (i, &kind) in FaultKind::ALL.iter().enumerate() {
            assert_eq!(kind.number(), i as u32, "{kind}");
            assert_eq!(FaultKind::of_number(kind.number()), Some(kind));
        }
        assert_eq!(FaultKind::of_number(FaultKind::ALL.len() as u32), None);
        assert_eq!(FaultKind::of_number(u32::MAX), None);
        let names: std::collections::BTreeSet<&str> =
            FaultKind::ALL.iter().map(|k| k.name()).collect();
        assert_eq!(names.len(), FaultKind::ALL.len(), "two kinds share a name");
    }
}
