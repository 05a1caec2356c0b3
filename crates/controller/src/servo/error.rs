//! [`MoveError`]: why a move could not start — nothing was enabled — or its timer failed.

use crate::link::LinkError;
use crate::traj::TrajStartError;
use qmarc_proto::Status;
use qmarc_timer::TickerError;

/// The move could not start (nothing was enabled), or its timer failed.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MoveError {
    /// The hwserver did not answer during set-up.
    #[error("hwserver link failed before the move: {0}")]
    Link(#[from] LinkError),
    /// The hwserver reported a problem before any motor was enabled.
    #[error("the hwserver reports {0} before the move: refused to enable the motors")]
    Refused(Status),
    /// The emergency-stop chain is open: nothing may move until it is closed.
    #[error(
        "EMERGENCY STOP: the emergency-stop chain is open (pressed, or a broken wire): release \
         it or mend the chain, then move again; nothing was enabled"
    )]
    EmergencyStop,
    /// The trajectory cannot start from where the robot is.
    #[error(transparent)]
    Trajectory(#[from] TrajStartError),
    /// The timer could not be armed or waited on.
    #[error(transparent)]
    Timer(#[from] TickerError),
    /// The gathered data would not fit its memory budget.
    #[error(transparent)]
    Gather(#[from] crate::gather::GatherBudgetError),
    /// A motor's frame is not homed.
    #[error(
        "motor {motor} is not homed: run `qmarc-starter home` first, or give --unhomed (software \
         limits off)"
    )]
    NotHomed {
        /// 1-based motor.
        motor: usize,
    },
    /// The path leaves the software limits.
    #[error(
        "motor {motor}: the path reaches {value:.1} counts, outside its software limits \
         [{min}, {max}]: refused before the move"
    )]
    OutsideSoftLimits {
        /// 1-based motor.
        motor: usize,
        /// The extreme command, counts.
        value: f64,
        /// Lower limit.
        min: f64,
        /// Upper limit.
        max: f64,
    },
}
