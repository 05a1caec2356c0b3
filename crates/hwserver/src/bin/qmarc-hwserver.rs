//! `qmarc-hwserver`: the hardware server process, started by `qmarc-starter` with the run it
//! prepared (`--settings FILE`, a [`qmarc_config::RunSpec`]); run by hand for debugging with a
//! file from `qmarc-starter --print-settings`.
//!
//! `--selftest` (with `--backend s626 --device PATH`) checks a Sensoray 626 and times its
//! instruction lists instead, enabling nothing.
//!
//! Exit codes ([`qmarc_proto::exit`]): 0 after an exit message or a stop signal (motors
//! disabled), 2 (fault) when the watchdog fired (controller silent with motors enabled), 3
//! when the hardware cannot be used, 64 for a bad command line or run file, 1 on any other
//! error.

use anyhow::Context;
use clap::Parser;
use qmarc_config::RunSpec;
use qmarc_hwserver::HwCore;
use qmarc_hwserver::server::{AnswerEnd, AnswerOptions, answer_requests};
use qmarc_proto::exit;
use qmarc_proto::service::IpcLocation;
use qmarc_timer::rt::{RtRequest, apply_to_current_thread};
use std::path::PathBuf;
use std::process::ExitCode;

/// Command line of `qmarc-hwserver`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc-hwserver",
    version,
    about = "QMARC hardware server (started by qmarc-starter; by hand: qmarc-starter --print-settings … > run.json)"
)]
struct HwServerArgs {
    /// The run: settings, mode, iceoryx2 location (JSON, as `qmarc-starter --print-settings`
    /// writes it).
    #[arg(long, required_unless_present = "selftest")]
    settings: Option<PathBuf>,
    /// Busy-poll for requests instead of blocking (only on an isolated core).
    #[arg(long)]
    spin: bool,
    /// Check the card and time its instruction lists, enabling nothing: run it first on a
    /// new PC (`--backend s626 --device /dev/comedi0 --selftest`).
    #[arg(long, conflicts_with = "settings")]
    selftest: bool,
    /// Settings file (with --selftest).
    #[arg(long, default_value = "config/qmarc.toml", requires = "selftest")]
    config: PathBuf,
    /// Hardware backend (with --selftest; default: `hwserver.backend`).
    #[arg(long, requires = "selftest")]
    backend: Option<String>,
    /// The Sensoray 626's comedi device (with --selftest; default: `s626.device`).
    #[arg(long, requires = "selftest")]
    device: Option<PathBuf>,
    /// Instruction lists of each kind to time (with --selftest).
    #[arg(long, default_value_t = 10_000, value_parser = clap::value_parser!(u32).range(1..=10_000_000))]
    count: u32,
}

/// `--selftest`: the settings file with the flags, then the card's check and timing.
fn selftest(args: &HwServerArgs) -> Result<ExitCode, (u8, anyhow::Error)> {
    let names = qmarc_config::Names::any();
    let refused = |e: anyhow::Error| (exit::REFUSED, e);
    let mut s =
        qmarc_config::Settings::load(&args.config, &names).map_err(|e| refused(e.into()))?;
    if let Some(b) = &args.backend {
        s.set_backend(b).map_err(|e| refused(e.into()))?;
    }
    // The selftest moves nothing: the settings' counts (4× in config/qmarc.toml) do not
    // matter to it, only the card and its wiring.
    if let Some(d) = &args.device {
        s.set_device(d).map_err(|e| refused(e.into()))?;
    }
    let report = qmarc_hwserver::selftest::run(&s, args.count).map_err(|e| refused(e.into()))?;
    print!("{report}");
    Ok(ExitCode::SUCCESS)
}

fn run(args: &HwServerArgs) -> Result<ExitCode, (u8, anyhow::Error)> {
    let Some(settings) = &args.settings else { return selftest(args) };
    let spec = RunSpec::read(settings).map_err(|e| (exit::USAGE, e.into()))?;
    let s = &spec.settings;
    let internal = |e: anyhow::Error| (exit::INTERNAL, e);
    let mut backend = qmarc_hwserver::backends::open(s, spec.deterministic)
        .map_err(|e| (exit::REFUSED, e.into()))?;
    if spec.epoch_ns != 0 {
        backend.set_epoch(spec.epoch_ns);
    }
    let location = IpcLocation::checked(&spec.iox_prefix, &spec.iox_root)
        .map_err(|e| (exit::USAGE, anyhow::Error::msg(e)))?;
    let stop =
        qmarc_timer::stop::install().context("cannot install signal handlers").map_err(internal)?;
    let priority = s.timer.hwserver_priority;
    let rt = apply_to_current_thread(&RtRequest {
        priority: (priority > 0).then_some(priority),
        lock_memory: s.timer.lock_memory,
        prefault_stack_bytes: 64 * 1024,
        cpu: s.timer.hwserver_cpu,
    });
    for w in &rt.warnings {
        eprintln!("qmarc-hwserver: warning: {w}");
    }
    let mut core = HwCore::for_settings(backend, s);
    let opts = AnswerOptions {
        watchdog_ns: u64::from(s.hwserver.watchdog_periods) * s.period_ns(),
        spin: args.spin || s.hwserver.wait == qmarc_config::HwWait::Spin,
        shutdown_grace_ns: 1_000_000_000,
        lockstep: spec.deterministic,
    };
    if opts.spin
        && rt.fifo_priority.is_some()
        && let Some((runtime, period)) = qmarc_timer::rt::rt_throttling()
    {
        eprintln!(
            "qmarc-hwserver: warning: spinning at SCHED_FIFO under RT throttling \
             (kernel.sched_rt_runtime_us = {runtime} of {period}): the kernel stops this process \
             for {} ms of every {} ms and the servo loop misses its periods then; on the \
             hwserver's own isolated core, `sysctl kernel.sched_rt_runtime_us=-1`",
            (period - runtime) / 1000,
            period / 1000
        );
    }
    let end = answer_requests(&mut core, &location, &opts, stop);
    core.finish().context("the backend's files").map_err(internal)?;
    let end = match end {
        Err(_) if qmarc_timer::stop::count() > 0 => return Ok(stopped_as_it_started()),
        end => end.map_err(|e| internal(e.into()))?,
    };
    Ok(match end {
        AnswerEnd::Exit => ExitCode::SUCCESS,
        AnswerEnd::Stopped => {
            let sig =
                qmarc_timer::stop::signal().map_or("a stop signal", qmarc_timer::stop::signal_name);
            eprintln!("qmarc-hwserver: stopped by {sig}: all motors disabled");
            ExitCode::SUCCESS
        }
        AnswerEnd::Watchdog { silent_ns, controller_alive } => {
            eprintln!(
                "qmarc-hwserver: watchdog: controller silent for {:.3} ms (limit {} periods of {} µs; \
                 its process {}) with motors enabled: all DACs zeroed, all motors disabled{}",
                silent_ns as f64 / 1e6,
                s.hwserver.watchdog_periods,
                s.period_us,
                if controller_alive { "still runs" } else { "is gone" },
                if controller_alive {
                    " (without PREEMPT_RT, host stalls of a few ms can do that: raise \
                     hwserver.watchdog_periods)"
                } else {
                    ""
                },
            );
            ExitCode::from(exit::FAULT)
        }
    })
}

/// A stop signal while iceoryx2 was setting up (a Ctrl-C in the first milliseconds)
/// interrupts its calls: that is the user's stop, not a failure.
fn stopped_as_it_started() -> ExitCode {
    let sig = qmarc_timer::stop::signal().map_or("a stop signal", qmarc_timer::stop::signal_name);
    eprintln!("qmarc-hwserver: stopped by {sig} as it started: all motors disabled");
    ExitCode::from(exit::INTERRUPTED)
}

fn main() -> ExitCode {
    let args: HwServerArgs = qmarc_program::cli::parse_or_exit();
    qmarc_program::cli::conclude("qmarc-hwserver", run(&args))
}
