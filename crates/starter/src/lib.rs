//! The QMARC starter (thesis 3.5): checks the settings, spawns `qmarc-hwserver` and
//! `qmarc-controller` for one move, supervises them, relays how they ended and prints the
//! summary.
//!
//! The children inherit the terminal, so their own messages (prefixed with their names)
//! reach the user directly; [`supervise`] adds how each one ended. Both children get
//! `PR_SET_PDEATHSIG = SIGTERM`, so they stop (motors disabled) if the starter dies.
//!
//! ```
//! use qmarc_starter::{Exit, describe_exit};
//! assert_eq!(describe_exit("qmarc-hwserver", Exit::Signal(9)), "qmarc-hwserver was killed by SIGKILL");
//! ```
#![deny(missing_docs)]

pub mod supervise;
pub mod table;

pub use supervise::{Exit, describe_exit};

use qmarc_controller::config::Settings;
use qmarc_hwserver::args::HwServerArgs;
use qmarc_proto::service::IpcLocation;

/// Prefix of the starter's default iceoryx2 prefixes (`qmarc_<pid>_`).
pub const PREFIX_STEM: &str = "qmarc_";

/// The default iceoryx2 prefix of this starter: unique per run, so runs never meet and
/// leftovers can be traced to a dead starter.
pub fn default_prefix() -> String {
    format!("{PREFIX_STEM}{}_", std::process::id())
}

/// The hwserver's command line for `settings`.
pub fn hwserver_args(
    settings: &Settings,
    deterministic: bool,
    location: &IpcLocation,
) -> HwServerArgs {
    let sim = &settings.sim;
    HwServerArgs {
        iox_prefix: location.prefix.clone(),
        iox_root: location.root.clone(),
        motors: settings.n_motors,
        period_us: u64::from(settings.period_us),
        deterministic,
        watchdog_periods: settings.hwserver.watchdog_periods,
        max_counts_per_s: settings.hwserver.max_counts_per_s,
        priority: settings.timer.hwserver_priority,
        no_mlock: !settings.timer.lock_memory,
        sim_kv: sim.kv,
        sim_tau_s: sim.tau_s,
        sim_coast_tau_s: sim.coast_tau_s,
        sim_start: sim.start_counts.iter().copied().take(settings.n_motors).collect(),
        sim_top_switch: sim.top_switch_counts,
        sim_bottom_switch: sim.bottom_switch_counts,
        sim_unhomed: !sim.homed,
        sim_counter_offset: sim.counter_offset,
        sim_stall: sim.stall_motor,
        sim_stuck_top: sim.stuck_top_motor,
        sim_events: sim.events_file.clone(),
        sim_state: sim.state_file.clone(),
        ..HwServerArgs::default()
    }
}

/// True if a process whose command line mentions `needle` is running (the children of a
/// starter carry its prefix in their arguments).
fn any_process_mentions(needle: &str) -> bool {
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return false;
    };
    entries.flatten().any(|e| {
        e.file_name().to_str().is_some_and(|n| n.bytes().all(|b| b.is_ascii_digit()))
            && std::fs::read(e.path().join("cmdline"))
                .is_ok_and(|c| c.windows(needle.len()).any(|w| w == needle.as_bytes()))
    })
}

/// Removes what earlier starters under `root` left when they died without cleaning up: their
/// prefix `qmarc_<pid>_` names a starter that no longer exists *and* no process (an orphaned
/// child still shutting down) uses it. iceoryx2 first removes the resources of the prefix's
/// dead nodes itself (`Node::list`, `try_remove_stale_resources`); then every file left with
/// the prefix goes (its global management segment among them). Returns how many files were
/// removed.
pub fn remove_stale_files(root: &str) -> usize {
    let Ok(entries) = std::fs::read_dir(qmarc_proto::service::SHM_DIR) else {
        return 0;
    };
    let mut stale: Vec<String> = entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let pid: u32 = name.strip_prefix(PREFIX_STEM)?.split('_').next()?.parse().ok()?;
            Some((pid, format!("{PREFIX_STEM}{pid}_")))
        })
        .filter(|(pid, prefix)| {
            !std::path::Path::new(&format!("/proc/{pid}")).exists() && !any_process_mentions(prefix)
        })
        .map(|(_, prefix)| prefix)
        .collect();
    stale.sort();
    stale.dedup();
    stale
        .iter()
        .map(|p| {
            let location = IpcLocation::new(p, root);
            remove_dead_nodes(&location);
            location.remove_files()
        })
        .sum()
}

/// Lets iceoryx2 remove the resources of every dead node at `location`.
fn remove_dead_nodes(location: &IpcLocation) {
    use iceoryx2::node::NodeView;
    use iceoryx2::prelude::*;
    let Ok(cfg) = location.config() else { return };
    let _ = Node::<ipc::Service>::list(&cfg, |state| {
        // Without its details iceoryx2 would clean up with its global configuration (which
        // reads ./config/iceoryx2.toml): the files of such a node go by prefix below.
        if let NodeState::Dead(view) = state
            && view.details().is_some()
        {
            let _ = view.try_remove_stale_resources();
        }
        CallbackProgression::Continue
    });
}

/// Checks the iceoryx2 root before a run. `explicit`: the user named it (`--iox-root`), and
/// then it must exist — a mistyped folder is refused rather than created. The default
/// (`/tmp/iceoryx2/`) may be missing; iceoryx2 creates it. Where it exists, it and its
/// `services` and `nodes` folders must be writable: after a run as root they belong to root,
/// and iceoryx2 would fail with a bare `InternalError`.
pub fn check_iox_root(root: &str, explicit: bool) -> Result<(), String> {
    use nix::unistd::{AccessFlags, access};
    let dir = std::path::Path::new(root);
    if !dir.exists() {
        return if explicit {
            Err(format!(
                "--iox-root {root}: no such folder; create it first (mkdir -p {root}) or leave \
                 --iox-root out"
            ))
        } else {
            Ok(())
        };
    }
    if !dir.is_dir() {
        return Err(format!("iceoryx2 root {root} is not a folder"));
    }
    for d in [dir.to_path_buf(), dir.join("services"), dir.join("nodes")] {
        if d.exists() && access(&d, AccessFlags::W_OK | AccessFlags::X_OK).is_err() {
            use std::os::unix::fs::MetadataExt;
            let owner = std::fs::metadata(&d).map(|m| m.uid()).unwrap_or(0);
            return Err(format!(
                "iceoryx2 files are in the way: {} belongs to uid {owner} (a run by another \
                 user, or as root, made it) and you cannot write there. When no QMARC run is \
                 going: remove it (`sudo rm -rf {root}`), or give this run its own folder \
                 (`--iox-root DIR`)",
                d.display()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hwserver_gets_the_settings_plant_and_priorities() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
        let s = Settings::load(&path).unwrap();
        let a = hwserver_args(&s, true, &IpcLocation::new("p_", "/tmp/r"));
        assert_eq!((a.motors, a.period_us, a.priority, a.watchdog_periods), (3, 400, 85, 250));
        assert_eq!(a.iox_root, "/tmp/r/");
        assert!(a.deterministic);
        assert_eq!(a.sim_start, vec![0.0, 0.0, 0.0]);
        let p = a.sim_params().unwrap();
        assert_eq!((p.kv_counts_per_s_per_v, p.tau_s), (25_000.0, 0.004));
    }
}
