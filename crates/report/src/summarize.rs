//! [`summarize`]: the summary of a finished move, from the loop's figures and the settings —
//! with the warnings a user must read (a path that ends moving, rescaled gains, a motor that
//! did not follow its command).

use crate::summary::{
    ApproachSummary, FaultReport, MotorSummary, SettleSummary, Summary, TimingSummary, Warning,
    WarningKind,
};
use qmarc_config::{Mode, Settings};
use qmarc_controller::record::MoveRecord;
use qmarc_plugins::check::MotorCheckReport;
use qmarc_timer::rt::RtStatus;

/// A path whose last command moves slower than this (counts/s) ends at rest.
pub const END_AT_REST_COUNTS_PER_S: f64 = 1.0;

/// The summary of a finished move.
pub fn summarize(
    settings: &Settings,
    record: &MoveRecord,
    rt: &RtStatus,
    mode: Mode,
    deterministic: bool,
) -> Summary {
    let cpr = settings.counts_per_rad();
    let n = settings.n_motors;
    let real_time = rt.warnings.iter().map(|w| Warning::new(WarningKind::RealTime, w.as_str()));
    let mut warnings: Vec<Warning> = real_time.collect();
    warnings.extend(move_warnings(settings, record));
    let motors = followed(record, n, cpr, &mut warnings);
    // The rows of the path (the settle's come after it).
    let path_rows = || record.gather.rows().iter().filter(|r| record.is_path_sample(r.cycle));
    let gathered = (!record.gather.rows().is_empty())
        .then(|| crate::effector::gathered(path_rows(), n, cpr, settings.gather.every));
    let effector = settings
        .robot()
        .filter(|_| gathered.as_ref().is_some_and(|g| g.rows > 0))
        .map(|robot| crate::effector::effector(&robot, path_rows()));
    let (settle, approach) = stretches(settings, record);
    let mut summary = Summary {
        mode,
        trajectory: record.generator.to_string(),
        ok: record.fault.is_none(),
        degraded: rt.degraded(),
        deterministic,
        fault: record.fault.map(|f| {
            let mut r = FaultReport::from(&f);
            if let Some(why) = &record.failure {
                r.message = format!("{why}; {}", r.message);
            }
            r
        }),
        n_motors: n,
        cycles: record.cycles,
        planned_samples: record.planned_samples,
        period_us: settings.period_us,
        gather_every: settings.gather.every,
        gathered_rows: record.gather.rows().len() as u64,
        counts_per_rad: cpr,
        motors,
        gathered,
        effector,
        gains_period_us: settings.gains_period_us,
        gains: (0..n).map(|m| settings.effective_gains(m).into()).collect(),
        settle,
        approach,
        timing: TimingSummary::new(
            &record.timing,
            &settings.timer.method.to_string(),
            &rt.policy(),
        ),
        warnings,
        starter_pid: nix::unistd::getppid().as_raw() as u32,
        files: Vec::new(),
        homing: None,
        check: findings::<Vec<MotorCheckReport>>(record, "check")
            .map(|r| r.iter().map(|m| crate::check::MotorCheck::of(settings, m)).collect()),
        conveyor: None,
        cell: None,
    };
    summary.judge_figures();
    summary
}

/// The generator's findings for the report's `section`, as `T` (none: the generator found
/// nothing for it, or what it found is not a `T`).
pub fn findings<T: serde::de::DeserializeOwned>(record: &MoveRecord, section: &str) -> Option<T> {
    let f = record.findings.as_ref().filter(|f| f.section == section)?;
    serde_json::from_value(f.value.clone()).ok()
}

/// What the settings and the path call for a warning about: gathered rows not kept, a path
/// that ends moving, gains rescaled to the period.
fn move_warnings(settings: &Settings, record: &MoveRecord) -> Vec<Warning> {
    let n = settings.n_motors;
    let mut warnings = Vec::new();
    if record.gather.dropped() > 0 {
        warnings.push(Warning::new(
            WarningKind::GatherDropped,
            format!(
                "{} rows of the stream were not kept: the gather buffer holds gather.stream_max_s \
             = {} s of a stream (raise it, or gather less often with gather.every)",
                record.gather.dropped(),
                settings.gather.stream_max_s
            ),
        ));
    }
    if let Some(v) = record.end_velocity
        && let Some(m) = (0..n).find(|&m| v[m].abs() > END_AT_REST_COUNTS_PER_S)
    {
        warnings.push(Warning::new(
            WarningKind::EndsMoving,
            format!(
                "the path ends moving (motor {} at {:.1} counts/s): its last command was held for \
             trajectory.settle_s = {} s so that the motors stop under control; end the path at \
             rest (a last knot repeated, or a PVT velocity of 0) to avoid the jolt",
                m + 1,
                v[m],
                settings.trajectory.settle_s
            ),
        ));
    }
    if settings.gains_rescaled() {
        warnings.push(Warning::new(
            WarningKind::GainsRescaled,
            format!(
                "the gains were tuned at general.gains_period_us = {} µs and run at {} µs: Kd and \
             Kvff × {r}, Kaff × {r2}, Ki ÷ {r} (the effective gains are in summary.json)",
                settings.gains_period_us,
                settings.period_us,
                r = f64::from(settings.gains_period_us) / f64::from(settings.period_us),
                r2 = (f64::from(settings.gains_period_us) / f64::from(settings.period_us)).powi(2),
            ),
        ));
    }
    warnings
}

/// The settle after the path and the approach before it, if the move had them.
fn stretches(
    settings: &Settings,
    record: &MoveRecord,
) -> (Option<SettleSummary>, Option<ApproachSummary>) {
    let n = settings.n_motors;
    let settle = record.settle.as_ref().map(|st| SettleSummary {
        cycles: st.cycles,
        seconds: (st.cycles * u64::from(settings.period_us)) as f64 / 1e6,
        final_error_counts: record.last_error[..n].to_vec(),
        max_abs_error_counts: st.errors.axes[..n]
            .iter()
            .map(|e| e.max.abs().max(e.min.abs()))
            .collect(),
    });
    let approach = record.approach.as_ref().map(|a| ApproachSummary {
        samples: a.samples,
        cycles: a.cycles,
        seconds: (a.samples * u64::from(settings.period_us)) as f64 / 1e6,
        from_counts: record.gather.rows().first().map_or_else(Vec::new, |r| r.cmd[..n].to_vec()),
        max_abs_error_counts: a.errors.axes[..n]
            .iter()
            .map(|e| e.max.abs().max(e.min.abs()))
            .collect(),
    });
    (settle, approach)
}

/// Each motor's error figures, judged on whether it followed its command (a motor that did
/// not gets a warning).
fn followed(
    record: &MoveRecord,
    n: usize,
    cpr: f64,
    warnings: &mut Vec<Warning>,
) -> Vec<MotorSummary> {
    // The error at the end: of the settle, or of the path when there was none.
    let final_error = record.last_error;
    let mut motors: Vec<MotorSummary> =
        record.errors.axes[..n].iter().map(|e| MotorSummary::new(e, cpr)).collect();
    let mut travel = record.errors.travel;
    if let Some(settled) = &record.settle {
        for (t, s) in travel.iter_mut().zip(&settled.errors.travel) {
            t.add(s.act.0, s.act.0);
            t.add(s.act.1, s.act.1);
        }
    }
    // Judged on a move that ran its course. One a fault cut short (a stop a few cycles into a
    // step) may have given the motors no time to follow: only the motor its fault names (a
    // following error, a switch) is judged, and its fault says what happened.
    let judged = |m: usize| record.fault.is_none_or(|f| f.motor == Some(m));
    for (m, summary) in motors.iter_mut().enumerate() {
        if judged(m) && travel[m].not_followed(final_error[m]) {
            summary.followed = false;
            let (commanded, moved) = travel[m].lengths();
            warnings.push(Warning::new(WarningKind::NotFollowed, format!(
                "motor {} did not follow its command: it moved {moved:.0} of the {commanded:.0} \
                 counts commanded and ended {:.0} counts from its last command (a seized joint, \
                 an amplifier that is off or not wired, a gain of the wrong sign?)",
                m + 1,
                final_error[m]
            )));
        }
    }
    motors
}
