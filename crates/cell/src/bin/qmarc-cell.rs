//! `qmarc-cell`: a cell of robots on one belt over Zenoh (issue 47, docs/cell.md).
//!
//! - `qmarc-cell camera --cell NAME [--config FILE] [--zenoh-config FILE]`: the cell's camera
//!   on the camera's PC: its parts numbered once and published to every robot.
//! - `qmarc-cell robot --settings RUN`: a robot's companion, started by `qmarc-starter
//!   conveyor --cell NAME` (not by hand): it joins the cell and relays between it and the
//!   conveyor session.
//!
//! Exit codes ([`qmarc_proto::exit`]): 0 when stopped (or `--seconds` ran out), 3 when the
//! cell refused the robot (or has a camera already), 64 for a bad command line, 1 on any
//! other error.

use clap::{Parser, Subcommand};
use qmarc_cell::camera::CameraNode;
use qmarc_config::{Names, RunSpec, Settings};
use qmarc_proto::exit;
use std::path::PathBuf;
use std::process::ExitCode;

/// Command line of `qmarc-cell`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc-cell",
    version,
    about = "A cell of QMARC robots on one belt over Zenoh: the cell's camera, and each robot's companion (docs/cell.md)"
)]
struct CellArgs {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// The cell's camera: runs the camera server of --config's [camera] and [conveyor],
    /// numbers its parts once for the cell and publishes them; answers the robots that join
    /// with the cell's belt
    Camera {
        /// The cell (letters, digits, - and _)
        #[arg(long)]
        cell: String,
        /// Settings file: its [conveyor] (the cell's belt) and [camera]
        #[arg(long, default_value = "config/qmarc.toml")]
        config: PathBuf,
        /// The Zenoh session's configuration (JSON5); default: rmw_zenoh's (a peer, a router
        /// at tcp/localhost:7447)
        #[arg(long)]
        zenoh_config: Option<PathBuf>,
        /// How long it runs, s (default: until Ctrl-C)
        #[arg(long, default_value_t = 0.0)]
        seconds: f64,
        /// The simulated camera's parts a minute (default `camera.parts_per_min`)
        #[arg(long)]
        parts_per_min: Option<f64>,
        /// The simulated belt's speed, mm/s (default `conveyor.speed_mm_s`)
        #[arg(long)]
        belt_mm_s: Option<f64>,
        /// iceoryx2 root directory of its camera server
        #[arg(long, default_value = "/tmp/iceoryx2/")]
        iox_root: String,
        /// Directory holding qmarc-camera (default: next to this program)
        #[arg(long)]
        bin_dir: Option<PathBuf>,
    },
    /// A Zenoh router for the cell's hosts (zenohd does the same): listens on --listen until
    /// Ctrl-C
    Router {
        /// Where it listens: ENDPOINT, e.g. tcp/0.0.0.0:7447 (repeat for more)
        #[arg(long, default_value = "tcp/127.0.0.1:7447")]
        listen: Vec<String>,
    },
    /// A robot's companion (started by qmarc-starter conveyor --cell): joins the cell and
    /// relays between it and the conveyor session
    Robot {
        /// The run (JSON, as qmarc-starter writes it)
        #[arg(long)]
        settings: PathBuf,
    },
}

fn run(args: CellArgs) -> Result<ExitCode, (u8, anyhow::Error)> {
    let internal = |e: anyhow::Error| (exit::INTERNAL, e);
    match args.command {
        Command::Camera {
            cell,
            config,
            zenoh_config,
            seconds,
            parts_per_min,
            belt_mm_s,
            iox_root,
            bin_dir,
        } => {
            let usage = |e: String| (exit::USAGE, anyhow::anyhow!(e));
            if let Some(why) = qmarc_config::cell_name_problem(&cell) {
                return Err(usage(format!("--cell: {why}")));
            }
            let mut settings =
                Settings::load(&config, &Names::any()).map_err(|e| (exit::USAGE, e.into()))?;
            if let Some(n) = parts_per_min {
                settings.set_parts_per_min(n).map_err(|e| (exit::USAGE, e.into()))?;
            }
            if let Some(v) = belt_mm_s {
                settings.set_belt_speed(v).map_err(|e| (exit::USAGE, e.into()))?;
            }
            let bin_dir = qmarc_program::process::bin_dir(bin_dir.as_deref())
                .map_err(|e| internal(e.into()))?;
            let node = CameraNode {
                cell: cell.clone(),
                settings,
                zenoh_config,
                iox_root,
                bin_dir,
                seconds,
            };
            let seen = node.run().map_err(|e| (qmarc_cell::exit_code(&e), e))?;
            println!(
                "qmarc-cell camera: cell {cell}: {} parts seen ({} detections)",
                seen.parts, seen.detections
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Router { listen } => {
            qmarc_cell::session::route(&listen).map_err(internal)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Robot { settings } => {
            let spec = RunSpec::read(&settings).map_err(|e| (exit::USAGE, e.into()))?;
            qmarc_cell::robot::run(&spec).map_err(|e| (qmarc_cell::exit_code(&e), e))?;
            Ok(ExitCode::SUCCESS)
        }
    }
}

fn main() -> ExitCode {
    let args: CellArgs = qmarc_program::cli::parse_or_exit();
    qmarc_program::cli::conclude("qmarc-cell", run(args))
}
