//! `qmarc-controller`: the controller process, started by `qmarc-starter` with the run it
//! prepared (`--settings FILE`, a [`qmarc_config::RunSpec`]); run by hand for debugging with a
//! file from `qmarc-starter --print-settings`.
//!
//! Exit codes: the table of [`qmarc_proto::exit`] — 0 the move ran to its end, 2 a fault ended
//! it (the summary says which), 3 refused before anything moved, 4 the move ran to its end
//! but its results are in the rescue folder, 130 a stop signal, 64 a bad command line, 1
//! anything else.

use clap::Parser;
use qmarc_config::RunSpec;
use qmarc_proto::exit;
use qmarc_proto::state::FaultKind;
use std::path::PathBuf;
use std::process::ExitCode;

/// Command line of `qmarc-controller`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc-controller",
    version,
    about = "QMARC controller (started by qmarc-starter; by hand: qmarc-starter --print-settings … > run.json)"
)]
struct ControllerArgs {
    /// The run: settings, mode, iceoryx2 location (JSON, as `qmarc-starter --print-settings`
    /// writes it).
    #[arg(long)]
    settings: PathBuf,
}

fn run(args: &ControllerArgs) -> Result<ExitCode, (u8, anyhow::Error)> {
    let spec = RunSpec::read(&args.settings).map_err(|e| (exit::USAGE, e.into()))?;
    qmarc_timer::stop::install().map_err(|e| (exit::INTERNAL, e.into()))?;
    let summary = match qmarc_controller_process::run::run_move(&spec) {
        // A stop signal before the move began: the user's stop, said as such, not an error.
        Err(e) if e.exit_code() == exit::INTERRUPTED => {
            eprintln!("qmarc-controller: {e}");
            return Ok(ExitCode::from(exit::INTERRUPTED));
        }
        moved => moved.map_err(|e| (e.exit_code(), anyhow::Error::from(e)))?,
    };
    for w in &summary.warnings {
        eprintln!("qmarc-controller: warning: {w}");
    }
    Ok(ExitCode::from(match &summary.fault {
        // A stop signal after the move (while its data were written): the user stopped it.
        None if qmarc_timer::stop::count() > 0 => exit::INTERRUPTED,
        // Its results are not in the output folder: the rescue folder holds them.
        None if !summary.files.iter().all(|f| f.starts_with(&spec.settings.gather.out_dir)) => {
            exit::RESCUED
        }
        None => exit::OK,
        // The fault is said once, by the summary (the starter's table, the console): not here
        // too.
        Some(f) if f.kind == FaultKind::Aborted => exit::INTERRUPTED,
        Some(_) => exit::FAULT,
    }))
}

fn main() -> ExitCode {
    let args: ControllerArgs = qmarc_program::cli::parse_or_exit();
    qmarc_program::cli::conclude("qmarc-controller", run(&args))
}
