//! `qmarc-starter`: runs one move (`step`) on the robot through the real process split.
//!
//! Exit codes: 0 when the move ran to its end and both children exited cleanly, 2 when a
//! fault ended it, 1 when it could not run (bad settings, a child that failed or died).

use anyhow::{Context, bail};
use clap::Parser;
use qmarc_controller::cli::{Mode, MoveOptions};
use qmarc_controller::config::Settings;
use qmarc_controller::gather::check_budget;
use qmarc_controller::registry;
use qmarc_controller::run::remove_outputs;
use qmarc_controller::summary::Summary;
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation};
use qmarc_starter::supervise::{self, Supervised};
use qmarc_starter::{
    Exit, default_prefix, describe_exit, hwserver_args, remove_stale_files, table,
};
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Duration;

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
    about = "Run the QMARC controller: spawns qmarc-hwserver and qmarc-controller for one move"
)]
struct StarterArgs {
    #[command(flatten)]
    opts: MoveOptions,
    /// Prefix of this run's iceoryx2 files (default: qmarc_<pid>_, unique per run).
    #[arg(long, global = true)]
    iox_prefix: Option<String>,
    /// iceoryx2 root directory.
    #[arg(long, global = true, default_value = DEFAULT_ROOT)]
    iox_root: String,
    /// Directory holding qmarc-hwserver and qmarc-controller (default: next to this program).
    #[arg(long, global = true)]
    bin_dir: Option<PathBuf>,
    #[command(subcommand)]
    mode: Mode,
}

fn run(args: &StarterArgs) -> anyhow::Result<ExitCode> {
    // Everything is checked before anything starts.
    let mut settings = args.opts.load()?;
    args.mode.apply(&mut settings)?;
    let bin_dir = match &args.bin_dir {
        Some(d) => d.clone(),
        None => std::env::current_exe()?
            .parent()
            .context("no directory for this program")?
            .to_path_buf(),
    };
    let hwserver_bin = bin_dir.join("qmarc-hwserver");
    let controller_bin = bin_dir.join("qmarc-controller");
    for b in [&hwserver_bin, &controller_bin] {
        if !b.is_file() {
            bail!("{} not found: build the workspace first (`cargo build --release`)", b.display());
        }
    }
    let prefix = args.iox_prefix.clone().unwrap_or_else(default_prefix);
    let location = IpcLocation::checked(&prefix, &args.iox_root).map_err(anyhow::Error::msg)?;
    location.config()?;
    let hw_args = hwserver_args(&settings, args.opts.deterministic, &location);
    hw_args.sim_params().context("simulator settings")?;
    let mut ctl_args = args.opts.to_args();
    ctl_args.push(format!("--iox-prefix={}", location.prefix));
    ctl_args.push(format!("--iox-root={}", location.root));
    ctl_args.extend(args.mode.to_args());

    // The path: knot files are read and checked now (streams are the controller's to read:
    // it inherits standard input), and its data must fit the gather budget.
    let generator = args.mode.generator(&settings);
    let entry = registry::generator(generator)
        .with_context(|| format!("no trajectory generator `{generator}`"))?;
    let path = (entry.build)(&settings)?;
    if let Some(samples) = path.samples() {
        check_budget(samples, settings.gather.every)?;
    }
    drop(path);

    let out_dir = settings.gather.out_dir.clone();
    remove_outputs(&out_dir);
    remove_stale_files(&location.root);
    let stop = qmarc_timer::stop::install()?;

    let hwserver = supervise::spawn(&hwserver_bin, &hw_args.to_args())
        .with_context(|| format!("cannot start {}", hwserver_bin.display()))?;
    // The hwserver has nothing to save: 3 s to end by itself, 2 s after SIGTERM. The
    // controller may be writing a long move's data: two minutes for each.
    let secs = Duration::from_secs;
    let mut children = vec![Supervised::new("qmarc-hwserver", hwserver, secs(3), secs(2))];
    match supervise::spawn(&controller_bin, &ctl_args) {
        Ok(c) => children.push(Supervised::new("qmarc-controller", c, secs(120), secs(120))),
        Err(e) => {
            say!("qmarc-starter: cannot start {}: {e}", controller_bin.display());
            supervise::send(&children[0].child, libc::SIGTERM);
        }
    }
    supervise::wait_all(&mut children, stop, |s| {
        if let Some(exit) = s.exit.filter(|e| !e.success()) {
            say!("qmarc-starter: {}", describe_exit(s.name, exit));
        }
    });
    location.remove_files();

    let all_clean =
        children.len() == 2 && children.iter().all(|s| s.exit.is_some_and(|e| e.success()));
    let summary_path = out_dir.join("summary.json");
    let mut summary: Option<Summary> =
        std::fs::read(&summary_path).ok().and_then(|b| serde_json::from_slice(&b).ok());
    // A controller that died wrote nothing: say what happened, and what the hwserver did.
    let controller = children.iter().find(|s| s.name == "qmarc-controller").and_then(|s| s.exit);
    let hwserver = children[0].exit;
    if summary.is_none()
        && let Some(exit @ Exit::Signal(_)) = controller
    {
        let lost = Summary::controller_lost(
            args.mode.name(),
            settings.period_us,
            controller_lost_message(exit, hwserver, &settings),
        );
        if let Err(e) = write_summary(&summary_path, &lost) {
            say!("qmarc-starter: cannot write {}: {e}", summary_path.display());
        }
        summary = Some(lost);
    }
    match &summary {
        Some(s) => {
            let _ = write!(std::io::stdout(), "{}", table::render(s, &out_dir));
        }
        None => say!("qmarc-starter: no summary was written: the move did not complete"),
    }
    Ok(match summary {
        Some(s) if s.ok && all_clean => ExitCode::SUCCESS,
        Some(s) if s.fault.is_some() => ExitCode::from(2),
        _ => ExitCode::from(1),
    })
}

/// What the starter knows when the controller died: how, and how the hwserver ended.
fn controller_lost_message(controller: Exit, hwserver: Option<Exit>, s: &Settings) -> String {
    let how = describe_exit("qmarc-controller", controller);
    let motors = match hwserver {
        Some(Exit::Code(3)) => format!(
            "the hwserver's watchdog disabled the motors after {} periods without a request",
            s.hwserver.watchdog_periods
        ),
        Some(Exit::Code(0)) => "the hwserver disabled the motors as it stopped".to_string(),
        Some(e) => format!("{}: the motors' state is unknown", describe_exit("qmarc-hwserver", e)),
        None => "the hwserver did not end".to_string(),
    };
    format!("{how}; {motors}")
}

fn write_summary(path: &std::path::Path, s: &Summary) -> std::io::Result<()> {
    let text = serde_json::to_string_pretty(s).map_err(std::io::Error::other)?;
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    std::fs::write(path, text + "\n")
}

fn main() -> ExitCode {
    let args = StarterArgs::parse();
    match run(&args) {
        Ok(code) => code,
        Err(e) => {
            say!("qmarc-starter: error: {e:#}");
            ExitCode::from(1)
        }
    }
}
