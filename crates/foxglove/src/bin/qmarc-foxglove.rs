//! `qmarc-foxglove`: the robot as Foxglove sees it, from the command line.
//!
//! - `qmarc-foxglove scene OUT/gather.mcap [--at S] [--png FILE]`: the Deltabot (and the belt
//!   with its parts) as the file's scene had it S seconds in, drawn to a PNG (side and top
//!   views), for a report or a machine without Foxglove.

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

fn main() -> ExitCode {
    let args: Args = qmarc_program::cli::parse_or_exit();
    let result = match args.command {
        Command::Scene { mcap, at, png } => scene(&mcap, at, png),
    };
    let outcome = result.map(|()| ExitCode::SUCCESS).map_err(|e| (qmarc_proto::exit::REFUSED, e));
    qmarc_program::cli::conclude("qmarc-foxglove", outcome)
}
