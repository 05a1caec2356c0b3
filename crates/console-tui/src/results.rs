//! What the console shows after a move: the summary, the series for the charts from
//! `gather.csv`, and the history of the session's moves.

use qmarc_report::Summary;
use std::path::Path;

/// The series of one move, per motor, from `gather.csv`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series {
    /// Time of each gathered row, s (from `time_s`, or cycle × period without it).
    pub t: Vec<f64>,
    /// Command per motor, counts (empty if not gathered).
    pub cmd: Vec<Vec<f64>>,
    /// Actual position per motor, counts (empty if not gathered).
    pub act: Vec<Vec<f64>>,
    /// Interval between consecutive gathered rows divided by the rows' cycle distance, µs:
    /// the servo period as it was (only with `time_s`).
    pub period_us: Vec<(f64, f64)>,
}

impl Series {
    /// Parses `gather.csv` text; `period_s` turns cycles into time when `time_s` is missing.
    pub fn parse(csv: &str, period_s: f64) -> Result<Series, String> {
        let mut lines = csv.lines();
        let header: Vec<&str> = lines.next().ok_or("gather.csv is empty")?.split(',').collect();
        let col = |name: &str| header.iter().position(|h| *h == name);
        let has =
            |m: usize| ["cmd", "act", "dac"].iter().any(|n| col(&format!("{n}{m}")).is_some());
        let n_motors = (1..=qmarc_proto::MAX_MOTORS).take_while(|&m| has(m)).count();
        let mut rows: Vec<Vec<f64>> = Vec::new();
        for (i, l) in lines.enumerate() {
            let r: Vec<f64> = l
                .split(',')
                .map(str::parse::<f64>)
                .collect::<Result<_, _>>()
                .map_err(|e| format!("gather.csv line {}: {e}", i + 2))?;
            if r.len() != header.len() {
                return Err(format!(
                    "gather.csv line {}: {} fields, the header has {}",
                    i + 2,
                    r.len(),
                    header.len()
                ));
            }
            rows.push(r);
        }
        let cycle = col("cycle").ok_or("gather.csv has no cycle column")?;
        let time = col("time_s");
        let t: Vec<f64> = rows.iter().map(|r| time.map_or(r[cycle] * period_s, |c| r[c])).collect();
        let per_motor = |name: &str| -> Vec<Vec<f64>> {
            (1..=n_motors)
                .map_while(|m| col(&format!("{name}{m}")))
                .map(|c| rows.iter().map(|r| r[c]).collect())
                .collect()
        };
        let mut period_us = Vec::new();
        if time.is_some() {
            for w in rows.windows(2) {
                let cycles = w[1][cycle] - w[0][cycle];
                if cycles > 0.0 {
                    let (t0, t1) = (time.map_or(0.0, |c| w[0][c]), time.map_or(0.0, |c| w[1][c]));
                    period_us.push((t1, (t1 - t0) / cycles * 1e6));
                }
            }
        }
        Ok(Series { t, cmd: per_motor("cmd"), act: per_motor("act"), period_us })
    }

    /// Following error (command − actual) of motor `m` over time.
    pub fn error(&self, m: usize) -> Vec<(f64, f64)> {
        match (self.cmd.get(m), self.act.get(m)) {
            (Some(c), Some(a)) => {
                self.t.iter().zip(c.iter().zip(a)).map(|(&t, (c, a))| (t, c - a)).collect()
            }
            _ => Vec::new(),
        }
    }

    /// `values` against time.
    pub fn points(&self, values: Option<&Vec<f64>>) -> Vec<(f64, f64)> {
        values.map_or_else(Vec::new, |v| self.t.iter().copied().zip(v.iter().copied()).collect())
    }
}

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
}

impl MoveResult {
    /// Reads `summary.json` and `gather.csv` from `out`.
    pub fn load(out: &Path) -> Result<MoveResult, String> {
        let path = out.join("summary.json");
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        let summary: Summary =
            serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))?;
        let period_s = f64::from(summary.period_us) * 1e-6;
        let series = std::fs::read_to_string(out.join("gather.csv"))
            .ok()
            .and_then(|c| Series::parse(&c, period_s).ok());
        let written = std::fs::metadata(&path).and_then(|m| m.modified()).ok();
        Ok(MoveResult { summary, series, written })
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
    pub fault: Option<qmarc_controller::fault::FaultKind>,
    /// Σ|error| per motor, counts.
    pub accumulated: Vec<f64>,
    /// (Kp, Kd, Kvff) per motor when it ran.
    pub gains: Vec<(f64, f64, f64)>,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn series_come_from_the_gathered_columns() {
        let csv = "cycle,time_s,cmd1,act1,dac1,cmd2,act2,dac2\n0,0,0,0,0,0,0,0\n1,0.0004,1000,3,8191,-5,-1,-30\n3,0.0012,1000,40,100,-5,-4,-2\n";
        let s = Series::parse(csv, 0.0004).unwrap();
        assert_eq!(s.t, [0.0, 0.0004, 0.0012]);
        assert_eq!(s.cmd.len(), 2);
        assert_eq!(s.error(0), [(0.0, 0.0), (0.0004, 997.0), (0.0012, 960.0)]);
        assert_eq!(s.error(1)[2], (0.0012, -1.0));
        assert_eq!(s.period_us.len(), 2);
        assert!((s.period_us[0].1 - 400.0).abs() < 1e-9 && (s.period_us[1].1 - 400.0).abs() < 1e-9);
        // Without time_s: cycles × period; without cmd: no error series.
        let s = Series::parse("cycle,act1\n0,5\n2,7\n", 0.0004).unwrap();
        assert_eq!(s.t, [0.0, 0.0008]);
        assert!(s.error(0).is_empty() && s.period_us.is_empty());
        // A cut-off row, an empty file, a header alone: an error or empty series, no panic.
        let e = Series::parse("cycle,time_s,cmd1,act1\n0,0,0,0\n1,0.0004\n", 0.0004).unwrap_err();
        assert_eq!(e, "gather.csv line 3: 2 fields, the header has 4");
        assert!(Series::parse("", 0.0004).is_err());
        let s = Series::parse("cycle,time_s,cmd1,act1\n", 0.0004).unwrap();
        assert!(s.t.is_empty() && s.error(0).is_empty() && s.period_us.is_empty());
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
