//! What the console shows after a move: the summary, the series for the charts from
//! `gather.csv` and its last row (where the move left the motors and the gripper), what the
//! charts page shows ([`ChartsView`]), and the history of the session's moves.

use qmarc_report::Summary;
pub use qmarc_report::series::Series;
use std::io::{BufRead, Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

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
    /// The gathered data, or why `gather.csv` could not be read.
    pub series: Result<Series, String>,
    /// The last row of `gather.csv`: where the move left the motors and the gripper, or why
    /// it is not known.
    pub end: Result<EndRow, String>,
    /// When `summary.json` was written.
    pub written: Option<std::time::SystemTime>,
    /// The move's PNG plots beside its data (the starter's `--plots`).
    pub plots: Vec<PathBuf>,
    /// The folder the results were read from.
    pub dir: PathBuf,
}

impl MoveResult {
    /// Reads `summary.json` and `gather.csv` from `out`.
    pub fn load(out: &Path) -> Result<MoveResult, String> {
        let summary = Summary::read(out)?;
        let series = Series::read(out, f64::from(summary.period_us) * 1e-6);
        let end = EndRow::read(out);
        let written = std::fs::metadata(out.join("summary.json")).and_then(|m| m.modified()).ok();
        let plots = qmarc_report::output::PLOT_FILES
            .iter()
            .map(|f| out.join(f))
            .filter(|p| p.is_file())
            .collect();
        Ok(MoveResult { summary, series, end, written, plots, dir: out.to_path_buf() })
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

/// Why the output folder `out` shows no results, `load_error` being why
/// [`MoveResult::load`] failed there; `None` when the folder holds neither data nor a summary
/// (no move has written there yet).
pub fn why_none(out: &Path, load_error: &str) -> Option<String> {
    let gather = out.join("gather.csv");
    if gather.is_file() {
        Some(format!(
            "{} is there, but not a summary to read with it: {load_error}",
            gather.display()
        ))
    } else if out.join("summary.json").exists() {
        Some(load_error.to_string())
    } else {
        None
    }
}

/// The last row of a move's `gather.csv`: where the move left the motors and the gripper.
#[derive(Debug, Clone, PartialEq)]
pub struct EndRow {
    /// Its servo cycle.
    pub cycle: u64,
    /// Actual position per motor, counts (empty when `act` was not gathered).
    pub act: Vec<f64>,
    /// The gripper as the `grip` column writes it (0 open, 1 closing, 2 closed, 3 opening,
    /// −1 none wired); `None` when it was not gathered.
    pub grip: Option<i8>,
}

/// Bytes read from the end of `gather.csv` to find its last row: far more than a row.
const TAIL_BYTES: u64 = 64 * 1024;

impl EndRow {
    /// The last row of `dir/gather.csv` (its header and its end are read, not the whole
    /// file); the error names the file.
    pub fn read(dir: &Path) -> Result<EndRow, String> {
        let path = dir.join("gather.csv");
        let named = |e: String| format!("{}: {e}", path.display());
        let mut file = std::fs::File::open(&path).map_err(|e| named(e.to_string()))?;
        let mut header = String::new();
        std::io::BufReader::new(&mut file)
            .take(TAIL_BYTES)
            .read_line(&mut header)
            .map_err(|e| named(e.to_string()))?;
        let len = file.metadata().map_err(|e| named(e.to_string()))?.len();
        file.seek(SeekFrom::Start(len.saturating_sub(TAIL_BYTES)))
            .map_err(|e| named(e.to_string()))?;
        let mut tail = Vec::new();
        file.read_to_end(&mut tail).map_err(|e| named(e.to_string()))?;
        let tail = String::from_utf8_lossy(&tail);
        let last = tail.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or_default();
        EndRow::parse(header.trim_end(), last).map_err(named)
    }

    /// The row `last` under the header `header` (`gather.csv`'s columns).
    pub fn parse(header: &str, last: &str) -> Result<EndRow, String> {
        let names: Vec<&str> = header.split(',').collect();
        let values: Vec<&str> = last.split(',').collect();
        if last.is_empty() || last == header {
            return Err("no gathered row".into());
        }
        if values.len() != names.len() {
            return Err(format!(
                "its last row has {} fields, the header {}",
                values.len(),
                names.len()
            ));
        }
        let value = |name: &str| -> Result<Option<f64>, String> {
            match names.iter().position(|n| *n == name) {
                None => Ok(None),
                Some(i) => values[i]
                    .trim()
                    .parse::<f64>()
                    .map(Some)
                    .map_err(|e| format!("its last row's {name}: {e}")),
            }
        };
        let cycle = value("cycle")?.ok_or("no cycle column")?;
        let mut act = Vec::new();
        for m in 1..=qmarc_proto::MAX_MOTORS {
            match value(&format!("act{m}"))? {
                Some(v) => act.push(v),
                None => break,
            }
        }
        let grip = value("grip")?.map(|g| g as i8);
        Ok(EndRow { cycle: cycle as u64, act, grip })
    }
}

/// What the charts page (F7) shows.
#[derive(Debug)]
pub enum ChartsView<'a> {
    /// A running move's live telemetry.
    Live(&'a crate::live::Live),
    /// The gathered data of a move that ended.
    Gathered {
        /// Its results.
        result: &'a MoveResult,
        /// Its series.
        series: &'a Series,
        /// Whose they are when not the last move's: an earlier move's, the last having left
        /// none of its own.
        note: Option<String>,
    },
    /// Nothing to chart: why, in words.
    Nothing(String),
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

    /// Issue 42: the last gathered row is read from the end of the file (the motors' actual
    /// positions and the gripper), and a file without rows says so.
    #[test]
    fn the_last_row_says_where_the_move_left_the_motors() {
        let header = "cycle,time_s,cmd1,act1,dac1,cmd2,act2,dac2,grip";
        let row = EndRow::parse(header, "7,0.0028,10,9.5,3,20,19,-4,2").unwrap();
        assert_eq!(row, EndRow { cycle: 7, act: vec![9.5, 19.0], grip: Some(2) });
        let row = EndRow::parse("cycle,dac1", "3,12").unwrap();
        assert_eq!((row.act.len(), row.grip), (0, None), "neither act nor grip gathered");
        assert_eq!(EndRow::parse(header, header), Err("no gathered row".into()));
        let dir = std::env::temp_dir().join(format!("qmarc-endrow-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut csv = String::from("cycle,act1,grip\n");
        for c in 0..20_000 {
            csv.push_str(&format!("{c},{},0\n", c * 2));
        }
        std::fs::write(dir.join("gather.csv"), csv).unwrap();
        let read = EndRow::read(&dir);
        std::fs::write(dir.join("gather.csv"), "cycle,act1\n").unwrap();
        let empty = EndRow::read(&dir);
        let _ = std::fs::remove_dir_all(&dir);
        assert_eq!(read, Ok(EndRow { cycle: 19_999, act: vec![39_998.0], grip: Some(0) }));
        assert!(empty.unwrap_err().ends_with("gather.csv: no gathered row"));
    }

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
