//! The plots of repeated trials (`qmarc-starter trials`): thesis Fig. 5-17 and 5-18.

use crate::PlotError;
use crate::chart::{PanelSpec, Trace, figure, line_panel, motor_colour, per_motor};
use qmarc_report::trials::TrialRow;
use std::path::{Path, PathBuf};

/// The PNGs [`trial_plots`] writes.
pub const TRIAL_PLOT_FILES: [&str; 2] = ["trials-error.png", "trials-periods.png"];

/// Draws the accumulated absolute error per trial and arm, and the periods more than 40 µs
/// off (and missed) per trial, into `dir`; returns their paths. `what` names the move.
pub fn trial_plots(dir: &Path, what: &str, rows: &[TrialRow]) -> Result<Vec<PathBuf>, PlotError> {
    if rows.is_empty() {
        return Err(PlotError::Data("no trial to plot".into()));
    }
    let title = format!("QMARC {what}: {} trials", rows.len());
    let n = rows.iter().map(|r| r.abs_rad.len()).max().unwrap_or(0);
    // Each arm a little beside the trial's number (arms of the same error do not hide one
    // another), with a marker of its own.
    let dodge = |m: usize| (m as f64 - (n as f64 - 1.0) / 2.0) * 0.08;
    let per_arm: Vec<Vec<(f64, f64)>> = (0..n)
        .map(|m| {
            let at = |r: &TrialRow| r.abs_rad.get(m).map(|&v| (f64::from(r.trial) + dodge(m), v));
            rows.iter().filter_map(at).collect()
        })
        .collect();
    let off: Vec<(f64, f64)> =
        rows.iter().map(|r| (f64::from(r.trial), r.periods_off_40us as f64)).collect();
    let missed: Vec<(f64, f64)> =
        rows.iter().map(|r| (f64::from(r.trial), r.missed_periods as f64)).collect();
    let [error_png, periods_png] = TRIAL_PLOT_FILES.map(|f| dir.join(f));
    let error = figure(&error_png, 480, 1, &title, |p| {
        line_panel(
            &p[0],
            &PanelSpec {
                min_span: (0.0, 0.0),
                integer_x: true,
                // The spread of the trials as it is: from zero, not stretched over the axis.
                from_zero: true,
                title: "accumulated absolute following error per trial".into(),
                x: "trial",
                y: "Σ|error|, rad".into(),
                traces: per_motor("arm", &per_arm)
                    .into_iter()
                    .map(|t| Trace { points: true, ..t })
                    .collect(),
            },
        )
    })?;
    let periods = figure(&periods_png, 480, 1, &title, |p| {
        line_panel(
            &p[0],
            &PanelSpec {
                min_span: (0.0, 0.0),
                integer_x: true,
                from_zero: true,
                title: "servo periods more than 40 µs off, and missed, per trial".into(),
                x: "trial",
                y: "periods".into(),
                traces: vec![
                    Trace {
                        name: "off by > 40 µs".into(),
                        colour: motor_colour(0),
                        points: true,
                        pts: &off,
                    },
                    Trace {
                        name: "missed".into(),
                        colour: motor_colour(1),
                        points: true,
                        pts: &missed,
                    },
                ],
            },
        )
    })?;
    Ok(vec![error, periods])
}
