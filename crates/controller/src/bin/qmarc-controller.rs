//! `qmarc-controller`: the controller process, started by `qmarc-starter`.
//!
//! Exit codes: 0 when the move ran to its end, 2 when a fault ended it (the summary says
//! which), 1 when it could not run at all.

use clap::Parser;
use qmarc_controller::cli::{Mode, MoveOptions};
use qmarc_controller::run::{RunOptions, run_move};
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation};
use std::process::ExitCode;
use std::time::Duration;

/// Command line of `qmarc-controller`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc-controller",
    version,
    about = "QMARC controller (started by qmarc-starter)"
)]
struct ControllerArgs {
    #[command(flatten)]
    opts: MoveOptions,
    /// Prefix of the run's iceoryx2 files (the hwserver's).
    #[arg(long)]
    iox_prefix: String,
    /// iceoryx2 root directory.
    #[arg(long, default_value = DEFAULT_ROOT)]
    iox_root: String,
    /// How long to wait for the hwserver, ms.
    #[arg(long, default_value_t = 5_000)]
    connect_wait_ms: u64,
    #[command(subcommand)]
    mode: Mode,
}

fn run(args: &ControllerArgs) -> anyhow::Result<ExitCode> {
    let mut settings = args.opts.load()?;
    args.mode.apply(&mut settings)?;
    qmarc_timer::stop::install()?;
    let opts = RunOptions {
        location: IpcLocation::checked(&args.iox_prefix, &args.iox_root)
            .map_err(anyhow::Error::msg)?,
        deterministic: args.opts.deterministic,
        connect_wait: Duration::from_millis(args.connect_wait_ms),
        unhomed: args.opts.unhomed,
    };
    let summary = run_move(&settings, &args.mode, &opts)?;
    for w in &summary.warnings {
        eprintln!("qmarc-controller: warning: {w}");
    }
    Ok(match &summary.fault {
        None => ExitCode::SUCCESS,
        Some(f) => {
            eprintln!("qmarc-controller: fault ({}): {}", f.kind, f.message);
            ExitCode::from(2)
        }
    })
}

fn main() -> ExitCode {
    let args = ControllerArgs::parse();
    match run(&args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("qmarc-controller: error: {e:#}");
            ExitCode::from(1)
        }
    }
}
