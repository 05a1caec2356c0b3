//! What the console shows after a move: the summary, the series for the charts from
//! `gather.csv`, and the history of the session's moves.

use qmarc_report::Summary;
pub use qmarc_report::series::Series;
use std::path::Path;

/// Keeps at most about `n` points of `pts` (charts need no more than their width): of each
/// run of k points, the one furthest from the run's first — so a single late period or an
/// error peak stays visible.
pub fn thin(pts: &[(f64, f64)], n: usize) -> Vec<(f64, f64)> {
    let step = pts.len().div_ceil(n.max(1)).max(1);
    pts.chunks(step)
        .map(|c| {
            *c.iter()
                .max_by(|a, b| (a.1 - c[0].1).abs().total_cmp(&(b.1 - c[0].1).abs()))
                .unwrap_or(&c[0])
        })
        .collect()
}

/// The outcome of one move.
#[derive(Debug, Clone, PartialEq)]
pub struct MoveResult {
    /// `summary.json`.
    pub summary: Summary,
    /// The gathered data, if `gather.csv` could be read.
    pub series: Option<Series>,
    /// When `summary.json` was written.
    pub written: Option<std::time::SystemTime>,
    /// The move's PNG plots beside its data (the starter's `--plots`).
    pub plots: Vec<std::path::PathBuf>,
}

impl MoveResult {
    /// Reads `summary.json` and `gather.csv` from `out`.
    pub fn load(out: &Path) -> Result<MoveResult, String> {
        let summary = Summary::read(out)?;
        let series = Series::read(out, f64::from(summary.period_us) * 1e-6).ok();
        let written = std::fs::metadata(out.join("summary.json")).and_then(|m| m.modified()).ok();
        let plots = qmarc_report::output::PLOT_FILES
            .iter()
            .map(|f| out.join(f))
            .filter(|p| p.is_file())
            .collect();
        Ok(MoveResult { summary, series, written, plots })
    }

    /// The work of one servo cycle of this move, µs: two exchanges with the hwserver (the
    /// median read round trip, twice: the write is the same exchange) and the median
    /// trajectory + law time — what the machine needs per period when the loop wakes on time.
    /// (Not "tick → DAC written": that adds the wake-up delay, which on a busy machine without
    /// PREEMPT_RT says how loaded it was, not what it can do.) `None` without figures.
    pub fn cycle_work_us(&self) -> Option<f64> {
        let t = &self.summary.timing;
        Some(2.0 * t.read_us.p50 + t.compute_us.p50).filter(|&w| w > 0.0)
    }

    /// How long ago the results were written, for the title: `12 s ago`, `5 min ago`.
    pub fn age(&self, now: std::time::SystemTime) -> Option<String> {
        let s = now.duration_since(self.written?).ok()?.as_secs();
        Some(match s {
            0..120 => format!("{s} s ago"),
            120..7200 => format!("{} min ago", s / 60),
            7200..172_800 => format!("{} h ago", s / 3600),
            _ => format!("{} days ago", s / 86_400),
        })
    }

    /// The results of the move the starter with pid `starter` made: its `summary.json` in
    /// `out` — refused if another run wrote it (a move that ended before writing its own must
    /// not show the one before it as its result) — or, when the output folder could not take
    /// them, in the rescue folder the starter named.
    pub fn load_for(out: &Path, starter: u32) -> Result<MoveResult, String> {
        let rescue = qmarc_report::output::rescue_dir(starter);
        let mut why = format!("{}: no summary.json of this move", out.display());
        for dir in [out, rescue.as_path()] {
            match MoveResult::load(dir) {
                Ok(r) if r.summary.starter_pid == starter => return Ok(r),
                Ok(_) if dir == out => {
                    why = format!("{} is from an earlier move", dir.join("summary.json").display())
                }
                _ => {}
            }
        }
        Err(why)
    }
}

/// One line of the history: what a move's accumulated errors were with which gains.
#[derive(Debug, Clone, PartialEq)]
pub struct HistoryEntry {
    /// 1-based move number of the session.
    pub n: usize,
    /// `step`, `run (spline)`, `home`.
    pub what: String,
    /// The fault kind, if one ended it.
    pub fault: Option<qmarc_proto::state::FaultKind>,
    /// Σ|error| per motor, counts.
    pub accumulated: Vec<f64>,
    /// (Kp, Kd, Kvff) per motor when it ran.
    pub gains: Vec<(f64, f64, f64)>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn thinning_keeps_every_kth_point() {
        let pts: Vec<(f64, f64)> = (0..100).map(|i| (f64::from(i), 0.0)).collect();
        assert_eq!(thin(&pts, 10).len(), 10);
        assert_eq!(thin(&pts, 1000).len(), 100);
        let mut spiky: Vec<(f64, f64)> = (0..100).map(|i| (f64::from(i), 400.0)).collect();
        spiky[57].1 = 3_000.0;
        assert!(thin(&spiky, 10).iter().any(|p| p.1 == 3_000.0), "a spike survives");
    }
}
