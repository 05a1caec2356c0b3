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

pub mod cli;
mod companion;
pub mod ending;
mod lost;
pub mod moves;
pub mod path;
mod status;
pub mod supervise;
pub mod trials;
pub mod tune;

pub use supervise::{Exit, describe_exit};

pub use qmarc_session::discovery::{
    PREFIX_STEM, default_prefix, remove_own_stale_files, remove_stale_files,
};

pub use qmarc_proto::service::run_file;

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

    /// Issue 11: the settings crate gets its names from the registries, not the other way.
    #[test]
    fn the_names_come_from_the_registries() {
        let n = qmarc_plugins::registry::names();
        assert_eq!(n.laws, ["pidff"]);
        assert_eq!(n.methods, ["step", "spline", "pvt", "pick"]);
        let backends: Vec<&str> =
            qmarc_hwserver::backends::BACKENDS.iter().map(|b| b.kind.name()).collect();
        assert_eq!(backends, ["sim", "s626"], "one registry entry per BackendKind, in its order");
        assert_eq!(backends, qmarc_config::BackendKind::NAMES);
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
        assert!(qmarc_config::Settings::load(&path, &n).is_ok());
    }
}
