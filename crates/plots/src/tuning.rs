//! The convergence plot of `qmarc-starter tune`: each motor's objective per evaluation and
//! the best feasible value so far, against the evaluation number.

use crate::PlotError;
use crate::chart::{PanelSpec, figure, line_panel, per_motor};
use std::path::{Path, PathBuf};

/// The PNG [`convergence_plot`] writes.
pub const CONVERGENCE_PLOT_FILE: &str = "convergence.png";

/// Draws, into `dir`, per motor the best feasible objective so far against the evaluation
/// number (`best[m]`: (evaluation, value) pairs), and the objective relative to its value
/// before (1 = the gains before); `what` names the objective and its unit. Returns the path.
pub fn convergence_plot(
    dir: &Path,
    title: &str,
    what: &str,
    best: &[Vec<(f64, f64)>],
) -> Result<PathBuf, PlotError> {
    if best.iter().all(Vec::is_empty) {
        return Err(PlotError::Data("no evaluation to plot".into()));
    }
    let relative: Vec<Vec<(f64, f64)>> = best
        .iter()
        .map(|s| {
            let first = s.first().map_or(1.0, |p| p.1);
            s.iter().map(|&(k, v)| (k, if first > 0.0 { v / first } else { v })).collect()
        })
        .collect();
    let png = dir.join(CONVERGENCE_PLOT_FILE);
    figure(&png, 720, 2, title, |p| {
        line_panel(
            &p[0],
            &PanelSpec {
                min_span: (0.0, 0.0),
                integer_x: true,
                from_zero: false,
                title: format!("best feasible {what} so far"),
                x: "evaluation (moves of the path, per motor)",
                y: what.to_string(),
                traces: per_motor("motor", best),
            },
        )?;
        line_panel(
            &p[1],
            &PanelSpec {
                min_span: (0.0, 0.1),
                integer_x: true,
                from_zero: false,
                title: "relative to the first feasible gains (1 = before)".into(),
                x: "evaluation (moves of the path, per motor)",
                y: "best / first".into(),
                traces: per_motor("motor", &relative),
            },
        )
    })?;
    Ok(png)
}
