//! `qmarc-foxglove`: the robot as Foxglove sees it, from the command line.
//!
//! - `qmarc-foxglove live [--iox-prefix P] [--iox-root R] [--addr HOST:PORT]`: a serving
//!   session's live view for Foxglove (the Foxglove WebSocket protocol, `foxglove.websocket.v1`)
//!   at 127.0.0.1:8765 by default; without `--iox-prefix`, your newest serving session.
//!   `qmarc-starter serve --foxglove [ADDR]` starts it beside the session.
//! - `qmarc-foxglove scene OUT/gather.mcap [--at S] [--png FILE]`: the Deltabot (and the belt
//!   with its parts) as the file's scene had it S seconds in, drawn to a PNG (side and top
//!   views), for a report or a machine without Foxglove.
//!
//! Exit codes: 0 done (the session ended, a stop signal), 1 failed (no serving session, the
//! server), 3 refused (the address taken, several sessions and none chosen, a file that is no
//! gather.mcap), 64 bad options.

use clap::{Parser, Subcommand};
use std::path::PathBuf;
use std::process::ExitCode;

/// Command line of `qmarc-foxglove`.
#[derive(Debug, Parser)]
#[command(name = "qmarc-foxglove", version, about = "The robot as Foxglove sees it")]
struct Args {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Serves a serving session's live view to Foxglove (`foxglove.websocket.v1`).
    Live {
        /// The serving session's iceoryx2 prefix (default: your newest serving run).
        #[arg(long)]
        iox_prefix: Option<String>,
        /// The session's iceoryx2 root (default: the one its run file names).
        #[arg(long)]
        iox_root: Option<String>,
        /// Where viewers connect, `host:port`.
        #[arg(long, default_value = qmarc_foxglove::live::DEFAULT_ADDR)]
        addr: String,
    },
    /// Draws a gather.mcap's scene at a time to a PNG (side and top views).
    Scene {
        /// The gather.mcap.
        mcap: PathBuf,
        /// Seconds from the file's first scene (past the end: the last).
        #[arg(long, default_value_t = 0.0)]
        at: f64,
        /// The PNG (default: scene.png beside the file).
        #[arg(long)]
        png: Option<PathBuf>,
    },
}

fn scene(mcap: &PathBuf, at: f64, png: Option<PathBuf>) -> anyhow::Result<()> {
    let bytes = std::fs::read(mcap).map_err(|e| anyhow::anyhow!("{}: {e}", mcap.display()))?;
    let scenes = qmarc_foxglove::read::scenes(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: not an MCAP file with a scene: {e}", mcap.display()))?;
    let Some((t, update)) = qmarc_foxglove::read::scene_at(&scenes, at) else {
        anyhow::bail!("{}: no /qmarc/scene message in it", mcap.display());
    };
    let png = png.unwrap_or_else(|| mcap.with_file_name("scene.png"));
    let t_s = (t - scenes[0].0) as f64 / 1e9;
    let title = format!("{} at {t_s:.3} s", mcap.display());
    qmarc_foxglove::render::png(update, &png, (640, 560), &title)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    println!("{}", png.display());
    Ok(())
}

/// Why the live view could not serve: refused (exit 3) or failed (1).
fn live(prefix: Option<&str>, root: Option<&str>, addr: &str) -> Result<(), (u8, anyhow::Error)> {
    use qmarc_proto::exit::{INTERNAL, REFUSED};
    let stop = qmarc_timer::stop::install().map_err(|e| (INTERNAL, e.into()))?;
    let (location, spec, _) =
        qmarc_session::discovery::serving_session(prefix, root).map_err(|e| {
            let refused = matches!(e, qmarc_session::discovery::SessionFindError::Ambiguous(_));
            (if refused { REFUSED } else { INTERNAL }, anyhow::Error::from(e))
        })?;
    let opts = qmarc_foxglove::live::LiveOptions { location, spec, addr: addr.to_string() };
    qmarc_foxglove::live::run(&opts, stop).map_err(|e| {
        let taken = e.downcast_ref::<qmarc_foxglove::live::AddressTaken>().is_some();
        (if taken { REFUSED } else { INTERNAL }, e)
    })
}

fn main() -> ExitCode {
    let args: Args = qmarc_program::cli::parse_or_exit();
    let outcome = match args.command {
        Command::Scene { mcap, at, png } => {
            scene(&mcap, at, png).map_err(|e| (qmarc_proto::exit::REFUSED, e))
        }
        Command::Live { iox_prefix, iox_root, addr } => {
            live(iox_prefix.as_deref(), iox_root.as_deref(), &addr)
        }
    };
    qmarc_program::cli::conclude("qmarc-foxglove", outcome.map(|()| ExitCode::SUCCESS))
}
