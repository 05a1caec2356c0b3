//! What a tuning says and writes: the before/after table of the four thesis error figures per
//! motor, every candidate in `tune.csv`, the tuned gains as a TOML fragment, and a copy of
//! the settings file with them (never the file itself).

use crate::eval::{Figures, PathRun};
use crate::optimise::{Record, Tuned, Verdict};
use qmarc_config::{MotorGains, TUNE_PARAMS, TuneParam};
use std::fmt::Write as _;
use std::path::Path;
use toml_edit::{DocumentMut, Item, Value};

/// The before/after table: per motor Σ|e|, Σe², max and min error (rad, thesis Table 5-2),
/// before → after and after ÷ before, and the saturated share after.
pub fn table(before: &PathRun, after: &PathRun) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "  motor  Σ|e| rad (before → after, ratio)      Σe² rad²                     max e rad            min e rad             DAC saturated"
    );
    let cell = |b: f64, a: f64| format!("{b:.4} → {a:.4}");
    for (m, (b, a)) in before.motors.iter().zip(&after.motors).enumerate() {
        let ratio = |x: fn(&Figures) -> f64| {
            if x(b) != 0.0 { format!("×{:.2}", x(a) / x(b)) } else { "–".into() }
        };
        let _ = writeln!(
            t,
            "  {:<5}  {:<20} {:<10} {:<28} {:<20} {:<20}  {:.2} %",
            m + 1,
            cell(b.abs_rad, a.abs_rad),
            ratio(|f| f.abs_rad),
            format!("{:.3e} → {:.3e} {}", b.sse_rad2, a.sse_rad2, ratio(|f| f.sse_rad2)),
            format!("{:.5} → {:.5}", b.max_rad, a.max_rad),
            format!("{:.5} → {:.5}", b.min_rad, a.min_rad),
            a.saturated * 100.0,
        );
    }
    t
}

/// The gains of `gains` as `[[motor]]` tables (only the gains: paste them over the file's),
/// headed by `comment` lines.
pub fn fragment(gains: &[MotorGains], comment: &str) -> String {
    let mut t = String::new();
    for line in comment.lines() {
        let _ = writeln!(t, "# {line}");
    }
    for g in gains {
        let _ = writeln!(t, "\n[[motor]]");
        for (name, v) in written(g) {
            let _ = writeln!(t, "{name} = {}", gain_text(v));
        }
    }
    t
}

/// The gains a settings file gets, by name: Kjff only where it is not 0 (left out, it is 0:
/// eq. 3-1).
fn written(g: &MotorGains) -> impl Iterator<Item = (&'static str, f64)> {
    TuneParam::ALL
        .into_iter()
        .map(|p| (p.name(), p.get(g)))
        .filter(|&(name, v)| name != "kjff" || v != 0.0)
}

/// A gain as the settings file writes it: 4 significant digits after the point is plenty
/// (the objective does not see less), always with a decimal point (TOML float).
pub fn gain_text(v: f64) -> String {
    let r = (v * 1e3).round() / 1e3;
    if r.fract() == 0.0 { format!("{r:.1}") } else { format!("{r}") }
}

/// The gains rounded as [`fragment`] and [`write_copy`] write them: what a user's file gets.
pub fn rounded(g: &MotorGains) -> MotorGains {
    let r = |v: f64| gain_text(v).parse().unwrap_or(v);
    let mut out = *g;
    for p in TuneParam::ALL {
        p.set(&mut out, r(p.get(g)));
    }
    out
}

/// Every candidate as CSV: motor, evaluation, the six gains, objective, best so far,
/// verdict, moves so far.
pub fn csv(records: &[Record]) -> String {
    let mut t =
        format!("motor,evaluation,{},objective,best,verdict,moves\n", TUNE_PARAMS.join(","));
    for r in records {
        let g = &r.gains;
        let objective = r.objective.map_or(String::new(), |v| v.to_string());
        let best = if r.best.is_finite() { r.best.to_string() } else { String::new() };
        let _ = writeln!(
            t,
            "{},{},{},{},{},{},{},{},{},{},{},{}",
            r.motor + 1,
            r.evaluation,
            g.kp,
            g.ki,
            g.kd,
            g.kvff,
            g.kaff,
            g.kjff,
            objective,
            best,
            r.verdict.word(),
            r.moves
        );
    }
    t
}

/// Per motor, the best feasible objective after each evaluation (from the first feasible
/// one): the convergence plot's series.
pub fn convergence(records: &[Record], n_motors: usize) -> Vec<Vec<(f64, f64)>> {
    let mut series = vec![Vec::new(); n_motors];
    for r in records {
        let best = match (&r.verdict, r.objective) {
            (Verdict::Feasible { best: true }, Some(v)) => v,
            _ => r.best,
        };
        if best.is_finite()
            && let Some(s) = series.get_mut(r.motor)
        {
            s.push((f64::from(r.evaluation), best));
        }
    }
    series
}

/// The copy could not be written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum WriteCopyError {
    /// `--write` names the settings file itself, or a file that exists.
    #[error("{0}: {1}")]
    Refused(String, &'static str),
    /// The settings file could not be read or parsed, or the copy written.
    #[error("{0}")]
    Io(String),
}

/// Refuses `dest` when it is the settings file `source` or any file that exists: a copy
/// never replaces anything.
pub fn check_copy(source: &Path, dest: &Path) -> Result<(), WriteCopyError> {
    let name = || dest.display().to_string();
    let same = match (source.canonicalize(), dest.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    };
    if same {
        return Err(WriteCopyError::Refused(
            name(),
            "is the settings file itself: --write writes a copy (name a new file)",
        ));
    }
    if dest.symlink_metadata().is_ok() {
        return Err(WriteCopyError::Refused(
            name(),
            "exists: --write never replaces a file (remove it or name a new one)",
        ));
    }
    Ok(())
}

/// Writes to `dest` a copy of the settings file `source` with each `[[motor]]` table's gains
/// replaced by `gains` (its comments, order and formatting kept). Refused as
/// [`check_copy`] refuses.
pub fn write_copy(
    source: &Path,
    dest: &Path,
    gains: &[MotorGains],
    comment: &str,
) -> Result<(), WriteCopyError> {
    check_copy(source, dest)?;
    let io = |e: &dyn std::fmt::Display| WriteCopyError::Io(e.to_string());
    let text =
        std::fs::read_to_string(source).map_err(|e| io(&format!("{}: {e}", source.display())))?;
    let mut doc: DocumentMut =
        text.parse().map_err(|e| io(&format!("{}: {e}", source.display())))?;
    let tables = doc
        .get_mut("motor")
        .and_then(Item::as_array_of_tables_mut)
        .ok_or_else(|| io(&format!("{}: no [[motor]] tables", source.display())))?;
    for (table, g) in tables.iter_mut().zip(gains) {
        for (name, v) in TuneParam::ALL.into_iter().map(|p| (p.name(), p.get(g))) {
            if name == "kjff" && v == 0.0 && !table.contains_key(name) {
                continue;
            }
            let value: f64 = gain_text(v).parse().unwrap_or(v);
            match table.get_mut(name).and_then(Item::as_value_mut) {
                Some(old) => {
                    let decor = old.decor().clone();
                    *old = Value::from(value);
                    *old.decor_mut() = decor;
                }
                None => {
                    table.insert(name, toml_edit::value(value));
                }
            }
        }
    }
    let mut out = String::new();
    for line in comment.lines() {
        let _ = writeln!(out, "# {line}");
    }
    out.push_str(&doc.to_string());
    // Created new or not at all: no file that appeared meanwhile (or a dangling link) is
    // written through.
    let write = || -> std::io::Result<()> {
        use std::io::Write;
        std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .open(dest)?
            .write_all(out.as_bytes())
    };
    write().map_err(|e| io(&format!("{}: {e}", dest.display())))
}

/// What a tuning writes for programs that show it (the console): `tune-summary.json` in its
/// output folder.
pub const SUMMARY_FILE: &str = "tune-summary.json";

/// How the lines of progress printed when no terminal shows the bar begin.
pub const PROGRESS_PREFIX: &str = "tune progress: ";

/// A line of progress: the motor, the candidate, the moves and the best objective so far.
pub fn progress_line(r: &Record, n_motors: usize, objective: &str) -> String {
    format!(
        "{PROGRESS_PREFIX}motor {}/{n_motors}, candidate {}, {} moves, best {objective} {}",
        r.motor + 1,
        r.evaluation,
        r.moves,
        if r.best.is_finite() { format!("{:.5}", r.best) } else { "–".into() }
    )
}

/// One motor in [`TuneSummary`].
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MotorOutcome {
    /// The path's figures with the gains before.
    pub before: Figures,
    /// With the gains after (`None` when a stop or a fault ended the tuning).
    pub after: Option<Figures>,
    /// Kp, Ki, Kd, Kvff, Kaff, Kjff before.
    pub gains_before: [f64; 6],
    /// Kp, Ki, Kd, Kvff, Kaff, Kjff after, rounded as the settings file gets them.
    pub gains_after: [f64; 6],
}

/// The path a tuning ran, in words: the knot file, or the generator's own path (`the pick
/// path of [pick]`).
pub fn path_name(s: &qmarc_config::Settings) -> String {
    let method = &s.trajectory.method;
    match qmarc_plugins::registry::generator(method) {
        Some(g) if !g.needs_knots() => format!("the {method} path of [{method}]"),
        _ => s.trajectory.knots.as_ref().map_or("the path".into(), |k| k.display().to_string()),
    }
}

/// What a tuning found, as `tune-summary.json` says it.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TuneSummary {
    /// The `qmarc-starter` that tuned (a reader tells its own tuning from an earlier one).
    pub starter_pid: u32,
    /// The knot file of the path.
    pub knots: String,
    /// The trajectory generator.
    pub method: String,
    /// The objective (`abs`, `sse`, `max`).
    pub objective: String,
    /// The gains tuned (`kp` … `kjff`).
    pub params: Vec<String>,
    /// Candidates evaluated.
    pub candidates: usize,
    /// Moves made (of the path and of steps; in-process lock-step moves on the simulated
    /// robot).
    pub moves: u32,
    /// Why it ended early, if it did: the gains after are then the last safe ones.
    pub ended_early: Option<String>,
    /// Per motor.
    pub motors: Vec<MotorOutcome>,
}

impl TuneSummary {
    /// The summary of tuning `settings`' path: `tuned`, the gains after as written
    /// (`after`) and the path with them (`after_run`).
    pub fn new(
        settings: &qmarc_config::Settings,
        tuned: &Tuned,
        after: &[MotorGains],
        after_run: Option<&PathRun>,
    ) -> TuneSummary {
        let six = |g: &MotorGains| TuneParam::ALL.map(|p| p.get(g));
        // A generator with a path of its own (`step`, `pick`) reads no knot file.
        let reads_knots = qmarc_plugins::registry::generator(&settings.trajectory.method)
            .is_some_and(|g| g.needs_knots());
        let knots = settings.trajectory.knots.as_ref().filter(|_| reads_knots);
        TuneSummary {
            starter_pid: std::process::id(),
            knots: knots.map_or(String::new(), |k| k.display().to_string()),
            method: settings.trajectory.method.clone(),
            objective: settings.tune.objective.to_string(),
            params: settings.tune.params.iter().map(|p| p.name().to_string()).collect(),
            candidates: tuned.records.len(),
            moves: tuned.records.last().map_or(0, |r| r.moves),
            ended_early: tuned.aborted.as_ref().map(ToString::to_string),
            motors: (0..after.len())
                .map(|m| MotorOutcome {
                    before: tuned.before_run.motors.get(m).copied().unwrap_or_default(),
                    after: after_run.and_then(|r| r.motors.get(m).copied()),
                    gains_before: six(&tuned.before[m]),
                    gains_after: six(&after[m]),
                })
                .collect(),
        }
    }

    /// Writes it as [`SUMMARY_FILE`] into `dir`.
    pub fn write(&self, dir: &Path) -> std::io::Result<std::path::PathBuf> {
        let path = dir.join(SUMMARY_FILE);
        let text = serde_json::to_string_pretty(self).map_err(std::io::Error::other)?;
        std::fs::write(&path, text + "\n")?;
        Ok(path)
    }

    /// Reads [`SUMMARY_FILE`] from `dir`.
    pub fn read(dir: &Path) -> Result<TuneSummary, String> {
        let path = dir.join(SUMMARY_FILE);
        let text =
            std::fs::read_to_string(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        serde_json::from_str(&text).map_err(|e| format!("{}: {e}", path.display()))
    }
}
