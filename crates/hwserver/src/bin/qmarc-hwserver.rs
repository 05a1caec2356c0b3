//! `qmarc-hwserver`: the hardware server process, started by `qmarc-starter`.
//!
//! Exit codes ([`qmarc_proto::exit`]): 0 after an exit message or a stop signal (motors
//! disabled), 2 (fault) when the watchdog fired (controller silent with motors enabled),
//! 64 for a bad command line, 1 on any other error.

use anyhow::Context;
use clap::Parser;
use qmarc_hwserver::args::{BackendKind, HwServerArgs};
use qmarc_hwserver::server::{ServeEnd, ServeOptions, serve};
use qmarc_hwserver::{Backend, HwCore, SimDeltabot};
use qmarc_proto::exit;
use qmarc_timer::rt::{RtRequest, apply_to_current_thread};
use std::process::ExitCode;

fn run(args: &HwServerArgs) -> anyhow::Result<ExitCode> {
    let backend: Box<dyn Backend> = match args.backend {
        BackendKind::Sim => {
            let sim = SimDeltabot::new(args.sim_params()?)?;
            Box::new(match &args.sim_state {
                Some(path) => sim.with_state_file(path),
                None => sim,
            })
        }
    };
    let stop = qmarc_timer::stop::install().context("cannot install signal handlers")?;
    let rt = apply_to_current_thread(&RtRequest {
        priority: (args.priority > 0).then_some(args.priority),
        lock_memory: !args.no_mlock,
        prefault_stack_bytes: 64 * 1024,
    });
    for w in &rt.warnings {
        eprintln!("qmarc-hwserver: warning: {w}");
    }
    if args.max_counts_per_s.is_nan() || args.max_counts_per_s <= 0.0 {
        anyhow::bail!("--max-counts-per-s must be > 0, found {}", args.max_counts_per_s);
    }
    let mut core = HwCore::new(backend).with_encoder_limit(args.max_counts_per_s);
    let opts = ServeOptions {
        watchdog_ns: u64::from(args.watchdog_periods) * args.period_ns(),
        spin: args.spin,
        shutdown_grace_ns: 1_000_000_000,
        lockstep: args.deterministic,
    };
    let location = args.location().map_err(anyhow::Error::msg)?;
    let end = serve(&mut core, &location, &opts, stop);
    if let Some(path) = &args.sim_events {
        let mut out = Vec::new();
        core.backend().write_log(&mut out)?;
        std::fs::write(path, out).with_context(|| format!("cannot write {}", path.display()))?;
    }
    let end = end?;
    Ok(match end {
        ServeEnd::Exit => ExitCode::SUCCESS,
        ServeEnd::Stopped => {
            let sig =
                qmarc_timer::stop::signal().map_or("a stop signal", qmarc_timer::stop::signal_name);
            eprintln!("qmarc-hwserver: stopped by {sig}: all motors disabled");
            ExitCode::SUCCESS
        }
        ServeEnd::Watchdog { silent_ns, controller_alive } => {
            eprintln!(
                "qmarc-hwserver: watchdog: controller silent for {:.3} ms (limit {} periods of {} µs; \
                 its process {}) with motors enabled: all DACs zeroed, all motors disabled{}",
                silent_ns as f64 / 1e6,
                args.watchdog_periods,
                args.period_us,
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

fn main() -> ExitCode {
    let args = match HwServerArgs::try_parse() {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { exit::USAGE } else { exit::OK });
        }
    };
    match run(&args) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("qmarc-hwserver: error: {e:#}");
            ExitCode::from(1)
        }
    }
}
