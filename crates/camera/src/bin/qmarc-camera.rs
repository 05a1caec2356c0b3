//! `qmarc-camera`: the camera server process, started by `qmarc-starter conveyor` beside the
//! hwserver with the run it prepared (`--settings FILE`, a [`qmarc_config::RunSpec`]); by
//! hand with a file from `qmarc-starter --print-settings … conveyor`.
//!
//! It publishes every frame's detections on the run's `qmarc/camera` service until a stop
//! signal (or its starter's death) and then says what it saw. Exit codes
//! ([`qmarc_proto::exit`]): 0 when stopped, 3 when its camera cannot be used, 64 for a bad
//! command line or run file, 1 on any other error.
//!
//! Its commands for the user (issue 46, docs/vision.md): `calibrate` (a frame of a dot target
//! on the belt → the calibration file), `detect` (the parts in one frame, as CSV), `draw`
//! (what the simulated camera sees: its target, or parts on the belt).

use clap::{Parser, Subcommand};
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
    about = "QMARC camera server (started by qmarc-starter conveyor; by hand: qmarc-starter --print-settings … conveyor > run.json), and its calibration and detection commands",
    args_conflicts_with_subcommands = true
)]
struct CameraArgs {
    /// The run: settings, mode, iceoryx2 location, world epoch (JSON, as `qmarc-starter
    /// --print-settings` writes it).
    #[arg(long, required = true)]
    settings: Option<PathBuf>,
    #[command(subcommand)]
    tool: Option<Tool>,
}

/// The user's commands.
#[derive(Debug, Subcommand)]
enum Tool {
    /// Fit the pixel-to-belt calibration to a frame of a dot target lying on the belt; print
    /// the reprojection error; write the file `[camera] calibration` reads
    Calibrate {
        /// The frame (PNG)
        #[arg(long)]
        image: PathBuf,
        /// The target's dots: columns (along the belt's travel) x rows (across), e.g. 9x7
        #[arg(long, value_parser = qmarc_camera::tools::parse_grid)]
        grid: [u32; 2],
        /// Between two dots' centres, mm
        #[arg(long, value_parser = positive_mm)]
        pitch_mm: f64,
        /// The origin dot's (the larger one's) belt coordinates X,Y mm
        #[arg(long, value_parser = qmarc_camera::tools::parse_point, default_value = "0,0", allow_hyphen_values = true)]
        origin_mm: [f64; 2],
        /// The calibration file to write
        #[arg(long)]
        out: PathBuf,
    },
    /// Print the parts found in a frame, one CSV line each: belt_mm,across_mm,angle_deg,area_px
    Detect {
        /// Settings file: its [camera] (calibration, polarity, threshold, area_px, intrinsics)
        #[arg(long)]
        config: PathBuf,
        /// The frame (PNG)
        #[arg(long)]
        image: PathBuf,
    },
    /// Draw what the simulated camera of --config sees to a PNG: the dot target it calibrates
    /// itself with (printing the calibrate command for it), or the belt with --part's
    Draw {
        /// Settings file: its [camera]
        #[arg(long)]
        config: PathBuf,
        /// The PNG to write
        #[arg(long)]
        out: PathBuf,
        /// A part on the belt: ALONG,ACROSS,ANGLE_DEG (mm, mm, degrees); repeat for more
        #[arg(long = "part", value_parser = part, allow_hyphen_values = true)]
        parts: Vec<[f64; 3]>,
    },
}

fn positive_mm(s: &str) -> Result<f64, String> {
    match s.parse::<f64>() {
        Ok(v) if v.is_finite() && v > 0.0 => Ok(v),
        _ => Err(format!("a length > 0 mm, found `{s}`")),
    }
}

fn part(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s.split(',').filter_map(|x| x.trim().parse().ok()).collect();
    match v[..] {
        [a, c, d] if v.iter().all(|x| x.is_finite()) => Ok([a, c, d]),
        _ => Err(format!("ALONG,ACROSS,ANGLE_DEG (three numbers), found `{s}`")),
    }
}

/// A user's command; its exit code.
fn tool(t: &Tool) -> Result<ExitCode, Failed> {
    use qmarc_camera::tools;
    let failed = |e: String| (exit::REFUSED, e);
    match t {
        Tool::Calibrate { image, grid, pitch_mm, origin_mm, out } => {
            let said =
                tools::calibrate(image, *grid, *pitch_mm, *origin_mm, out).map_err(failed)?;
            println!("{said}");
        }
        Tool::Detect { config, image } => {
            let s = tools::settings(config).map_err(|e| (exit::USAGE, e))?;
            let (csv, said) = tools::detect(&s, image).map_err(failed)?;
            print!("{csv}");
            eprintln!("qmarc-camera: {said}");
        }
        Tool::Draw { config, out, parts } => {
            let s = tools::settings(config).map_err(|e| (exit::USAGE, e))?;
            println!("{}", tools::draw(&s, out, parts).map_err(failed)?);
        }
    }
    Ok(ExitCode::SUCCESS)
}

/// Errors with their exit codes.
type Failed = (u8, String);

fn run(args: &CameraArgs) -> Result<ExitCode, Failed> {
    let settings = match (&args.tool, &args.settings) {
        (Some(t), _) => return tool(t),
        (None, Some(s)) => s,
        (None, None) => return Err((exit::USAGE, "--settings FILE, or a command".into())),
    };
    let spec = RunSpec::read(settings).map_err(|e| (exit::USAGE, e.to_string()))?;
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
