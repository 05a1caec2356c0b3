//! `qmarc-bench`: proves with one command how close the controller comes to this machine's
//! limit (`../shared/notes/realtime-linux.md`, "Benchmark"):
//!
//! - `jitter`: interleaved rounds of a bare timer loop (the controller's own timer code,
//!   cyclictest's algorithm, nothing else) and the full servo pipeline (three real processes
//!   over real iceoryx2, through `qmarc-starter step`); the servo's wake-latency p99 over the
//!   bare loop's, per round, with the noisy-host flag.
//! - `ipc`: the controller ⇄ hwserver exchange beside a raw futex and a raw spin ping-pong.
//! - `cycle`: the per-cycle compute of every registered generator × law for 1–4 motors.
//! - `command`: a serving session's move commands, from sent to the loop's first new command.
//! - `pick`: the Delta pick-and-place cycle through a serving session, with the gripper.
//! - `conveyor`: conveyor tracking — picks a minute, missed parts, the grip error, what
//!   limits the rate, how far it goes, at 1 m/s, and the intercept's cost in the cycle.
//! - `bridge`: the ROS 2 bridge — the loop's p99 with it and two subscribers against without,
//!   joint states over 60 s (loss, latency from the servo sample), a target to the loop.
//! - `files`: a move's files written with `gather.mcap` off and on (the time ratio, sizes).
//! - `cell`: a cell of two robots on one belt over Zenoh — the share, one robot killed, the
//!   claim latency with the second robot on another host (a network namespace).
//! - `foxglove`: the live view — the loop's p99 with it and two viewers against without, what
//!   a viewer receives.
//!
//! Figures are printed (and written as JSON with `--json`), never asserted: the machine decides.

mod baselines;
mod bridge;
mod cell;
mod command;
mod conveyor;
mod cycle;
mod files;
mod foxglove;
mod ipc;
mod jitter;
mod pick;
mod session;
mod stats;
mod vision;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Command line of `qmarc-bench`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc-bench",
    version,
    about = "Benchmarks of the QMARC servo loop against this machine's limit"
)]
struct Args {
    #[command(subcommand)]
    command: BenchCommand,
}

#[derive(Debug, Subcommand)]
enum BenchCommand {
    /// Interleaved rounds of the bare timer loop and the servo pipeline: wake latency, period
    /// error, missed periods, periods off by more than 40 µs, output latency; the p99 ratio.
    Jitter(jitter::JitterArgs),
    /// Round trips of the controller ⇄ hwserver exchange beside raw futex and spin ping-pongs.
    Ipc(ipc::IpcArgs),
    /// Per-cycle compute (trajectory sample + law step) of every generator × law, 1–4 motors.
    Cycle(cycle::CycleArgs),
    /// A serving session: from a move command sent to the loop's first command of it.
    Command(command::CommandArgs),
    /// The Delta pick-and-place cycle through a serving session: cycle time, picks per
    /// minute, tracking error, beside the thesis' X-Z path.
    Pick(pick::PickArgs),
    /// Conveyor tracking through real `qmarc-starter conveyor` sessions: picks a minute,
    /// missed parts, the grip error, what limits the rate, the highest rate with none missed,
    /// 1 m/s; the intercept's computation in the servo cycle.
    Conveyor(conveyor::ConveyorArgs),
    /// A cell of two robots on one belt (real sessions, a Zenoh router, the cell's camera):
    /// picks a minute together, missed, picked twice, the split; one robot killed mid-run;
    /// the claim latency with the second robot on another host (a network namespace).
    Cell(cell::CellArgs),
    /// The ROS 2 bridge: the loop with it and two subscribers against without (p99 ratio),
    /// joint states' loss and latency, a published target to the loop's first command.
    Bridge(bridge::BridgeArgs),
    /// What gather.mcap costs: a move's files written with it off and on (the ratio).
    Files(files::FilesArgs),
    /// The live view: the loop with it and two viewers against without (p99 ratio), what a
    /// viewer receives.
    Foxglove(foxglove::FoxgloveArgs),
    /// The vision system: detection's time on 1280×1024 frames of 20 parts, its accuracy,
    /// the calibration's fit; a conveyor session whose camera finds the parts in frames.
    Vision(vision::VisionArgs),
}

fn main() -> ExitCode {
    let args: Args = qmarc_program::cli::parse_or_exit();
    let result = match &args.command {
        BenchCommand::Jitter(a) => jitter::run(a),
        BenchCommand::Ipc(a) => ipc::run(a),
        BenchCommand::Cycle(a) => cycle::run(a),
        BenchCommand::Command(a) => command::run(a),
        BenchCommand::Pick(a) => pick::run(a),
        BenchCommand::Conveyor(a) => conveyor::run(a),
        BenchCommand::Cell(a) => cell::run(a),
        BenchCommand::Bridge(a) => bridge::run(a),
        BenchCommand::Files(a) => files::run(a),
        BenchCommand::Foxglove(a) => foxglove::run(a),
        BenchCommand::Vision(a) => vision::run(a),
    };
    let outcome = result.map(|()| ExitCode::SUCCESS).map_err(|e| (qmarc_proto::exit::INTERNAL, e));
    qmarc_program::cli::conclude("qmarc-bench", outcome)
}
