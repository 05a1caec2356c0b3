//! `qmarc-camera`: the camera server process, started by `qmarc-starter conveyor` beside the
//! hwserver with the run it prepared (`--settings FILE`, a [`qmarc_config::RunSpec`]); by
//! hand with a file from `qmarc-starter --print-settings … conveyor`.
//!
//! It publishes every frame's detections on the run's `qmarc/camera` service until a stop
//! signal (or its starter's death) and then says what it saw. Exit codes
//! ([`qmarc_proto::exit`]): 0 when stopped, 3 when its camera cannot be used, 64 for a bad
//! command line or run file, 1 on any other error.

use clap::Parser;
use qmarc_config::RunSpec;
use qmarc_proto::camera::{PartDetection, open_camera_service};
use qmarc_proto::exit;
use qmarc_proto::service::{IpcLocation, create_node};
use std::path::PathBuf;
use std::process::ExitCode;

/// Command line of `qmarc-camera`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc-camera",
    version,
    about = "QMARC camera server (started by qmarc-starter conveyor; by hand: qmarc-starter --print-settings … conveyor > run.json)"
)]
struct CameraArgs {
    /// The run: settings, mode, iceoryx2 location, world epoch (JSON, as `qmarc-starter
    /// --print-settings` writes it).
    #[arg(long)]
    settings: PathBuf,
}

/// Errors with their exit codes.
type Failed = (u8, String);

fn run(args: &CameraArgs) -> Result<ExitCode, Failed> {
    let spec = RunSpec::read(&args.settings).map_err(|e| (exit::USAGE, e.to_string()))?;
    let location = IpcLocation::checked(&spec.iox_prefix, &spec.iox_root)
        .map_err(|e| (exit::USAGE, e.to_string()))?;
    let stop = qmarc_timer::stop::install()
        .map_err(|e| (exit::INTERNAL, format!("cannot install signal handlers: {e}")))?;
    let mut camera = qmarc_camera::open(&spec).map_err(|e| (exit::REFUSED, e.to_string()))?;
    let internal = |e: qmarc_proto::service::ServiceError| (exit::INTERNAL, e.to_string());
    let node = create_node::<iceoryx2::prelude::ipc::Service>("qmarc-camera", &location)
        .map_err(internal)?;
    let service = open_camera_service(&node).map_err(internal)?;
    let publisher = service
        .publisher_builder()
        .create()
        .map_err(|e| (exit::INTERNAL, format!("the camera's publisher on qmarc/camera: {e:?}")))?;
    let (mut frames, mut parts, mut unsent) = (0u64, 0u64, 0u64);
    let mut found: Vec<PartDetection> = Vec::new();
    loop {
        match camera.next_frame(&mut found, stop) {
            Ok(Some(_)) => frames += 1,
            Ok(None) => break,
            Err(e) => {
                eprintln!("qmarc-camera: {e}; {frames} frames, {parts} detections sent");
                return Err((exit::INTERNAL, e.to_string()));
            }
        }
        for d in &found {
            match publisher.send_copy(*d) {
                Ok(_) => parts += 1,
                Err(_) => unsent += 1,
            }
        }
    }
    let lost = if unsent > 0 { format!(", {unsent} could not be sent") } else { String::new() };
    eprintln!(
        "qmarc-camera: stopped: {frames} frames, {parts} detections sent{lost} ({} camera)",
        camera.name()
    );
    Ok(ExitCode::SUCCESS)
}

fn main() -> ExitCode {
    let args: CameraArgs = qmarc_program::cli::parse_or_exit();
    qmarc_program::cli::conclude("qmarc-camera", run(&args))
}
