//! `qmarc-controller`: the controller process, started by `qmarc-starter`.
//!
//! Exit codes: the table of [`qmarc_proto::exit`] — 0 the move ran to its end, 2 a fault ended
//! it (the summary says which), 3 refused before anything moved, 130 a stop signal, 64 a bad
//! command line, 1 anything else.

use clap::Parser;
use qmarc_controller::cli::{Mode, MoveOptions};
use qmarc_controller::run::{RunOptions, run_move};
use qmarc_proto::exit;
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

fn run(args: &ControllerArgs) -> Result<ExitCode, (u8, anyhow::Error)> {
    let refused = |e: qmarc_controller::config::ConfigLoadError| (exit::REFUSED, e.into());
    let mut settings = args.opts.load().map_err(refused)?;
    args.mode.apply(&mut settings).map_err(refused)?;
    qmarc_timer::stop::install().map_err(|e| (exit::INTERNAL, e.into()))?;
    let opts = RunOptions {
        location: IpcLocation::checked(&args.iox_prefix, &args.iox_root)
            .map_err(|e| (exit::REFUSED, anyhow::Error::msg(e)))?,
        deterministic: args.opts.deterministic,
        connect_wait: Duration::from_millis(args.connect_wait_ms),
        unhomed: args.opts.unhomed,
    };
    let summary = run_move(&settings, &args.mode, &opts).map_err(|e| (e.exit_code(), e.into()))?;
    for w in &summary.warnings {
        eprintln!("qmarc-controller: warning: {w}");
    }
    Ok(ExitCode::from(match &summary.fault {
        None => exit::OK,
        Some(f) => {
            eprintln!("qmarc-controller: fault ({}): {}", f.kind, f.message);
            if f.kind == "aborted" { exit::INTERRUPTED } else { exit::FAULT }
        }
    }))
}

fn main() -> ExitCode {
    let args: ControllerArgs = qmarc_controller::cli::parse_or_exit();
    match run(&args) {
        Ok(code) => code,
        Err((code, e)) => {
            eprintln!("qmarc-controller: error: {e:#}");
            ExitCode::from(code)
        }
    }
}
