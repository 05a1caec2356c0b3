//! The iceoryx2 services between controller and hwserver, opened identically by both sides.
//!
//! One request/response service carries [`HwMsg`] both ways. iceoryx2 0.10 request/response
//! ports only poll, so two event services make the exchange blocking: the client notifies
//! [`REQUEST_EVENT`] after sending, the server waits on it; the server notifies
//! [`RESPONSE_EVENT`] after answering, the client waits on it (see `../shared/notes/iceoryx2.md`).
//!
//! Every file iceoryx2 creates is named with the run's prefix and lives under its root, so
//! parallel runs never meet and a run's leftovers can be removed by prefix.

use crate::HwMsg;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::{event, request_response};

/// Name of the request/response service.
pub const HW_SERVICE: &str = "qmarc/hw";
/// Name of the event service the client notifies after each request.
pub const REQUEST_EVENT: &str = "qmarc/hw/request";
/// Name of the event service the server notifies after each response.
pub const RESPONSE_EVENT: &str = "qmarc/hw/response";
/// Node name of the hardware server.
pub const HWSERVER_NODE: &str = "qmarc-hwserver";
/// Node name of the controller.
pub const CONTROLLER_NODE: &str = "qmarc-controller";
/// Default iceoryx2 root directory (iceoryx2's own default).
pub const DEFAULT_ROOT: &str = "/tmp/iceoryx2/";

/// The service type of the link: iceoryx2's `ipc` with a futex wake-up ([`crate::wake`]).
pub use crate::wake::Link;

/// The request/response service.
pub type HwService = request_response::PortFactory<Link, HwMsg, (), HwMsg, ()>;
/// An event service.
pub type EventService = event::PortFactory<Link>;

/// The three services of one controller ⇄ hwserver link.
pub struct HwServices {
    /// Requests and responses.
    pub hw: HwService,
    /// Client → server wake-ups.
    pub request_event: EventService,
    /// Server → client wake-ups.
    pub response_event: EventService,
}

/// Where a link's files live: the name prefix and the root directory.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct IpcLocation {
    /// Prefix of every file iceoryx2 creates, e.g. `qmarc_1234_`.
    pub prefix: String,
    /// Root directory with a trailing slash, e.g. `/tmp/iceoryx2/`.
    pub root: String,
}

impl IpcLocation {
    /// A location; a missing trailing slash is added to `root`.
    pub fn new(prefix: &str, root: &str) -> IpcLocation {
        let mut root = root.to_string();
        if !root.ends_with('/') {
            root.push('/');
        }
        IpcLocation { prefix: prefix.to_string(), root }
    }

    /// A location after checking that its files can be told apart from everybody else's: the
    /// prefix is 1‥40 characters of `A-Z a-z 0-9 _ -` ending in `_` (so that `qmarc_1_` never
    /// matches `qmarc_12_…`), the root an absolute path other than `/`, and both together short
    /// enough for iceoryx2's event socket, `root + prefix + 30-digit id + ".event"`, to fit
    /// the 108-byte `sun_path` (`iceoryx2.md`): at most 72 characters.
    pub fn checked(prefix: &str, root: &str) -> Result<IpcLocation, String> {
        let loc = IpcLocation::new(prefix, root);
        let ok_chars = prefix.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-');
        if prefix.is_empty() || prefix.len() > 40 || !ok_chars || !prefix.ends_with('_') {
            return Err(format!(
                "iceoryx2 prefix `{prefix}`: must be 1 to 40 characters of A-Z a-z 0-9 _ - ending in `_`"
            ));
        }
        if !loc.root.starts_with('/') || loc.root == "/" {
            return Err(format!(
                "iceoryx2 root `{root}`: must be an absolute directory other than /"
            ));
        }
        if loc.root.len() + loc.prefix.len() > 72 {
            return Err(format!(
                "iceoryx2 root `{}` and prefix `{prefix}` are {} characters together: at most 72 fit \
                 iceoryx2's socket names",
                loc.root,
                loc.root.len() + loc.prefix.len()
            ));
        }
        Ok(loc)
    }

    /// The iceoryx2 configuration for this location.
    pub fn config(&self) -> Result<Config, ServiceError> {
        let mut cfg = Config::default();
        cfg.global.prefix = FileName::new(self.prefix.as_bytes())
            .map_err(|e| ServiceError::new("the iceoryx2 prefix", &self.prefix, e))?;
        let root = Path::new(self.root.as_bytes())
            .map_err(|e| ServiceError::new("the iceoryx2 root path", &self.root, e))?;
        cfg.global.set_root_path(&root);
        Ok(cfg)
    }
}

/// Opening a node or a service failed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ServiceError {
    /// What could not be opened.
    pub what: String,
    /// iceoryx2's reason.
    pub reason: String,
}

impl ServiceError {
    /// `what` named `name` could not be opened, for iceoryx2's `reason`.
    pub fn new(what: &str, name: &str, reason: impl std::fmt::Debug) -> ServiceError {
        ServiceError { what: format!("{what} `{name}`"), reason: format!("{reason:?}") }
    }
}

impl std::fmt::Display for ServiceError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "cannot open {}: {}", self.what, self.reason)
    }
}

impl std::error::Error for ServiceError {}

/// iceoryx2 logs only its errors (unless `IOX2_LOG_LEVEL` says otherwise). Every QMARC
/// program passes iceoryx2 its configuration explicitly ([`IpcLocation::config`]), but
/// iceoryx2 0.10 falls back on its global one in places (cleaning up a dead node whose details
/// are unreadable) and warns then "No config file was loaded, a config with default values
/// will be used" — which a user who passed `--config` reads as their file ignored. Our own
/// messages say what went wrong. Runs once; [`create_node`] calls it.
pub fn quiet_iceoryx2() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| set_log_level_from_env_or(LogLevel::Error));
}

/// Creates a node of service type `S` (the link's [`Link`], or `ipc::Service` for the rest)
/// named `name` at `location`. iceoryx2's own signal handling is off: each process installs
/// its own handlers.
pub fn create_node<S: iceoryx2::service::Service>(
    name: &str,
    location: &IpcLocation,
) -> Result<Node<S>, ServiceError> {
    quiet_iceoryx2();
    let cfg = location.config()?;
    let node_name = NodeName::new(name).map_err(|e| ServiceError::new("node name", name, e))?;
    NodeBuilder::new()
        .name(&node_name)
        .config(&cfg)
        .signal_handling_mode(SignalHandlingMode::Disabled)
        .create::<S>()
        .map_err(|e| ServiceError::new("node", name, e))
}

/// Opens (or creates) the three services with the QoS both sides require: one client, one
/// server, at most two requests in flight.
pub fn open_hw_services(node: &Node<Link>) -> Result<HwServices, ServiceError> {
    let hw = node
        .service_builder(&service_name(HW_SERVICE)?)
        .request_response::<HwMsg, HwMsg>()
        .max_clients(1)
        .max_servers(1)
        .max_active_requests_per_client(2)
        .max_response_buffer_size(2)
        .open_or_create()
        .map_err(|e| ServiceError::new("service", HW_SERVICE, e))?;
    Ok(HwServices {
        hw,
        request_event: open_event_service(node, REQUEST_EVENT)?,
        response_event: open_event_service(node, RESPONSE_EVENT)?,
    })
}

/// `name` as an iceoryx2 service name.
fn service_name(name: &str) -> Result<ServiceName, ServiceError> {
    ServiceName::new(name).map_err(|e| ServiceError::new("service name", name, e))
}

/// Opens (or creates) one wake-up event service of the link named `name`.
pub fn open_event_service(node: &Node<Link>, name: &str) -> Result<EventService, ServiceError> {
    node.service_builder(&service_name(name)?)
        .event()
        // One event id (0, the notifier's default): every wait drains the listener's counter
        // per id with an atomic swap, 256 of them at iceoryx2's default.
        .event_id_max_value(0)
        .open_or_create()
        .map_err(|e| ServiceError::new("service", name, e))
}

/// Directory of POSIX shared memory, where iceoryx2 puts its segments.
pub const SHM_DIR: &str = "/dev/shm";

/// The run file of the run with iceoryx2 prefix `prefix` (the settings both children get,
/// written by the starter): next to its shared memory, so that it goes with the run's other
/// files, and so that readers of a run (`qmarc scope`) find it.
pub fn run_file(prefix: &str) -> std::path::PathBuf {
    std::path::Path::new(SHM_DIR).join(format!("{prefix}run.json"))
}

impl IpcLocation {
    /// Every file of this prefix that exists now: shared-memory segments in [`SHM_DIR`] and
    /// files under the root (services, node records, event sockets).
    pub fn files(&self) -> Vec<std::path::PathBuf> {
        let mut found = Vec::new();
        collect_prefixed(std::path::Path::new(SHM_DIR), &self.prefix, false, &mut found);
        collect_prefixed(std::path::Path::new(&self.root), &self.prefix, true, &mut found);
        found
    }

    /// Removes every file of this prefix and the per-node directories (`<root>/nodes/<id>`)
    /// that it leaves empty; the shared `services` and `nodes` directories stay, since other
    /// runs may be creating files in them. Only call it when no process of this prefix runs
    /// (iceoryx2 #601: clear both locations together). Returns how many files were removed.
    pub fn remove_files(&self) -> usize {
        if self.prefix.is_empty() {
            return 0; // would match every file
        }
        let files = self.files();
        let removed = files.iter().filter(|f| std::fs::remove_file(f).is_ok()).count();
        let nodes = std::path::Path::new(&self.root).join("nodes");
        for f in &files {
            if let Some(dir) = f.parent().filter(|d| d.parent() == Some(nodes.as_path())) {
                // Fails (as it should) while the directory holds another node's files.
                let _ = std::fs::remove_dir(dir);
            }
        }
        removed
    }
}

fn collect_prefixed(
    dir: &std::path::Path,
    prefix: &str,
    recurse: bool,
    out: &mut Vec<std::path::PathBuf>,
) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let path = e.path();
        let is_dir = e.file_type().is_ok_and(|t| t.is_dir());
        if is_dir {
            if recurse {
                collect_prefixed(&path, prefix, true, out);
            }
        } else if e.file_name().to_string_lossy().starts_with(prefix) {
            out.push(path);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn locations_that_could_touch_other_files_are_refused() {
        assert!(IpcLocation::checked("qmarc_12_", "/tmp/iceoryx2/").is_ok());
        for (prefix, root, expected) in [
            (
                "",
                "/tmp/x",
                "iceoryx2 prefix ``: must be 1 to 40 characters of A-Z a-z 0-9 _ - ending in `_`",
            ),
            (
                "abc",
                "/tmp/x",
                "iceoryx2 prefix `abc`: must be 1 to 40 characters of A-Z a-z 0-9 _ - ending in `_`",
            ),
            (
                "a/b_",
                "/tmp/x",
                "iceoryx2 prefix `a/b_`: must be 1 to 40 characters of A-Z a-z 0-9 _ - ending in `_`",
            ),
            ("p_", "/", "iceoryx2 root `/`: must be an absolute directory other than /"),
            ("p_", "tmp/x", "iceoryx2 root `tmp/x`: must be an absolute directory other than /"),
        ] {
            assert_eq!(IpcLocation::checked(prefix, root).unwrap_err(), expected);
        }
        let long_root = format!("/tmp/{}", "r".repeat(70));
        assert!(IpcLocation::checked("p_", &long_root).unwrap_err().contains("at most 72"));
        assert_eq!(IpcLocation::new("", "/tmp").remove_files(), 0);
    }

    /// Issue 28, item 8: iceoryx2's fallback on its global configuration says nothing once
    /// QMARC has quieted it (checked in a child process: the log level is global).
    #[test]
    fn iceoryx2_does_not_say_it_loaded_no_config_file() {
        if std::env::var_os("QMARC_QUIET_CHILD").is_some() {
            quiet_iceoryx2();
            let _ = iceoryx2::config::Config::global_config();
            return;
        }
        let me = std::env::current_exe().unwrap();
        let child = std::process::Command::new(me)
            .args(["--exact", "service::tests::iceoryx2_does_not_say_it_loaded_no_config_file"])
            .env("QMARC_QUIET_CHILD", "1")
            .env_remove("IOX2_LOG_LEVEL")
            .env("HOME", "/nonexistent")
            .output()
            .unwrap();
        assert!(child.status.success(), "{child:?}");
        let err = String::from_utf8_lossy(&child.stderr);
        assert!(!err.contains("No config file was loaded"), "{err}");
    }
}
