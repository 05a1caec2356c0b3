//! The Tune action of the Gains section (Ctrl-T), what the console's state is told of it:
//! `qmarc-starter tune run` on the settings' path, its progress on the message line while it runs (the starter's `tune progress:`
//! lines, which it prints when no terminal shows its bar), the before/after figures and gains
//! on the results page when it ends (from its `tune-summary.json`), and Ctrl-A, which puts
//! the tuned gains into the form (saved by F10 or by the next move, like any edit).

use crate::form::Place;
use crate::results::MoveResult;
use qmarc_config::TUNE_PARAMS;
use qmarc_tune::eval::Figures;
use qmarc_tune::report::{PROGRESS_PREFIX, TuneSummary, gain_text};
use ratatui::style::{Color, Style};
use ratatui::text::Line;
use std::path::{Path, PathBuf};
use std::process::ExitStatus;

/// What the last tuning found.
#[derive(Debug, Clone, PartialEq)]
pub struct TuneResult {
    /// Its `tune-summary.json`.
    pub summary: TuneSummary,
    /// Its output folder.
    pub dir: PathBuf,
    /// It is what the results page shows: no move has ended since.
    pub latest: bool,
}

/// The message line's words for the newest of a tuning's progress `lines`, if one is among
/// them.
pub fn progress(lines: &[String]) -> Option<String> {
    let p = lines.iter().rev().find_map(|l| l.strip_prefix(PROGRESS_PREFIX))?;
    Some(format!("tuning: {p} · F9 stops it (the best gains so far are kept)"))
}

/// What a tuning that ended left: its result, the path run with the tuned gains (the
/// results page's last move) or why there is none, and the message to say.
#[derive(Debug)]
pub struct TuneEnded {
    /// The tuning's result.
    pub result: TuneResult,
    /// The path run with the tuned gains, when there is one.
    pub last: Option<MoveResult>,
    /// Why there is no such path, if there is none.
    pub note: Option<String>,
    /// The message line's words, and whether they are an error's.
    pub message: (String, bool),
}

/// The tuning of starter `pid` into `out_dir` ended with `status`: what it left (refused if
/// an earlier tuning wrote it), or why there is nothing, in words.
pub fn ended(out_dir: &Path, pid: u32, status: ExitStatus) -> Result<TuneEnded, String> {
    let dir = out_dir.join("tune");
    let summary = TuneSummary::read(&dir).and_then(|s| {
        if s.starter_pid == pid {
            Ok(s)
        } else {
            Err(format!("{} is from an earlier tuning", dir.join("tune-summary.json").display()))
        }
    });
    let summary = summary.map_err(|e| format!("tune ended ({status}) without results: {e}"))?;
    // On the simulated robot `after/`; by real moves the last move, which ran the path with
    // the tuned gains when the tuning was not stopped.
    let tuned_path = summary.motors.iter().all(|m| m.after.is_some());
    let last = ["after", "moves"]
        .iter()
        .filter(|_| tuned_path)
        .find_map(|d| MoveResult::load(&dir.join(d)).ok());
    let note = last
        .is_none()
        .then(|| format!("the tuning left no path run with the tuned gains in {}", dir.display()));
    let message = match &summary.ended_early {
        Some(why) => {
            (format!("tune ended early ({why}): Ctrl-A puts the last safe gains in the form"), true)
        }
        None => (
            format!(
                "tune done, {} candidates: Ctrl-A puts the tuned gains in the form (F10 saves)",
                summary.candidates
            ),
            false,
        ),
    };
    Ok(TuneEnded { result: TuneResult { summary, dir, latest: true }, last, note, message })
}

impl TuneResult {
    /// The gains it tuned, as the form's fields and their text.
    pub fn tuned_gains(&self) -> Vec<(Place, String)> {
        let mut tuned = Vec::new();
        for (m, motor) in self.summary.motors.iter().enumerate() {
            for (k, key) in TUNE_PARAMS.iter().enumerate() {
                if self.summary.params.iter().any(|p| p == key) {
                    tuned.push((Place::Motor(m, key), gain_text(motor.gains_after[k])));
                }
            }
        }
        tuned
    }
}

/// One of a motor's figures.
type Figure = fn(&Figures) -> f64;

/// A figure in a few characters: 3 significant digits.
fn num(v: f64) -> String {
    if v == 0.0 || (1e-2..1e4).contains(&v.abs()) { format!("{v:.3}") } else { format!("{v:.1e}") }
}

/// A gain as a person reads it: whole above 1000, else to the thousandth.
fn gain(v: f64) -> String {
    if v.abs() >= 1e3 { format!("{v:.0}") } else { format!("{}", (v * 1e3).round() / 1e3) }
}

/// `before→after ×ratio` (at most 21 characters: three motors fit 80 columns).
fn cell(before: f64, after: Option<f64>) -> String {
    match after {
        Some(a) if before != 0.0 => format!("{}→{} ×{:.2}", num(before), num(a), a / before),
        Some(a) => format!("{}→{}", num(before), num(a)),
        None => format!("{}→–", num(before)),
    }
}

/// The results page's lines for `t`: what was tuned, the four thesis error figures and the
/// DAC saturation per motor before → after, and the gains tuned.
pub fn lines(t: &TuneResult) -> Vec<Line<'static>> {
    let s = &t.summary;
    let mut out = vec![Line::styled(
        format!(
            "tune on {} ({}), objective {}: {} candidates{}",
            s.knots,
            s.method,
            s.objective,
            s.candidates,
            if s.moves > 0 { format!(", {} moves", s.moves) } else { String::new() }
        ),
        Style::new().fg(Color::Green).bold(),
    )];
    if let Some(why) = &s.ended_early {
        out.push(Line::styled(
            format!("ended early: {why}; the gains after are the last safe ones"),
            Style::new().fg(Color::Red).bold(),
        ));
    }
    const W: usize = 22;
    let head: String =
        (1..=s.motors.len()).map(|m| format!("{:<W$}", format!("M{m} before→after"))).collect();
    out.push(Line::styled(format!("{:<11}{head}", ""), Style::new().bold()));
    let figures: [(&str, Figure); 5] = [
        ("Σ|e| rad", |f| f.abs_rad),
        ("Σe² rad²", |f| f.sse_rad2),
        ("max e rad", |f| f.max_rad),
        ("min e rad", |f| f.min_rad),
        ("DAC sat. %", |f| f.saturated * 100.0),
    ];
    for (name, get) in figures {
        let row: String = s
            .motors
            .iter()
            .map(|m| format!("{:<W$}", cell(get(&m.before), m.after.as_ref().map(get))))
            .collect();
        out.push(Line::from(format!("{name:<11}{row}")));
    }
    for (k, key) in TUNE_PARAMS.iter().enumerate() {
        if !s.params.iter().any(|p| p == key) {
            continue;
        }
        let row: String = s
            .motors
            .iter()
            .map(|m| {
                let text = format!("{}→{}", gain(m.gains_before[k]), gain(m.gains_after[k]));
                format!("{text:<W$}")
            })
            .collect();
        out.push(Line::from(format!("{key:<11}{row}")));
    }
    out.push(Line::styled(
        format!("Ctrl-A puts these gains in the form · files in {}", t.dir.display()),
        Style::new().dim(),
    ));
    out
}
