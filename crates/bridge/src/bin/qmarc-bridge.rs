//! `qmarc-bridge [--iox-prefix P] [--iox-root R] [--namespace NS] [--domain N] [--rate HZ]
//! [--zenoh-config FILE]`: a serving QMARC as a ROS 2 node on Zenoh (`qmarc_bridge`). Without
//! `--iox-prefix` it serves your newest serving session (`qmarc-starter serve`).
//!
//! Exit codes: 0 the session ended (or a stop signal), 1 no serving session, the network or
//! the session failed, 3 refused (a ROS node of its name is already alive in its domain; or
//! several serving sessions and no `--iox-prefix`), 64 bad options.

use clap::Parser;
use qmarc_bridge::bridge::{Options, run};
use qmarc_bridge::convert::Converter;
use qmarc_bridge::node::NodeOpenError;
use qmarc_proto::service::run_file;
use std::path::PathBuf;
use std::process::ExitCode;

/// Command line of `qmarc-bridge`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc-bridge",
    version,
    about = "A serving QMARC as a ROS 2 participant over Zenoh (rmw_zenoh), beside the controller"
)]
struct Args {
    /// The serving session's iceoryx2 prefix (default: your newest serving run in /dev/shm).
    #[arg(long)]
    iox_prefix: Option<String>,
    /// The session's iceoryx2 root (default: the one its run file names).
    #[arg(long)]
    iox_root: Option<String>,
    /// The ROS namespace of the node and its topics: `/robot1` (default: none).
    #[arg(long, default_value = "")]
    namespace: String,
    /// The ROS domain id (as ROS_DOMAIN_ID).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u32).range(0..=232))]
    domain: u32,
    /// Joint states a second (and how often commands are read).
    #[arg(long, default_value_t = 250.0)]
    rate: f64,
    /// A Zenoh configuration file (JSON5) instead of rmw_zenoh's session defaults (a peer
    /// connecting to a router at tcp/localhost:7447).
    #[arg(long)]
    zenoh_config: Option<PathBuf>,
}

fn main() -> ExitCode {
    let args: Args = qmarc_program::cli::parse_or_exit();
    if let Err(e) = qmarc_program::cli::check_ros_namespace(&args.namespace) {
        eprintln!("qmarc-bridge: --namespace: {e}");
        return ExitCode::from(qmarc_proto::exit::USAGE);
    }
    if !(args.rate.is_finite() && (1.0..=2000.0).contains(&args.rate)) {
        eprintln!("qmarc-bridge: --rate: 1 to 2000 Hz, found {}", args.rate);
        return ExitCode::from(qmarc_proto::exit::USAGE);
    }
    let outcome = (|| {
        let stop = qmarc_timer::stop::install()?;
        let (location, spec, _) = qmarc_session::discovery::serving_session(
            args.iox_prefix.as_deref(),
            args.iox_root.as_deref(),
        )
        .map_err(anyhow::Error::from)?;
        let s = &spec.settings;
        let opts = Options {
            location,
            namespace: args.namespace.clone(),
            domain: args.domain,
            rate_hz: args.rate,
            zenoh_config: args.zenoh_config.clone(),
            converter: Converter {
                n_motors: s.n_motors,
                counts_per_rad: s.counts_per_rad(),
                robot: s.robot(),
            },
            hardware_id: s.hwserver.backend.to_string(),
        };
        let location = opts.location.clone();
        let served = run(opts, stop);
        // The session ended first: the files the bridge's node made under its prefix go
        // with the session's (its starter has removed the rest).
        if !run_file(&location.prefix).exists() {
            location.remove_files();
        }
        served?;
        anyhow::Ok(ExitCode::SUCCESS)
    })();
    qmarc_program::cli::conclude(
        "qmarc-bridge",
        outcome.map_err(|e| {
            // A node of its name already alive, or several sessions and none chosen: refused,
            // not failed.
            use qmarc_session::discovery::SessionFindError;
            let refused = matches!(e.downcast_ref(), Some(NodeOpenError::Alive { .. }))
                || matches!(e.downcast_ref(), Some(SessionFindError::Ambiguous(_)));
            (if refused { qmarc_proto::exit::REFUSED } else { qmarc_proto::exit::INTERNAL }, e)
        }),
    )
}
