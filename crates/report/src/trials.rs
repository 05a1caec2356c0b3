//! `trials.csv`: one row per trial of `qmarc-starter trials --n N` (thesis Fig. 5-17, 5-18),
//! each from that trial's `summary.json`.

use crate::Summary;
use std::io::{self, Write};

/// One trial's figures.
#[derive(Debug, Clone, PartialEq)]
pub struct TrialRow {
    /// 1-based trial number.
    pub trial: u32,
    /// Per arm: Σ|error|, rad — over the path's gathered rows when the summary has them (as
    /// the thesis summed its figures), else over every cycle of the move.
    pub abs_rad: Vec<f64>,
    /// Per arm: Σ error², rad², over the same rows.
    pub sq_rad: Vec<f64>,
    /// Servo periods more than 40 µs off.
    pub periods_off_40us: u64,
    /// Periods that expired without a cycle.
    pub missed_periods: u64,
    /// The fault that ended it (its kind), or empty.
    pub fault: String,
}

impl TrialRow {
    /// The row of trial `trial` from its summary, for `n_motors` arms: an arm the summary has
    /// no figures for (its controller died) gets NaN, written as an empty cell.
    pub fn of(trial: u32, s: &Summary, n_motors: usize) -> TrialRow {
        let motors = s.gathered.as_ref().map_or(&s.motors, |g| &g.motors);
        let per_arm = |f: fn(&crate::summary::MotorSummary) -> f64| -> Vec<f64> {
            (0..n_motors).map(|m| motors.get(m).map_or(f64::NAN, f)).collect()
        };
        TrialRow {
            trial,
            abs_rad: per_arm(|m| m.accumulated_abs_error_rad),
            sq_rad: per_arm(|m| m.sum_squares_error_rad2),
            periods_off_40us: s.timing.outside_40us,
            missed_periods: s.timing.missed_periods,
            fault: s.fault.as_ref().map(|f| f.kind.to_string()).unwrap_or_default(),
        }
    }
}

/// The header of `trials.csv` for `n_motors` arms.
pub fn header(n_motors: usize) -> String {
    let mut c = vec!["trial".to_string()];
    c.extend((1..=n_motors).map(|m| format!("abs_rad{m}")));
    c.extend((1..=n_motors).map(|m| format!("sq_rad{m}")));
    c.extend(["periods_off_40us", "missed_periods", "fault"].map(String::from));
    c.join(",")
}

/// Writes one row of `trials.csv` (the shortest text that reads back as the same figure;
/// an empty cell for a figure the trial does not have).
pub fn write_row(r: &TrialRow, w: &mut impl Write) -> io::Result<()> {
    write!(w, "{}", r.trial)?;
    for v in r.abs_rad.iter().chain(&r.sq_rad) {
        if v.is_finite() {
            write!(w, ",{v}")?;
        } else {
            write!(w, ",")?;
        }
    }
    writeln!(w, ",{},{},{}", r.periods_off_40us, r.missed_periods, r.fault)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_row_reads_as_its_header_says() {
        let r = TrialRow {
            trial: 7,
            abs_rad: vec![0.5, 0.25],
            sq_rad: vec![0.002, 0.001],
            periods_off_40us: 3,
            missed_periods: 1,
            fault: "following-error".into(),
        };
        let mut out = Vec::new();
        write_row(&r, &mut out).unwrap();
        assert_eq!(
            header(2),
            "trial,abs_rad1,abs_rad2,sq_rad1,sq_rad2,periods_off_40us,missed_periods,fault"
        );
        assert_eq!(String::from_utf8(out).unwrap(), "7,0.5,0.25,0.002,0.001,3,1,following-error\n");
    }

    /// A trial whose controller died has a summary without motors: its row keeps the header's
    /// width, the missing figures empty.
    #[test]
    fn a_trial_without_figures_keeps_the_columns() {
        let lost =
            Summary::controller_lost((qmarc_config::Mode::Step, false), 2, 400, 10, "x".into());
        let r = TrialRow::of(3, &lost, 2);
        let mut out = Vec::new();
        write_row(&r, &mut out).unwrap();
        let line = String::from_utf8(out).unwrap();
        assert_eq!(line.trim_end().split(',').count(), header(2).split(',').count(), "{line}");
        assert!(line.starts_with("3,,,,,"), "{line}");
    }
}
