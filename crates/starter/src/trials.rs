//! `qmarc-starter trials --n N run|step|home …`: a move repeated N times, one process set per
//! trial (thesis 5.3, Fig. 5-17 and 5-18): each trial's data in `trial-NNN/`, one row per
//! trial in `trials.csv`, written as each trial ends (an interrupted series keeps its rows),
//! and a table of the spread at the end.

use crate::cli::{Command, StepArgs};
use clap::Args;
use qmarc_report::trials::{TrialRow, header, write_row};
use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

/// Options of `trials`.
#[derive(Debug, Clone, PartialEq, Args)]
pub struct TrialsArgs {
    /// How many trials.
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=10_000))]
    pub n: u32,
    /// The move each trial makes.
    #[command(subcommand)]
    pub command: Command,
}

/// The move of trial `k` (1-based): the same each time, except that a step alternates its
/// sign (`size` is the step the settings give), so the robot goes back and forth instead of
/// walking toward a limit (on hardware each trial starts where the last one ended).
pub fn command_of(command: &Command, k: u32, size: i64) -> Command {
    match command {
        Command::Step(a) => Command::Step(StepArgs {
            size: Some(if k % 2 == 1 { size } else { -size }),
            duration: a.duration,
        }),
        c => c.clone(),
    }
}

/// The folder of trial `k` in `base`.
pub fn trial_dir(base: &Path, k: u32) -> PathBuf {
    base.join(format!("trial-{k:03}"))
}

/// `trials.csv`, written a row at a time.
pub struct TrialsCsv {
    path: PathBuf,
    file: std::fs::File,
    rows: Vec<TrialRow>,
}

/// Where an earlier series in the same folder goes when a new one begins.
pub const PREVIOUS_SERIES: &str = "previous-trials";

/// Whether `name` is a file of a series: `trials.csv`, `trials.log`, its plots, `trial-NNN`.
fn of_a_series(name: &str) -> bool {
    matches!(name, "trials.csv" | "trials.log")
        || qmarc_plots::TRIAL_PLOT_FILES.contains(&name)
        || name
            .strip_prefix("trial-")
            .is_some_and(|n| n.len() >= 3 && n.bytes().all(|b| b.is_ascii_digit()))
}

/// Moves an earlier series in `base` — all of it — into `base/previous-trials/`, replacing
/// the one kept there: a folder never mixes two series, and the last one is not lost.
pub fn retire_series(base: &Path) -> std::io::Result<()> {
    let mut names: Vec<std::ffi::OsString> = std::fs::read_dir(base)?
        .filter_map(Result::ok)
        .map(|e| e.file_name())
        .filter(|n| n.to_str().is_some_and(of_a_series))
        .collect();
    if names.is_empty() {
        return Ok(());
    }
    names.sort();
    let previous = base.join(PREVIOUS_SERIES);
    match std::fs::remove_dir_all(&previous) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
        _ => {}
    }
    std::fs::create_dir(&previous)?;
    for n in names {
        std::fs::rename(base.join(&n), previous.join(&n))?;
    }
    Ok(())
}

impl TrialsCsv {
    /// Starts `base/trials.csv` for `n_motors` arms.
    pub fn create(base: &Path, n_motors: usize) -> std::io::Result<TrialsCsv> {
        let path = base.join("trials.csv");
        let mut file = std::fs::File::create(&path)?;
        writeln!(file, "{}", header(n_motors))?;
        Ok(TrialsCsv { path, file, rows: Vec::new() })
    }

    /// Appends `row` and writes it out at once.
    pub fn push(&mut self, row: TrialRow) -> std::io::Result<()> {
        write_row(&row, &mut self.file)?;
        self.file.flush()?;
        self.rows.push(row);
        Ok(())
    }

    /// The rows so far.
    pub fn rows(&self) -> &[TrialRow] {
        &self.rows
    }

    /// Where it is.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// Mean, smallest, largest and standard deviation (population) of `v`.
fn spread(v: &[f64]) -> (f64, f64, f64, f64) {
    let n = v.len().max(1) as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n;
    let (lo, hi) =
        v.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    (mean, lo, hi, var.sqrt())
}

/// The table printed after the trials of `what`, `planned` of them.
pub fn render(what: &str, planned: u32, rows: &[TrialRow]) -> String {
    let mut t = String::new();
    let faults: Vec<&TrialRow> = rows.iter().filter(|r| !r.fault.is_empty()).collect();
    let _ = writeln!(
        t,
        "QMARC trials of {what}: {} of {planned} ran, {} ok{}",
        rows.len(),
        rows.len() - faults.len(),
        if faults.is_empty() { String::new() } else { format!(", {} faulted", faults.len()) }
    );
    let n = rows.iter().map(|r| r.abs_rad.len()).max().unwrap_or(0);
    // The error figures of whole trials only: a faulted trial's are of part of the path.
    let whole: Vec<&TrialRow> = rows.iter().filter(|r| r.fault.is_empty()).collect();
    if n > 0 && !whole.is_empty() {
        let _ = writeln!(
            t,
            "\n  per trial, over the {} that ran to their end{:>5} {:>10} {:>10} {:>10}",
            whole.len(),
            "mean",
            "min",
            "max",
            "std"
        );
        for (what, pick) in [
            ("Σ|e| rad", (|r: &TrialRow, m: usize| r.abs_rad.get(m).copied()) as fn(_, _) -> _),
            ("Σe² rad²", |r: &TrialRow, m: usize| r.sq_rad.get(m).copied()),
        ] {
            for m in 0..n {
                let v: Vec<f64> =
                    whole.iter().filter_map(|r| pick(r, m)).filter(|v| v.is_finite()).collect();
                let (mean, lo, hi, sd) = spread(&v);
                let sd = if v.len() < 2 { "—".to_string() } else { format!("{sd:.2e}") };
                let _ = writeln!(
                    t,
                    "  arm {} {what:<14} {mean:>10.4e} {lo:>10.4e} {hi:>10.4e} {sd:>10}",
                    m + 1
                );
            }
        }
        let off: Vec<f64> = rows.iter().map(|r| r.periods_off_40us as f64).collect();
        let missed: u64 = rows.iter().map(|r| r.missed_periods).sum();
        let (mean, lo, hi, _) = spread(&off);
        let _ = writeln!(
            t,
            "\n  periods off by > 40 µs per trial: mean {mean:.1}, min {lo:.0}, max {hi:.0}; \
             missed periods in all: {missed}"
        );
    }
    for r in faults {
        let _ = writeln!(t, "  trial {}: fault {}", r.trial, r.fault);
    }
    t
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(k: u32, e: f64, fault: &str) -> TrialRow {
        TrialRow {
            trial: k,
            abs_rad: vec![e, 2.0 * e],
            sq_rad: vec![e * e, 0.0],
            periods_off_40us: u64::from(k),
            missed_periods: 1,
            fault: fault.into(),
        }
    }

    #[test]
    fn steps_alternate_paths_repeat() {
        let step = Command::Step(StepArgs { size: None, duration: Some(0.5) });
        let sizes: Vec<Option<i64>> = (1..=4)
            .map(|k| match command_of(&step, k, 1000) {
                Command::Step(a) => {
                    assert_eq!(a.duration, Some(0.5));
                    a.size
                }
                _ => unreachable!(),
            })
            .collect();
        assert_eq!(sizes, [Some(1000), Some(-1000), Some(1000), Some(-1000)]);
        assert_eq!(command_of(&Command::Home, 2, 1000), Command::Home);
    }

    #[test]
    fn the_table_gives_the_spread_and_the_faults() {
        let rows = [row(1, 0.5, ""), row(2, 0.7, "following-error"), row(3, 0.6, "")];
        let t = render("run (spline)", 5, &rows);
        assert!(
            t.starts_with("QMARC trials of run (spline): 3 of 5 ran, 2 ok, 1 faulted\n"),
            "{t}"
        );
        // The spread is over the two whole trials; the faulted one's figures are of part of it.
        assert!(t.contains("over the 2 that ran to their end"), "{t}");
        assert!(
            t.contains("  arm 1 Σ|e| rad        5.5000e-1  5.0000e-1  6.0000e-1    5.00e-2\n"),
            "{t}"
        );
        let one = render("step", 1, &rows[..1]);
        assert!(one.contains("5.0000e-1  5.0000e-1  5.0000e-1          —\n"), "std of one: {one}");
        assert!(t.contains("mean 2.0, min 1, max 3; missed periods in all: 3"), "{t}");
        assert!(t.ends_with("  trial 2: fault following-error\n"), "{t}");
    }

    #[test]
    fn rows_are_on_disk_as_they_come_and_an_old_series_is_kept_whole() {
        let dir = std::env::temp_dir().join(format!("qmarc-trials-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("trial-001")).unwrap();
        std::fs::create_dir_all(dir.join("trial-002")).unwrap();
        for f in ["trials.csv", "trials.log", "trials-error.png", "notes.txt"] {
            std::fs::write(dir.join(f), "old\n").unwrap();
        }
        retire_series(&dir).unwrap();
        let kept = dir.join(PREVIOUS_SERIES);
        for f in ["trials.csv", "trials.log", "trials-error.png", "trial-001", "trial-002"] {
            assert!(kept.join(f).exists() && !dir.join(f).exists(), "{f}");
        }
        assert!(dir.join("notes.txt").exists(), "not a series' file: left alone");
        let mut csv = TrialsCsv::create(&dir, 2).unwrap();
        csv.push(row(1, 0.5, "")).unwrap();
        let text = std::fs::read_to_string(csv.path()).unwrap();
        assert_eq!(
            text,
            "trial,abs_rad1,abs_rad2,sq_rad1,sq_rad2,periods_off_40us,missed_periods,fault\n\
             1,0.5,1,0.25,0,1,1,\n"
        );
        assert_eq!(csv.rows().len(), 1);
        // The next series replaces the kept one with this one.
        retire_series(&dir).unwrap();
        assert!(!kept.join("trial-001").exists() && kept.join("trials.csv").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }
}
