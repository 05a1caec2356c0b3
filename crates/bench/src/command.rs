//! `qmarc-bench command`: how soon a command changes what the loop commands. A serving
//! session (`qmarc-starter serve` on the simulated robot, real time) gets `--moves` moves, each
//! while the robot moves, through the command service; for each, on one clock
//! (`CLOCK_MONOTONIC`): sent by the client → read by the controller's command thread → taken
//! by the loop in the cycle whose command is the new profile's first. The goal: taken by the
//! first cycle the loop runs after the order was queued — the command changes within one
//! period, or at the first cycle after a host stall.

use crate::session::Session;
use crate::stats::percentiles_us;
use qmarc_session::client::CommandClient;
use qmarc_session::wire::{CommandKind, CommandRequest};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// Options of `command`.
#[derive(Debug, clap::Args)]
pub struct CommandArgs {
    /// Moves measured.
    #[arg(long, default_value_t = 200)]
    pub moves: u32,
    /// Settings file of the session.
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Directory holding qmarc-starter and its children (default: next to this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
}

/// Runs `command`.
pub fn run(a: &CommandArgs) -> anyhow::Result<()> {
    anyhow::ensure!(a.moves >= 1, "--moves must be ≥ 1");
    let session = Session::start(&a.config, a.bin_dir.as_deref(), "cmd")?;
    let measured = session.client().and_then(|client| measure(client, a.moves, &a.config));
    let ended = session.quit();
    let Measured { mut to_read, mut to_taken, cycles, period_ns } = measured?;
    ended?;
    let (read, taken) = (percentiles_us(&mut to_read), percentiles_us(&mut to_taken));
    let next = cycles.iter().filter(|&&c| c == 1).count();
    let later = cycles.iter().max().copied().unwrap_or(0);
    println!(
        "qmarc-bench command: {} moves sent while the robot moved, {} µs period",
        a.moves,
        period_ns / 1_000
    );
    println!("                               p50       p99       max");
    println!(
        "  sent → read (command thread)  {:>6.0} µs {:>6.0} µs {:>6.0} µs",
        read.p50, read.p99, read.max
    );
    println!(
        "  read → taken by the loop      {:>6.0} µs {:>6.0} µs {:>6.0} µs",
        taken.p50, taken.p99, taken.max
    );
    println!(
        "  taken by the first cycle after it was queued: {next} of {} ({:.1} %); the latest by \
         cycle +{later}",
        cycles.len(),
        100.0 * next as f64 / cycles.len() as f64
    );
    Ok(())
}

/// What the moves measured.
struct Measured {
    /// Sent → read by the command thread, ns.
    to_read: Vec<u64>,
    /// Read → taken by the loop, ns.
    to_taken: Vec<u64>,
    /// The loop's cycles from queued to taken (1: the first cycle after).
    cycles: Vec<u64>,
    /// The servo period, ns.
    period_ns: u64,
}

/// Sends the moves and measures each.
fn measure(
    mut client: CommandClient,
    moves: u32,
    config: &std::path::Path,
) -> anyhow::Result<Measured> {
    let settings = qmarc_config::Settings::load(config, &qmarc_plugins::registry::names())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let period_ns = settings.period_ns();
    let started = Instant::now();
    let (mut to_read, mut to_taken, mut cycles) = (Vec::new(), Vec::new(), Vec::new());
    for k in 0..moves {
        // Back and forth between two points: every move arrives while the last one runs.
        let c = if k % 2 == 0 { 2_000.0 } else { -2_000.0 };
        let sent = qmarc_timer::clock::monotonic_now_ns();
        let r = client.send(CommandRequest::move_to(&[c, -c, c / 2.0], 1.0))?;
        anyhow::ensure!(r.answer.ok == 1, "move refused: {}", r.reason());
        let id = r.orders.accepted;
        let (taken_ns, taken_cycle) = loop {
            let s = client.send(CommandRequest::of(CommandKind::Status))?;
            if s.orders.taken >= id {
                break (s.timing.taken_ns, s.timing.taken_cycle);
            }
            anyhow::ensure!(started.elapsed() < Duration::from_secs(600), "the loop took nothing");
        };
        to_read.push(r.timing.received_ns.saturating_sub(sent));
        to_taken.push(taken_ns.saturating_sub(r.timing.received_ns));
        cycles.push(taken_cycle.saturating_sub(r.timing.received_cycle));
        std::thread::sleep(Duration::from_millis(15));
    }
    Ok(Measured { to_read, to_taken, cycles, period_ns })
}
