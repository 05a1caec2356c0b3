//! How a run that did not end well is told: a controller lost or not, a process that stopped
//! responding, what the starter knows when the controller died.

use crate::supervise;
use crate::{Exit, describe_exit};
use qmarc_config::Settings;
use qmarc_proto::state::FaultKind;
use qmarc_report::Summary;

/// Whether the controller, ended by `exit` without a summary, was lost: killed, or failed
/// once its move had `began` (a panic, data it could not write anywhere). One that refused
/// before anything moved has said why; one that ended well was not lost, whatever is missing;
/// one the user's stop (`stopped_by`, forwarded to it) ended before its move began, before it
/// could handle signals, was stopped, not lost.
pub(crate) fn lost(exit: Exit, began: bool, stopped_by: Option<i32>) -> bool {
    match exit {
        Exit::Signal(s) => began || stopped_by != Some(s),
        _ => began && !exit.success(),
    }
}

/// The signal the user stopped this run with (the one forwarded to the children), if they did.
pub(crate) fn stopped_by(stop: &std::sync::atomic::AtomicBool) -> Option<i32> {
    stop.load(std::sync::atomic::Ordering::Relaxed).then(|| supervise::forwarded_signal() as i32)
}

/// The fault of a run that `name` ended by stopping to respond: that, then what the controller
/// saw (its own fault, or how it died).
pub(crate) fn stopped_responding(s: &mut Summary, name: &str, u: supervise::Unresponsive) {
    let kind =
        if name == "qmarc-hwserver" { FaultKind::HwserverLost } else { FaultKind::ControllerLost };
    let then = s.fault.as_ref().map(|f| format!(" (then: {})", f.message)).unwrap_or_default();
    let message = format!("{}{then}", u.describe(name));
    let report = qmarc_report::summary::FaultReport {
        kind,
        motor: None,
        cycle: s.cycles,
        message: String::new(),
        hw_time_ns: None,
    };
    let f = s.fault.get_or_insert(report);
    (f.kind, f.message) = (kind, message);
    s.ok = false;
}

/// What the starter knows when the controller died: how, how far the move got, and how the
/// hwserver ended.
pub(crate) fn controller_lost_message(
    controller: Exit,
    hwserver: Option<Exit>,
    s: &Settings,
    reached: Option<qmarc_proto::progress::Snapshot>,
) -> String {
    let how = describe_exit("qmarc-controller", controller);
    let at = match reached {
        Some(r) if r.phase > 0 => format!(
            " at cycle {} while {}",
            r.cycle,
            qmarc_proto::state::Phase::from_wire(r.phase).map_or("?", |p| p.name())
        ),
        _ => " before the move began".to_string(),
    };
    let motors = match hwserver {
        Some(Exit::Code(2)) => format!(
            "the hwserver's watchdog disabled the motors after {} periods without a request",
            s.hwserver.watchdog_periods
        ),
        Some(Exit::Code(0)) => "the hwserver disabled the motors as it stopped".to_string(),
        Some(e) => format!("{}: the motors' state is unknown", describe_exit("qmarc-hwserver", e)),
        None => "the hwserver did not end".to_string(),
    };
    format!("{how}{at}; {motors}")
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 28, items 7 and 8: a controller that ended well is never reported lost, whatever
    /// is missing; one killed is, unless by the user's stop before its move began; one that
    /// failed is lost only once its move began.
    #[test]
    fn a_controller_that_ended_well_is_never_lost() {
        assert!(!lost(Exit::Code(0), true, None));
        assert!(!lost(Exit::Code(0), false, None));
        assert!(lost(Exit::Signal(9), false, None));
        assert!(lost(Exit::Code(1), true, None));
        assert!(!lost(Exit::Code(3), false, None), "refused before anything moved");
        // Ctrl-C forwarded before it could handle signals: stopped, not lost; after its move
        // began, or by another signal, lost.
        assert!(!lost(Exit::Signal(2), false, Some(2)));
        assert!(lost(Exit::Signal(2), true, Some(2)));
        assert!(lost(Exit::Signal(9), false, Some(2)));
    }
}
