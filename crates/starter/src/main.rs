//! `qmarc-starter`: runs one move (`home`, `step`, `run`) on the robot through the real
//! process split.
//!
//! Exit codes: the table of [`qmarc_proto::exit`] (docs/usage.md "Exit codes") — 0 the move ran to
//! its end and both children exited cleanly, 2 a fault ended it, 3 refused before anything
//! moved, 4 the results went to the rescue folder, 130 interrupted by a stop signal, 64 a bad
//! command line, 1 anything else.

use anyhow::{Context, anyhow};
use clap::{Parser, Subcommand};
use qmarc_plugins::registry::names;
use qmarc_proto::exit;
use qmarc_report::Summary;
use qmarc_starter::cli::{Command, MoveOptions};
use qmarc_starter::moves::{Failure, MoveRequest, Outcome, TrialIo, internal, refused};
use qmarc_starter::path::PathArgs;
use qmarc_starter::say;
use qmarc_starter::trials::{TrialsArgs, TrialsCsv};
use qmarc_starter::tune::TuneArgs;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

mod tune_command;

/// Command line of `qmarc-starter`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc-starter",
    version,
    about = "Run the QMARC controller: spawns qmarc-hwserver and qmarc-controller for one move",
    after_help = "Exit codes: 0 ok, 1 internal error, 2 fault during the move, 3 refused before \
                  moving, 4 results rescued (not in --out), 64 usage error, 130 interrupted."
)]
struct StarterArgs {
    #[command(flatten)]
    opts: MoveOptions,
    /// Prefix of this run's iceoryx2 files (default: qmarc_<pid>_, unique per run).
    #[arg(long, global = true)]
    iox_prefix: Option<String>,
    /// iceoryx2 root directory; it must exist (default: /tmp/iceoryx2/, created if missing).
    #[arg(long, global = true)]
    iox_root: Option<String>,
    /// Directory holding qmarc-hwserver and qmarc-controller (default: next to this program).
    #[arg(long, global = true)]
    bin_dir: Option<PathBuf>,
    /// Check everything, print the run both children would get (JSON) and exit: to run
    /// `qmarc-hwserver --settings FILE` and `qmarc-controller --settings FILE` by hand.
    #[arg(long, global = true)]
    print_settings: bool,
    /// After the move, draw its PNG plots next to gather.csv: arms, error, velocity and
    /// acceleration, servo period and, with a [robot], the end-effector path.
    #[arg(long, global = true)]
    plots: bool,
    #[command(subcommand)]
    command: StarterCommand,
}

/// A move, or a tool that prepares one.
#[derive(Debug, Subcommand)]
enum StarterCommand {
    #[command(flatten)]
    Move(Command),
    /// Make a knot file for `run` from Cartesian waypoints (`t_s x_m y_m z_m` per line)
    /// through the inverse kinematics of the settings' [robot]; writes it to `--out FILE`.
    Path(PathArgs),
    /// Run a move N times, one process set per trial, as a user pressing the button would;
    /// writes trials.csv and its plots in `--out`, each trial's data in `trial-NNN/`.
    Trials(TrialsArgs),
    /// Tune the gains on a path (argmin's Nelder–Mead per motor): in lock-step simulation on
    /// the simulated robot, by real moves on hardware (or with --paced); writes tune.csv,
    /// tuned-gains.toml and convergence.png in `--out` (default `<gather.out_dir>/tune`).
    Tune(TuneArgs),
}

/// One move (`trial` set: a trial's, quiet) with this command line's options.
fn one_move(args: &StarterArgs, command: &Command, trial: TrialIo<'_>) -> Result<Outcome, Failure> {
    qmarc_starter::moves::one_move(&MoveRequest {
        opts: &args.opts,
        command,
        bin_dir: args.bin_dir.as_deref(),
        iox_prefix: args.iox_prefix.as_deref(),
        iox_root: args.iox_root.as_deref(),
        print_settings: args.print_settings,
        trial,
    })
}

/// A move, and its plots with `--plots`.
fn run(args: &StarterArgs, command: &Command) -> Result<ExitCode, Failure> {
    let outcome = one_move(args, command, TrialIo::default())?;
    if args.plots
        && let Some((summary, dir)) = &outcome.summary
    {
        plot_move(summary, dir, outcome.robot.as_ref());
    }
    Ok(ExitCode::from(outcome.code))
}

/// Draws the plots of the move in `dir` (`robot`: its settings', for the end-effector) and
/// names them; a failure is said, not fatal (the move's data are written).
fn plot_move(summary: &Summary, dir: &Path, robot: Option<&qmarc_kinematics::Robot>) {
    if !dir.join("gather.csv").exists() {
        return say!("qmarc-starter: no plots: the move wrote no data");
    }
    match qmarc_plots::move_plots(dir, summary, robot) {
        Ok(done) => {
            let names: Vec<String> = done.iter().map(|p| p.display().to_string()).collect();
            println!("  plots: {}", names.join(", "));
        }
        Err(e) => say!("qmarc-starter: {e}"),
    }
}

/// The settings of `trials`, refused where a series would not repeat one move.
fn trials_settings(args: &StarterArgs, t: &TrialsArgs) -> Result<qmarc_config::Settings, Failure> {
    let names = names();
    let mut settings = args.opts.load(&names).map_err(refused)?;
    t.command.apply(&mut settings, &names).map_err(refused)?;
    if args.print_settings {
        return Err(refused(anyhow!(
            "trials makes moves: check the move with `qmarc-starter --print-settings run|step|home …`"
        )));
    }
    if matches!(t.command, Command::Jog(_) | Command::Check) {
        return Err(refused(anyhow!(
            "trials repeat a move the robot makes the same way each time: step, run or home, not \
             {} (a repeated jog walks toward a limit)",
            t.command.mode()
        )));
    }
    if settings.trajectory.knots.as_deref() == Some(Path::new("-")) {
        return Err(refused(anyhow!(
            "trials cannot read the path from standard input: every trial reads it again; give \
             a knot file"
        )));
    }
    Ok(settings)
}

/// `trials`: the move `t.command` made `t.n` times, each by its own process set.
fn trials(args: &StarterArgs, t: &TrialsArgs) -> Result<ExitCode, Failure> {
    let settings = trials_settings(args, t)?;
    let base = settings.gather.out_dir.clone();
    qmarc_report::output::check(&base, 0).map_err(refused)?;
    let _lock = qmarc_report::output::lock(&base).map_err(refused)?;
    // Every check of the move before anything of an earlier series is touched; then that
    // series goes, whole, into previous-trials/.
    let check = TrialIo { out: Some(&base), check_only: true, ..TrialIo::default() };
    one_move(args, &t.command, check)?;
    qmarc_starter::trials::retire_series(&base)
        .with_context(|| format!("cannot keep the earlier series of {}", base.display()))
        .map_err(refused)?;
    let mut csv = TrialsCsv::create(&base, settings.n_motors)
        .with_context(|| format!("cannot write {}", base.join("trials.csv").display()))
        .map_err(refused)?;
    // The trials' processes say what they say here, not over the progress bar.
    let log_path = base.join("trials.log");
    let log = std::fs::File::create(&log_path)
        .with_context(|| format!("cannot write {}", log_path.display()))
        .map_err(refused)?;
    let bar = indicatif::ProgressBar::new(u64::from(t.n));
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{pos}/{len} trials done [{bar:30}] {elapsed} · ETA {eta} · {msg}",
        )
        .map_err(internal)?
        .progress_chars("=> "),
    );
    let series = Series { args, t, settings: &settings, base: &base, log: &log, bar: &bar };
    let (mut what, stopped) = series.run(&mut csv)?;
    bar.finish_and_clear();
    if what.is_empty() {
        what = t.command.mode().to_string();
    }
    print!("{}", qmarc_starter::trials::render(&what, t.n, csv.rows()));
    let mut files = vec![csv.path().to_path_buf(), log_path];
    if !csv.rows().is_empty() {
        match qmarc_plots::trial_plots(&base, &what, csv.rows()) {
            Ok(done) => files.extend(done),
            Err(e) => say!("qmarc-starter: {e}"),
        }
    }
    let names: Vec<String> = files.iter().map(|p| p.display().to_string()).collect();
    println!(
        "\n  files: {}; each trial's data in {}",
        names.join(", "),
        base.join("trial-NNN").display()
    );
    if let Some((_, why)) = &stopped {
        say!("qmarc-starter: {why}");
    }
    Ok(ExitCode::from(match stopped {
        Some((code, _)) => code,
        None if csv.rows().iter().any(|r| !r.fault.is_empty()) => exit::FAULT,
        None => exit::OK,
    }))
}

/// A series of trials under way.
struct Series<'a> {
    args: &'a StarterArgs,
    t: &'a TrialsArgs,
    settings: &'a qmarc_config::Settings,
    base: &'a Path,
    log: &'a std::fs::File,
    bar: &'a indicatif::ProgressBar,
}

impl Series<'_> {
    /// The trials, one row of `csv` each: what they were (`Summary::what`) and, when the
    /// series stopped early, its exit code and why.
    fn run(&self, csv: &mut TrialsCsv) -> Result<(String, Option<(u8, String)>), Failure> {
        let (t, n_motors) = (self.t, self.settings.n_motors);
        let mut what = String::new();
        for k in 1..=t.n {
            let command = qmarc_starter::trials::command_of(&t.command, k, self.settings.step.size);
            let dir = qmarc_starter::trials::trial_dir(self.base, k);
            let _ = writeln!(&mut &*self.log, "== trial {k} ({})", dir.display());
            let io = TrialIo { out: Some(&dir), log: Some(self.log), ..TrialIo::default() };
            let outcome = match one_move(self.args, &command, io) {
                Ok(o) => o,
                Err(e) if k == 1 => return Err(e),
                Err(Failure { error: e, .. }) => {
                    let why = format!("trial {k} could not start: {e:#}");
                    return Ok((what, Some((exit::INTERNAL, why))));
                }
            };
            if let Some((summary, dir)) = &outcome.summary {
                what = summary.what();
                let row = qmarc_report::trials::TrialRow::of(k, summary, n_motors);
                if let Some(e) = row.abs_rad.first().filter(|e| e.is_finite()) {
                    self.bar.set_message(format!("last Σ|e| {e:.3e} rad (arm 1)"));
                }
                csv.push(row).map_err(internal)?;
                if self.args.plots {
                    self.bar.suspend(|| plot_move(summary, dir, outcome.robot.as_ref()));
                }
            }
            self.bar.inc(1);
            if let Some(stop) = series_stops(k, &outcome) {
                return Ok((what, Some(stop)));
            }
        }
        Ok((what, None))
    }
}

/// Whether the series stops after trial `k` ended with `outcome`: its exit code and why. An
/// emergency stop ends it (the next trial must be a person's decision, not the chain closing
/// again by itself), and so does anything but a move that ran or faulted.
fn series_stops(k: u32, outcome: &Outcome) -> Option<(u8, String)> {
    let estop = outcome
        .summary
        .as_ref()
        .and_then(|(s, _)| s.fault.as_ref())
        .is_some_and(|f| f.kind == qmarc_proto::state::FaultKind::EmergencyStop);
    if estop {
        return Some((exit::FAULT, format!("an emergency stop ended trial {k}: the series stops")));
    }
    match outcome.code {
        exit::OK | exit::FAULT => None,
        exit::INTERRUPTED => Some((exit::INTERRUPTED, format!("interrupted during trial {k}"))),
        c => Some((c, format!("trial {k} ended with exit code {c}: the series stops"))),
    }
}

fn main() -> ExitCode {
    let args: StarterArgs = qmarc_program::cli::parse_or_exit();
    let result = match &args.command {
        StarterCommand::Move(command) => run(&args, command),
        StarterCommand::Path(path) => qmarc_starter::path::make(&args.opts, path)
            .map(|done| {
                println!("{done}");
                ExitCode::SUCCESS
            })
            .map_err(refused),
        StarterCommand::Trials(t) => trials(&args, t),
        StarterCommand::Tune(t) => tune_command::tune(&args, t),
    };
    qmarc_program::cli::conclude("qmarc-starter", result.map_err(<(u8, anyhow::Error)>::from))
}
