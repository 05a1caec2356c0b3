//! `gather.csv` read back: the gathered series of one move, per motor, for the console's
//! charts and the PNG plots.

use std::path::Path;

/// The series of one move, per motor, from `gather.csv`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Series {
    /// Servo cycle of each gathered row.
    pub cycle: Vec<f64>,
    /// Time of each gathered row, s (from `time_s`, or cycle × period without it).
    pub t: Vec<f64>,
    /// Command per motor, counts (empty if not gathered).
    pub cmd: Vec<Vec<f64>>,
    /// Actual position per motor, counts (empty if not gathered).
    pub act: Vec<Vec<f64>>,
    /// DAC code per motor (±8191 = ±10 V; empty if not gathered).
    pub dac: Vec<Vec<f64>>,
    /// Interval between consecutive gathered rows divided by the gathering's spacing (the
    /// smallest cycle distance between rows), µs: the servo period as it was, a mean over the
    /// spacing, and a stall that skipped periods shows whole (only with `time_s`).
    pub period_us: Vec<(f64, f64)>,
}

impl Series {
    /// Reads `gather.csv` in `dir`; `period_s` turns cycles into time when `time_s` is
    /// missing. The error names the file.
    pub fn read(dir: &Path, period_s: f64) -> Result<Series, String> {
        let path = dir.join("gather.csv");
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        Series::parse(&text, period_s).map_err(|e| format!("{}: {e}", dir.display()))
    }

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
        let spacing = rows
            .windows(2)
            .map(|w| w[1][cycle] - w[0][cycle])
            .filter(|&c| c > 0.0)
            .fold(f64::INFINITY, f64::min);
        if let Some(tc) = time.filter(|_| spacing.is_finite()) {
            for w in rows.windows(2).filter(|w| w[1][cycle] > w[0][cycle]) {
                period_us.push((w[1][tc], (w[1][tc] - w[0][tc]) / spacing * 1e6));
            }
        }
        Ok(Series {
            cycle: rows.iter().map(|r| r[cycle]).collect(),
            t,
            cmd: per_motor("cmd"),
            act: per_motor("act"),
            dac: per_motor("dac"),
            period_us,
        })
    }

    /// Motors with both command and actual gathered.
    pub fn n_motors(&self) -> usize {
        self.cmd.len().min(self.act.len())
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
        // Cycle 2 was missed: the interval to cycle 3 is two periods, and shows so.
        assert!((s.period_us[0].1 - 400.0).abs() < 1e-9 && (s.period_us[1].1 - 800.0).abs() < 1e-9);
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
}
