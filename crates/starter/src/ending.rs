//! How a move ended, from what its processes left: [`conclude`] finds (or writes) its
//! summary — with the rows a dead controller left in its gather page — and [`exit_code`] is
//! docs/usage.md's "Exit codes" table, a pure function of what ended.

use crate::Exit;
use crate::lost::{controller_lost_message, lost, stopped_by, stopped_responding};
use crate::say;
use crate::supervise::{Supervised, Unresponsive};
use qmarc_config::RunSpec;
use qmarc_foxglove::recording::Recording;
use qmarc_proto::exit;
use qmarc_proto::progress::Snapshot;
use qmarc_proto::state::{FaultKind, Phase};
use qmarc_report::Summary;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

/// The summary of the move and the folder it is in: the one this run's controller wrote
/// (amended when a child stopped responding: the controller could not know why the run
/// ended), or, for a controller that died after its move began, one the starter writes with
/// what it knows.
pub fn conclude(spec: &RunSpec, e: &Ended) -> Option<(Summary, PathBuf)> {
    let out_dir = spec.settings.gather.out_dir.as_path();
    let unresponsive = e.unresponsive();
    if let Some((mut s, dir)) = read_own_summary(out_dir) {
        if let Some((name, u)) = unresponsive {
            stopped_responding(&mut s, name, u);
            if let Err(err) = qmarc_report::output::amend_summary(&dir, &s) {
                say!("qmarc-starter: {err}");
            }
        }
        return Some((s, dir));
    }
    // A controller that died — killed, or failed once its move had begun (a panic, data it
    // could not write anywhere) — wrote nothing: say what is known, and what the hwserver
    // did. One that refused before anything moved has said why.
    if let Some(exit) = e.controller().filter(|x| lost(*x, e.began(), stopped_by(e.stop))) {
        let settings = &spec.settings;
        let mut s = Summary::controller_lost(
            (spec.mode, spec.deterministic),
            settings.n_motors,
            settings.period_us,
            e.reached.map_or(0, |r| r.cycle),
            controller_lost_message(exit, e.hwserver(), settings, e.reached),
        );
        // The settings' scale, which the rows it left are in.
        s.counts_per_rad = settings.counts_per_rad();
        if let Some((name, u)) = unresponsive {
            stopped_responding(&mut s, name, u);
        }
        let written = match e.salvaged.as_ref().filter(|g| !g.rows().is_empty()) {
            // Its rows up to its last cycle, from the gather page it left: marked cut short.
            Some(g) => {
                let last = g.rows().last().map_or(0, |r| r.cycle);
                s.gather_every = g.every();
                s.gathered_rows = g.rows().len() as u64;
                let overwritten = match g.dropped() {
                    0 => String::new(),
                    k => format!(" ({k} rows before them not kept: the ring's, or never fitted)"),
                };
                s.warnings.push(qmarc_report::summary::Warning::new(
                    qmarc_report::summary::WarningKind::CutShort,
                    format!(
                        "cut short: the controller died; gather.csv and gather.m hold the {} \
                         rows it had gathered, to cycle {last}, from its gather page{overwritten}",
                        g.rows().len()
                    ),
                ));
                let frozen = s.clone();
                let recording = Recording {
                    settings,
                    gather: g,
                    summary: &frozen,
                    started_wall_ns: started_wall_ns(e.reached.map(|r| r.t0_ns), g),
                    path_from: 0,
                    settle_from: None,
                    parts: &[],
                };
                recording.write_results(out_dir, &mut s, std::process::id(), &[])
            }
            None => qmarc_report::output::write_summary_set(out_dir, &s).map(|_| ()),
        };
        if let Err(err) = written {
            say!("qmarc-starter: {err}");
        }
        return Some((s, out_dir.to_path_buf()));
    }
    if e.controller().is_some_and(Exit::success) {
        // It ended well and said it wrote its results: they are there, but cannot be read.
        let why = Summary::read(out_dir).err().unwrap_or_else(|| "not this run's".into());
        say!("qmarc-starter: the controller ended well, but its summary cannot be read: {why}");
    }
    None
}

/// Tick 0 of a dead controller's loop on the system clock: from its progress page's `t0_ns`
/// (`CLOCK_MONOTONIC`) where that is a past time of this clock, else as if its last gathered
/// row were now.
fn started_wall_ns(t0_ns: Option<u64>, g: &qmarc_controller::gather::Gather) -> u64 {
    let wall = qmarc_timer::clock::realtime_now_ns();
    let now = qmarc_timer::clock::monotonic_now_ns();
    let since = match t0_ns.filter(|&t| t > 0 && t <= now) {
        Some(t0) => now - t0,
        None => g.rows().last().map_or(0, |r| (r.time_s * 1e9) as u64),
    };
    wall.saturating_sub(since)
}

/// The summary this run's controller wrote and its folder: `summary.json` in `out_dir` if
/// this starter's (an older run's is not this run's result), else the one in the rescue
/// folder.
pub fn read_own_summary(out_dir: &Path) -> Option<(Summary, PathBuf)> {
    let me = std::process::id();
    let rescue = qmarc_report::output::rescue_dir(me);
    [out_dir.to_path_buf(), rescue]
        .into_iter()
        .filter_map(|d| Summary::read(&d).ok().map(|s| (s, d)))
        .find(|(s, _)| s.starter_pid == me)
}

/// How the two children ended.
pub struct Ended {
    /// How each child ended (hwserver first; the controller's missing if it could not start).
    pub children: Vec<Supervised>,
    /// What the progress page said last.
    pub reached: Option<Snapshot>,
    /// The user's stop flag (Ctrl-C, SIGTERM, the terminal gone).
    pub stop: &'static AtomicBool,
    /// The rows a controller that did not end well left in its gather page, oldest first.
    pub salvaged: Option<qmarc_controller::gather::Gather>,
}

impl Ended {
    /// How the controller ended (None: it did not start, or did not end).
    pub fn controller(&self) -> Option<Exit> {
        self.children.iter().find(|s| s.name == "qmarc-controller").and_then(|s| s.exit)
    }

    /// How the hwserver ended.
    pub fn hwserver(&self) -> Option<Exit> {
        self.children.first().and_then(|s| s.exit)
    }

    /// Both children started and exited 0.
    pub fn all_clean(&self) -> bool {
        self.children.len() == 2
            && self.children.iter().all(|s| s.exit.is_some_and(|e| e.success()))
    }

    /// The child that stopped responding, if one did.
    pub fn unresponsive(&self) -> Option<(&'static str, Unresponsive)> {
        self.children.iter().find_map(|s| s.unresponsive.map(|u| (s.name, u)))
    }

    /// Whether the user stopped the run.
    pub fn stopped(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// Whether the move had begun (it got past preparing) when the run ended.
    pub fn began(&self) -> bool {
        self.reached
            .and_then(|r| Phase::from_wire(r.phase))
            .is_some_and(|p| !matches!(p, Phase::Idle | Phase::Preparing))
    }
}

/// What the exit code of a move is decided from.
#[derive(Debug, Clone, Copy)]
pub struct Ending<'a> {
    /// The move's summary, if there is one.
    pub summary: Option<&'a Summary>,
    /// How the controller ended.
    pub controller: Option<Exit>,
    /// Both children started and exited 0.
    pub all_clean: bool,
    /// A child stopped responding and the run was ended for it.
    pub unresponsive: bool,
    /// The user stopped the run.
    pub stopped: bool,
}

/// The exit code of a move: docs/usage.md's "Exit codes" table ([`qmarc_proto::exit`]).
pub fn exit_code(e: &Ending<'_>) -> u8 {
    let code_is = |c: u8| matches!(e.controller, Some(Exit::Code(x)) if x == i32::from(c));
    let fault_is = |s: &Summary, k| s.fault.as_ref().is_some_and(|f| f.kind == k);
    match e.summary {
        // The check ran, and found a motor to mend.
        Some(s) if s.check.as_ref().is_some_and(|c| c.iter().any(|m| !m.ok)) => exit::FAULT,
        // A process stopped responding: the run was ended for it.
        _ if e.unresponsive => exit::FAULT,
        // The move ran, but its results are not where they were asked for.
        Some(s) if s.ok && code_is(exit::RESCUED) => exit::RESCUED,
        Some(s) if s.ok && e.all_clean => exit::OK,
        Some(s) if fault_is(s, FaultKind::Aborted) => exit::INTERRUPTED,
        // The move ran, but its controller failed after it (its data could not be written).
        Some(s) if code_is(exit::INTERNAL) && fault_is(s, FaultKind::ControllerLost) => {
            exit::INTERNAL
        }
        Some(s) if s.fault.is_some() => exit::FAULT,
        // Done without a fault, but not ok (figures that are not numbers).
        Some(s) if !s.ok => exit::FAULT,
        None if code_is(exit::REFUSED) => exit::REFUSED,
        None if code_is(exit::INTERRUPTED) => exit::INTERRUPTED,
        _ if e.stopped => exit::INTERRUPTED,
        _ => exit::INTERNAL,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qmarc_config::Mode;

    fn summary(ok: bool, fault: Option<FaultKind>) -> Summary {
        let mut s = Summary::controller_lost((Mode::Step, true), 3, 400, 10, String::new());
        s.ok = ok;
        s.fault = fault.map(|kind| qmarc_report::summary::FaultReport {
            kind,
            motor: None,
            cycle: 10,
            message: String::new(),
            hw_time_ns: None,
        });
        s
    }

    fn ending(summary: Option<&Summary>, controller: Option<Exit>) -> Ending<'_> {
        let all_clean = controller.is_some_and(Exit::success);
        Ending { summary, controller, all_clean, unresponsive: false, stopped: false }
    }

    /// docs/usage.md's "Exit codes", row by row, from what a move ended with.
    #[test]
    fn the_exit_codes_are_the_readme_table() {
        let ok = summary(true, None);
        let code = |c: u8| Some(Exit::Code(i32::from(c)));
        assert_eq!(exit_code(&ending(Some(&ok), code(exit::OK))), exit::OK);
        // A clean summary with a child that did not end cleanly is not ok.
        let unclean = Ending { all_clean: false, ..ending(Some(&ok), code(exit::OK)) };
        assert_eq!(exit_code(&unclean), exit::INTERNAL);
        let fault = summary(false, Some(FaultKind::FollowingError));
        assert_eq!(exit_code(&ending(Some(&fault), code(exit::FAULT))), exit::FAULT);
        let not_numbers = summary(false, None);
        assert_eq!(exit_code(&ending(Some(&not_numbers), code(exit::OK))), exit::FAULT);
        let stuck = Ending { unresponsive: true, ..ending(Some(&ok), code(exit::OK)) };
        assert_eq!(exit_code(&stuck), exit::FAULT, "a child stopped responding");
        assert_eq!(exit_code(&ending(None, code(exit::REFUSED))), exit::REFUSED);
        assert_eq!(exit_code(&ending(Some(&ok), code(exit::RESCUED))), exit::RESCUED);
        let aborted = summary(false, Some(FaultKind::Aborted));
        assert_eq!(exit_code(&ending(Some(&aborted), code(exit::INTERRUPTED))), exit::INTERRUPTED);
        assert_eq!(exit_code(&ending(None, code(exit::INTERRUPTED))), exit::INTERRUPTED);
        let stopped = Ending { stopped: true, ..ending(None, Some(Exit::Signal(2))) };
        assert_eq!(exit_code(&stopped), exit::INTERRUPTED, "stopped before it began");
        let lost = summary(false, Some(FaultKind::ControllerLost));
        assert_eq!(exit_code(&ending(Some(&lost), Some(Exit::Signal(9)))), exit::FAULT);
        assert_eq!(exit_code(&ending(Some(&lost), code(exit::INTERNAL))), exit::INTERNAL);
        assert_eq!(exit_code(&ending(None, Some(Exit::Signal(9)))), exit::INTERNAL);
        assert_eq!(exit_code(&ending(None, None)), exit::INTERNAL, "no controller started");
    }

    /// A failed check is a fault, even when the move itself ran to its end.
    #[test]
    fn a_check_that_finds_a_motor_to_mend_is_a_fault() {
        let mut s = summary(true, None);
        let motor = |ok| qmarc_report::check::MotorCheck {
            motor: 1,
            volts: 1.0,
            seconds: 0.1,
            moved_counts: 0.0,
            counts_per_volt_second: 0.0,
            expected_counts_per_volt_second: 1.0,
            other_motor: 0,
            other_moved_counts: 0.0,
            ok,
            advice: String::new(),
        };
        s.check = Some(vec![motor(true)]);
        assert_eq!(exit_code(&ending(Some(&s), Some(Exit::Code(0)))), exit::OK);
        s.check = Some(vec![motor(true), motor(false)]);
        assert_eq!(exit_code(&ending(Some(&s), Some(Exit::Code(0)))), exit::FAULT);
    }
}
