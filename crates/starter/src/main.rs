//! `qmarc-starter`: runs one move (`home`, `step`, `run`) on the robot through the real
//! process split.
//!
//! Exit codes: the table of [`qmarc_proto::exit`] (README "Exit codes") — 0 the move ran to
//! its end and both children exited cleanly, 2 a fault ended it, 3 refused before anything
//! moved, 4 the results went to the rescue folder, 130 interrupted by a stop signal, 64 a bad
//! command line, 1 anything else.

mod lost;

use anyhow::{Context, anyhow};
use clap::{Parser, Subcommand};
use lost::{controller_lost_message, lost, stopped_by, stopped_responding};
use qmarc_config::{RunSpec, Settings};
use qmarc_controller::gather::check_budget;
use qmarc_plugins::registry;
use qmarc_proto::exit;
use qmarc_proto::progress::Progress;
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation};
use qmarc_proto::state::FaultKind;
use qmarc_proto::state::Phase;
use qmarc_report::Summary;
use qmarc_report::table;
use qmarc_starter::cli::{Command, MoveOptions};
use qmarc_starter::path::PathArgs;
use qmarc_starter::supervise::{self, Supervised};
use qmarc_starter::trials::{TrialsArgs, TrialsCsv};
use qmarc_starter::tune::TuneArgs;
use qmarc_starter::{
    Exit, check_iox_root, default_prefix, describe_exit, names, remove_stale_files, run_file,
};
use std::io::{IsTerminal, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

mod tuning;

/// A line on standard error that cannot fail: if whoever reads it went away (a closed pipe),
/// the starter still stops its children and removes its files.
macro_rules! say {
    ($($t:tt)*) => {{
        let _ = writeln!(std::io::stderr(), $($t)*);
    }};
}

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

/// An error and the exit code it ends the run with.
type Failure = (u8, anyhow::Error);

/// `?` for errors of the user's input: the run is refused.
fn refused<E: Into<anyhow::Error>>(e: E) -> Failure {
    (exit::REFUSED, e.into())
}

/// `?` for everything else.
fn internal<E: Into<anyhow::Error>>(e: E) -> Failure {
    (exit::INTERNAL, e.into())
}

/// How a move ended: its exit code, its summary and the folder it is in, and the robot of
/// its settings (for the end-effector plots).
struct Outcome {
    code: u8,
    summary: Option<(Summary, PathBuf)>,
    robot: Option<qmarc_kinematics::Robot>,
}

/// How a trial's move differs from a move by hand.
#[derive(Default)]
struct TrialIo<'a> {
    /// The output folder instead of the settings'.
    out: Option<&'a Path>,
    /// The children's standard error goes here; no table is printed.
    log: Option<&'a std::fs::File>,
    /// Check everything, as `--print-settings` does, and start nothing.
    check_only: bool,
    /// These settings instead of the file's with the command line's (a tuning's candidate).
    settings: Option<&'a Settings>,
}

/// One move (`trial` set: a trial's, quiet).
fn one_move(args: &StarterArgs, command: &Command, trial: TrialIo<'_>) -> Result<Outcome, Failure> {
    let (out, quiet) = (trial.out, trial.log.is_some());
    // Everything is checked before anything starts.
    let names = names();
    let mut settings = match trial.settings {
        Some(s) => s.clone(),
        None => {
            let mut s = args.opts.load(&names).map_err(refused)?;
            command.apply(&mut s, &names).map_err(refused)?;
            s
        }
    };
    if let Some(out) = out {
        settings.gather.out_dir = out.to_path_buf();
    }
    let mode = command.mode();
    let bin_dir = qmarc_starter::bin_dir(args.bin_dir.as_deref()).map_err(internal)?;
    let hwserver_bin = bin_dir.join("qmarc-hwserver");
    let controller_bin = bin_dir.join("qmarc-controller");
    for b in [&hwserver_bin, &controller_bin] {
        if !b.is_file() {
            return Err(internal(anyhow!(
                "{} not found: build the workspace first (`cargo build --release`)",
                b.display()
            )));
        }
    }
    let prefix = args.iox_prefix.clone().unwrap_or_else(default_prefix);
    let root = args.iox_root.clone().unwrap_or_else(|| DEFAULT_ROOT.to_string());
    let location = IpcLocation::checked(&prefix, &root).map_err(|e| refused(anyhow!(e)))?;
    check_iox_root(&location.root, args.iox_root.is_some()).map_err(|e| refused(anyhow!(e)))?;
    location.config().map_err(refused)?;
    let spec = RunSpec {
        settings,
        mode,
        deterministic: args.opts.lockstep(),
        unpaced: args.opts.unpaced,
        unhomed: args.opts.unhomed,
        iox_prefix: location.prefix.clone(),
        iox_root: location.root.clone(),
    };
    let settings = &spec.settings;
    if spec.unpaced && settings.hwserver.backend != "sim" {
        return Err(refused(anyhow!(
            "--unpaced runs only on the simulated robot (`--backend sim`), not on `{}`: real \
             hardware moves in real time",
            settings.hwserver.backend
        )));
    }
    // The hardware: there, usable and as the settings describe it (a missing device fails
    // here, at once, naming it).
    qmarc_hwserver::backends::check(settings, spec.deterministic).map_err(refused)?;

    // The path: knot files are read and checked now (streams are the controller's to read:
    // it inherits standard input), and its data must fit the gather budget and the disk.
    let generator = qmarc_runner::run::generator_name(mode, settings);
    let entry = registry::generator(generator)
        .with_context(|| format!("no trajectory generator `{generator}`"))
        .map_err(refused)?;
    let path = (entry.build)(settings).map_err(refused)?;
    let planned = path.samples();
    drop(path);
    let settle = (settings.trajectory.settle_s / settings.period_s()).round() as u64;
    let samples = planned.unwrap_or(qmarc_runner::run::stream_gather_samples(settings)) + settle;
    check_budget(samples, settings.gather.every).map_err(refused)?;
    let out_dir = settings.gather.out_dir.clone();
    let rows = samples.div_ceil(u64::from(settings.gather.every));
    qmarc_report::output::check(
        &out_dir,
        qmarc_report::output::estimate_bytes(rows, settings.n_motors),
    )
    .map_err(refused)?;
    if args.print_settings || trial.check_only {
        if args.print_settings {
            println!("{}", spec.to_json());
        }
        return Ok(Outcome { code: exit::OK, summary: None, robot: None });
    }
    let _lock = qmarc_report::output::lock(&out_dir).map_err(refused)?;

    remove_stale_files(&location.root);
    if args.iox_prefix.is_some() {
        qmarc_starter::remove_own_stale_files(&location);
    }
    let stop = qmarc_timer::stop::install().map_err(internal)?;
    let progress = Progress::create(&Progress::path(&location.prefix)).ok();
    // The one settings value both children get, next to the run's shared memory.
    let run = run_file(&location.prefix);
    spec.write(&run).map_err(internal)?;
    let child_args = [format!("--settings={}", run.display())];
    // The children inherit this mask; the hwserver and the servo thread then pin themselves.
    if let Err(e) = qmarc_timer::cpus::keep_off(&settings.timer.rt_cpus()) {
        say!("qmarc-starter: warning: cannot keep off the real-time CPUs ({e})");
    }

    let hwserver = supervise::spawn_logged(&hwserver_bin, &child_args, trial.log)
        .with_context(|| format!("cannot start {}", hwserver_bin.display()))
        .map_err(|e| {
            location.remove_files();
            internal(e)
        })?;
    // The hwserver has nothing to save: 3 s to end by itself, 2 s after SIGTERM. The
    // controller may be writing a long move's data: two minutes to end by itself, and after
    // SIGTERM (which it answers within a second, writing or not) 10 s.
    let secs = Duration::from_secs;
    let mut children = vec![Supervised::new("qmarc-hwserver", hwserver, secs(3), secs(2))];
    match supervise::spawn_logged(&controller_bin, &child_args, trial.log) {
        Ok(c) => children.push(Supervised::new("qmarc-controller", c, secs(120), secs(10))),
        Err(e) => {
            say!("qmarc-starter: cannot start {}: {e}", controller_bin.display());
            supervise::send(&children[0].child, nix::sys::signal::Signal::SIGTERM);
        }
    }
    let status = std::cell::RefCell::new(StatusLine::new(progress.as_ref()));
    // A child stopped (SIGSTOP) this long has stopped responding: the other would wait for it
    // no longer (the hwserver's watchdog, the controller's response timeout). In lock-step
    // the other waits for as long as it lives (simulated time sees no stall): so does this.
    let hw = &settings.hwserver;
    let stall_limit = if spec.deterministic {
        Duration::MAX
    } else {
        Duration::from_secs_f64(
            settings.period_s() * f64::from(hw.watchdog_periods.max(hw.response_timeout_periods)),
        )
    };
    supervise::wait_all(
        &mut children,
        stop,
        stall_limit,
        |s| {
            status.borrow_mut().clear();
            match (s.exit, s.unresponsive) {
                (Some(exit), _) if !exit.success() => {
                    say!("qmarc-starter: {}", describe_exit(s.name, exit))
                }
                (None, Some(u)) => {
                    say!("qmarc-starter: {}; ending the run", u.describe(s.name))
                }
                _ => {}
            }
        },
        || status.borrow_mut().update(),
    );
    status.borrow_mut().clear();
    let reached = progress.as_ref().map(Progress::read);
    drop(progress);
    location.remove_files();

    let all_clean =
        children.len() == 2 && children.iter().all(|s| s.exit.is_some_and(|e| e.success()));
    let controller = children.iter().find(|s| s.name == "qmarc-controller").and_then(|s| s.exit);
    let hwserver = children[0].exit;
    let unresponsive = children.iter().find_map(|s| s.unresponsive.map(|u| (s.name, u)));
    let (mut summary, mut summary_dir) = match read_own_summary(&out_dir) {
        Some((s, d)) => (Some(s), d),
        None => (None, out_dir.clone()),
    };
    // The controller wrote what it gathered, but could not know why the run ended.
    if let (Some(s), Some((name, u))) = (summary.as_mut(), unresponsive) {
        stopped_responding(s, name, u);
        if let Err(e) = qmarc_report::output::amend_summary(&summary_dir, s) {
            say!("qmarc-starter: {e}");
        }
    }
    // A controller that died — killed, or failed once its move had begun (a panic, data it
    // could not write anywhere) — wrote nothing: say what is known, and what the hwserver
    // did. One that refused before anything moved has said why.
    let began = reached
        .and_then(|r| qmarc_proto::state::Phase::from_code(r.phase))
        .is_some_and(|p| !matches!(p, Phase::Idle | Phase::Preparing));
    if summary.is_none()
        && let Some(exit) = controller.filter(|e| lost(*e, began, stopped_by(stop)))
    {
        let mut lost = Summary::controller_lost(
            (mode, spec.deterministic),
            settings.n_motors,
            settings.period_us,
            reached.map_or(0, |r| r.cycle),
            controller_lost_message(exit, hwserver, settings, reached),
        );
        if let Some((name, u)) = unresponsive {
            stopped_responding(&mut lost, name, u);
        }
        if let Err(e) = qmarc_report::output::write_summary_set(&out_dir, &lost) {
            say!("qmarc-starter: {e}");
        }
        summary = Some(lost);
        summary_dir = out_dir.clone();
    }
    if summary.is_none() && controller.is_some_and(Exit::success) {
        // It ended well and said it wrote its results: they are there, but cannot be read.
        let why = Summary::read(&out_dir).err().unwrap_or_else(|| "not this run's".into());
        say!("qmarc-starter: the controller ended well, but its summary cannot be read: {why}");
    }
    match &summary {
        Some(_) if quiet => {}
        Some(s) => {
            let _ = write!(std::io::stdout(), "{}", table::render(s));
        }
        None => say!(
            "qmarc-starter: no move was made{}",
            if stop.load(std::sync::atomic::Ordering::Relaxed) {
                ": interrupted before it began"
            } else {
                ""
            }
        ),
    }
    let code = match (&summary, controller) {
        // The check ran, and found a motor to mend.
        (Some(s), _) if s.check.as_ref().is_some_and(|c| c.iter().any(|m| !m.ok)) => exit::FAULT,
        // A process stopped responding: the run was ended for it.
        _ if unresponsive.is_some() => exit::FAULT,
        // The move ran, but its results are not where they were asked for.
        (Some(s), Some(Exit::Code(c))) if s.ok && c == i32::from(exit::RESCUED) => exit::RESCUED,
        (Some(s), _) if s.ok && all_clean => exit::OK,
        (Some(s), _) if s.fault.as_ref().is_some_and(|f| f.kind == FaultKind::Aborted) => {
            exit::INTERRUPTED
        }
        // The move ran, but its controller failed after it (its data could not be written).
        (Some(s), Some(Exit::Code(c)))
            if c == i32::from(exit::INTERNAL)
                && s.fault.as_ref().is_some_and(|f| f.kind == FaultKind::ControllerLost) =>
        {
            exit::INTERNAL
        }
        (Some(s), _) if s.fault.is_some() => exit::FAULT,
        // Done without a fault, but not ok (figures that are not numbers).
        (Some(s), _) if !s.ok => exit::FAULT,
        (None, Some(Exit::Code(c))) if c == i32::from(exit::REFUSED) => exit::REFUSED,
        (None, Some(Exit::Code(c))) if c == i32::from(exit::INTERRUPTED) => exit::INTERRUPTED,
        _ if stop.load(std::sync::atomic::Ordering::Relaxed) => exit::INTERRUPTED,
        _ => exit::INTERNAL,
    };
    Ok(Outcome { code, summary: summary.map(|s| (s, summary_dir)), robot: settings.robot() })
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

/// `trials`: the move `t.command` made `t.n` times, each by its own process set.
fn trials(args: &StarterArgs, t: &TrialsArgs) -> Result<ExitCode, Failure> {
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
    let mut what = String::new();
    let mut stopped = None;
    for k in 1..=t.n {
        let command = qmarc_starter::trials::command_of(&t.command, k, settings.step.size);
        let dir = qmarc_starter::trials::trial_dir(&base, k);
        let _ = writeln!(&log, "== trial {k} ({})", dir.display());
        let io = TrialIo { out: Some(&dir), log: Some(&log), ..TrialIo::default() };
        let outcome = match one_move(args, &command, io) {
            Ok(o) => o,
            Err(e) if k == 1 => return Err(e),
            Err((_, e)) => {
                stopped = Some((exit::INTERNAL, format!("trial {k} could not start: {e:#}")));
                break;
            }
        };
        if let Some((summary, dir)) = &outcome.summary {
            what = summary.what();
            let row = qmarc_report::trials::TrialRow::of(k, summary, settings.n_motors);
            if let Some(e) = row.abs_rad.first().filter(|e| e.is_finite()) {
                bar.set_message(format!("last Σ|e| {e:.3e} rad (arm 1)"));
            }
            csv.push(row).map_err(internal)?;
            if args.plots {
                bar.suspend(|| plot_move(summary, dir, outcome.robot.as_ref()));
            }
        }
        bar.inc(1);
        // An emergency stop ends the series: the next trial must be a person's decision, not
        // the chain closing again by itself.
        let estop = outcome
            .summary
            .as_ref()
            .and_then(|(s, _)| s.fault.as_ref())
            .is_some_and(|f| f.kind == qmarc_proto::state::FaultKind::EmergencyStop);
        if estop {
            stopped =
                Some((exit::FAULT, format!("an emergency stop ended trial {k}: the series stops")));
            break;
        }
        match outcome.code {
            exit::OK | exit::FAULT => {}
            exit::INTERRUPTED => {
                stopped = Some((exit::INTERRUPTED, format!("interrupted during trial {k}")));
                break;
            }
            c => {
                stopped =
                    Some((c, format!("trial {k} ended with exit code {c}: the series stops")));
                break;
            }
        }
    }
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

/// The summary this run's controller wrote and its folder: `summary.json` in `out_dir` if
/// this starter's (an older run's is not this run's result), else the one in the rescue
/// folder.
fn read_own_summary(out_dir: &Path) -> Option<(Summary, PathBuf)> {
    let me = std::process::id();
    let rescue = qmarc_report::output::rescue_dir(me);
    [out_dir.to_path_buf(), rescue]
        .into_iter()
        .filter_map(|d| Summary::read(&d).ok().map(|s| (s, d)))
        .find(|(s, _)| s.starter_pid == me)
}

/// Homing shown as it happens on a terminal: one status line on standard error, rewritten
/// in place, cleared before anything else is printed.
struct StatusLine<'a> {
    progress: Option<&'a Progress>,
    shown: String,
    on_terminal: bool,
}

impl<'a> StatusLine<'a> {
    fn new(progress: Option<&'a Progress>) -> StatusLine<'a> {
        StatusLine { progress, shown: String::new(), on_terminal: std::io::stderr().is_terminal() }
    }

    fn update(&mut self) {
        let Some(p) = self.progress.filter(|_| self.on_terminal) else { return };
        let text = qmarc_plugins::homing::describe_progress(p.read().detail).unwrap_or_default();
        if text != self.shown {
            let _ = write!(std::io::stderr(), "\r\x1b[K{text}");
            self.shown = text;
        }
    }

    fn clear(&mut self) {
        if !self.shown.is_empty() {
            let _ = write!(std::io::stderr(), "\r\x1b[K");
            self.shown.clear();
        }
    }
}

fn main() -> ExitCode {
    let args: StarterArgs = qmarc_starter::cli::parse_or_exit();
    let result = match &args.command {
        StarterCommand::Move(command) => run(&args, command),
        StarterCommand::Path(path) => qmarc_starter::path::make(&args.opts, path)
            .map(|done| {
                println!("{done}");
                ExitCode::SUCCESS
            })
            .map_err(refused),
        StarterCommand::Trials(t) => trials(&args, t),
        StarterCommand::Tune(t) => tuning::tune(&args, t),
    };
    match result {
        Ok(code) => code,
        Err((code, e)) => {
            say!("qmarc-starter: error: {e:#}");
            ExitCode::from(code)
        }
    }
}
