//! `qmarc-starter tune run …`: better gains on the user's own path ([`qmarc_tune`]).
//!
//! On the simulated robot every candidate is a lock-step move inside this process, the robot
//! standing at the path's start (milliseconds each); on any other backend, or with
//! `--paced`, every candidate is a real move through the process set, within `tune.max_change`
//! of the best gains and at most `tune.max_moves` moves. Writes into `--out` (default
//! `<gather.out_dir>/tune`): `tune.csv` (every candidate), `tuned-gains.toml`,
//! `convergence.png`, `tune-summary.json` (the before/after figures and gains, for the
//! console) and, on the simulated robot, `before/` and `after/` (the path's data with the
//! gains before and after).

use crate::cli::RunArgs;
use anyhow::{Context, anyhow};
use clap::{Args, Subcommand};
use qmarc_config::{Mode, RunSpec, Settings};
use qmarc_foxglove::recording::Recording;
use qmarc_tune::eval::{EvalError, Evaluator, Objective, Param, PathRun};
use qmarc_tune::optimise::{Plan, Record, Tuned, tune};
use qmarc_tune::report;
use std::path::{Path, PathBuf};
use std::sync::atomic::AtomicBool;

/// Options of `tune`.
#[derive(Debug, Clone, PartialEq, Args)]
pub struct TuneArgs {
    /// The gains to tune, comma-separated (default: `tune.params`): kp, ki, kd, kvff, kaff,
    /// kjff.
    #[arg(long, value_delimiter = ',')]
    pub params: Option<Vec<String>>,
    /// What to minimise per motor over the path (default: `tune.objective`): `abs` Σ|e|,
    /// `sse` Σe², `max` max |e|.
    #[arg(long)]
    pub objective: Option<String>,
    /// Optimiser iterations per motor (default: `tune.budget`).
    #[arg(long, value_parser = clap::value_parser!(u32).range(1..=100_000))]
    pub budget: Option<u32>,
    /// Write a copy of the settings file with the tuned gains to FILE (never the file itself,
    /// never over an existing file).
    #[arg(long)]
    pub write: Option<PathBuf>,
    /// Real moves through the process set, paced by the timer, even on the simulated robot:
    /// the procedure of real hardware (implied by any other backend).
    #[arg(long)]
    pub paced: bool,
    /// The path to tune on.
    #[command(subcommand)]
    pub command: TuneCommand,
}

/// What `tune` tunes on.
#[derive(Debug, Clone, PartialEq, Subcommand)]
pub enum TuneCommand {
    /// A path from a knot file (thesis A.2.3): the path the robot will run.
    Run(RunArgs),
}

impl TuneArgs {
    /// The path's options.
    pub fn run_args(&self) -> &RunArgs {
        let TuneCommand::Run(r) = &self.command;
        r
    }

    /// Applies `--params`, `--objective` and `--budget` to `s.tune`.
    pub fn apply(&self, s: &mut Settings) -> anyhow::Result<()> {
        if let Some(p) = &self.params {
            s.tune.params = qmarc_config::check_params(p).map_err(|e| anyhow!("--params: {e}"))?;
        }
        if let Some(o) = &self.objective {
            s.tune.objective = o.parse().map_err(|e| anyhow!("--objective: {e}"))?;
        }
        if let Some(b) = self.budget {
            s.tune.budget = b;
        }
        Ok(())
    }
}

/// What a tuning left: what it found, the path with the gains after, and where it wrote.
pub struct TuneOutcome {
    /// The search.
    pub tuned: Tuned,
    /// The gains after, as written (rounded).
    pub after: Vec<qmarc_config::MotorGains>,
    /// The path with them (`None` when a stop or a fault ended the tuning: the robot is not
    /// known to be at the path's start).
    pub after_run: Option<PathRun>,
    /// The files written.
    pub files: Vec<PathBuf>,
}

/// Tunes the motors of `settings` on its path through `eval`, reporting each candidate to
/// `on_record`; writes the results into `out`. `local`: the lock-step move of the path on
/// the simulated robot, whose before/after data are written too.
pub fn run(
    settings: &Settings,
    eval: &mut dyn Evaluator,
    out: &Path,
    local: Option<&RunSpec>,
    on_record: &mut dyn FnMut(&Record),
) -> anyhow::Result<TuneOutcome> {
    let params: Vec<Param> = settings.tune.params.clone();
    let objective: Objective = settings.tune.objective;
    let plan = Plan {
        tune: &settings.tune,
        params: &params,
        objective,
        budget: settings.tune.budget,
        law: (settings.fe_scale, (settings.gains_period_us, settings.period_us)),
    };
    let before = &settings.motors[..settings.n_motors];
    let tuned = tune(&plan, before, eval, on_record)?;
    let after: Vec<_> = tuned.after.iter().map(report::rounded).collect();
    let mut files = Vec::new();
    let csv = out.join("tune.csv");
    std::fs::write(&csv, report::csv(&tuned.records))
        .with_context(|| format!("cannot write {}", csv.display()))?;
    files.push(csv);
    let toml = out.join("tuned-gains.toml");
    std::fs::write(&toml, report::fragment(&after, &provenance(settings)))
        .with_context(|| format!("cannot write {}", toml.display()))?;
    files.push(toml);
    let series = report::convergence(&tuned.records, settings.n_motors);
    let what = match objective {
        Objective::Abs => "Σ|e|, rad",
        Objective::Sse => "Σe², rad²",
        Objective::Max => "max |e|, rad",
    };
    let title = format!("QMARC tune on {}", report::path_name(settings));
    match qmarc_plots::convergence_plot(out, &title, what, &series) {
        Ok(png) => files.push(png),
        Err(e) => eprintln!("qmarc-starter: {e}"),
    }
    if let Some(spec) = local {
        for (name, gains) in [("before", before), ("after", &after[..])] {
            files.push(write_local(spec, gains, &out.join(name))?);
        }
    }
    // The path with the tuned gains, for the table: one move beyond the move budget, not
    // after a stop or a fault (the robot is then not known to be at the path's start).
    eval.final_move();
    let after_run = match tuned.aborted {
        None | Some(EvalError::MoveBudget(_)) => eval.path(&after).ok(),
        Some(_) => None,
    };
    let summary = report::TuneSummary::new(settings, &tuned, &after, after_run.as_ref());
    files.push(summary.write(out).with_context(|| format!("cannot write into {}", out.display()))?);
    Ok(TuneOutcome { tuned, after, after_run, files })
}

/// Where tuned gains came from: the comment over them.
pub fn provenance(s: &Settings) -> String {
    format!(
        "gains tuned by `qmarc-starter tune` on {} ({}), objective {}, from {}",
        report::path_name(s),
        s.trajectory.method,
        s.tune.objective,
        s.source.display()
    )
}

/// Runs the path of `spec` with `gains` in lock-step inside this process and writes its
/// data files into `dir`.
fn write_local(
    spec: &RunSpec,
    gains: &[qmarc_config::MotorGains],
    dir: &Path,
) -> anyhow::Result<PathBuf> {
    let mut s = spec.settings.clone();
    s.motors[..gains.len()].copy_from_slice(gains);
    s.gather.out_dir = dir.to_path_buf();
    let spec = RunSpec { settings: s, mode: Mode::Run, ..spec.clone() };
    let mut done = qmarc_tune::local::run_local(&spec, &AtomicBool::new(false))?;
    let frozen = done.summary.clone();
    let r = &done.record;
    let recording = Recording::of(&spec.settings, r, &frozen, &[]);
    recording.write_results(dir, &mut done.summary, std::process::id(), &[])?;
    Ok(dir.to_path_buf())
}
