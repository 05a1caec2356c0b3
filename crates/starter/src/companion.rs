//! A serving session's companions beside the controller and the hwserver: `qmarc-bridge`
//! (`serve --bridge`), `qmarc-foxglove live` (`serve --foxglove`) and `qmarc-camera`
//! (`conveyor`). A companion is not one of the run's
//! children: its end, or its death (kill -9), ends nothing, and a death is said once, at once;
//! the session's end stops it (SIGTERM, then SIGKILL after 3 s). Like every child it ends if
//! the starter dies (its parent-death signal).

use crate::status::StatusLine;
use crate::supervise::{self, Exit, describe_exit};
use qmarc_proto::service::IpcLocation;
use std::path::Path;
use std::process::Child;
use std::time::{Duration, Instant};

/// The options that name the session at `location` to a client program.
fn location_args(location: &IpcLocation) -> Vec<String> {
    vec![format!("--iox-prefix={}", location.prefix), format!("--iox-root={}", location.root)]
}

/// A companion of a serving session.
pub(crate) struct Companion {
    /// Its program's name.
    name: &'static str,
    /// What goes on without it, as its death is said.
    goes_on: &'static str,
    child: Option<Child>,
}

impl Companion {
    /// Starts the bridge `program` with its options `own` on the session at `location` (its
    /// messages to `log`, if given).
    pub(crate) fn bridge(
        program: &Path,
        own: &[String],
        location: &IpcLocation,
        log: Option<&std::fs::File>,
    ) -> Companion {
        let mut args = location_args(location);
        args.extend_from_slice(own);
        Companion::start("qmarc-bridge", "the session goes on", program, &args, log)
    }

    /// Starts the live view `program` (`qmarc-foxglove live`) of the session at `location`,
    /// serving at `addr` (its messages to `log`, if given).
    pub(crate) fn foxglove(
        program: &Path,
        addr: &str,
        location: &IpcLocation,
        log: Option<&std::fs::File>,
    ) -> Companion {
        let mut args = vec!["live".to_string()];
        args.extend(location_args(location));
        args.push(format!("--addr={addr}"));
        Companion::start("qmarc-foxglove", "the session goes on", program, &args, log)
    }

    /// Starts the camera server `program` on the run's file (`args`, the children's).
    pub(crate) fn camera(
        program: &Path,
        args: &[String],
        log: Option<&std::fs::File>,
    ) -> Companion {
        let goes_on = "the session goes on, picking the parts it has already seen";
        Companion::start("qmarc-camera", goes_on, program, args, log)
    }

    fn start(
        name: &'static str,
        goes_on: &'static str,
        program: &Path,
        args: &[String],
        log: Option<&std::fs::File>,
    ) -> Companion {
        match supervise::spawn_logged(program, args, log) {
            Ok(child) => Companion { name, goes_on, child: Some(child) },
            Err(e) => {
                eprintln!(
                    "qmarc-starter: cannot start {}: {e}; serving without it",
                    program.display()
                );
                Companion { name, goes_on, child: None }
            }
        }
    }

    /// Notes, once, that the companion has ended while the session goes on.
    pub(crate) fn watch(&mut self, status: &mut StatusLine<'_>) {
        let Some(child) = self.child.as_mut() else { return };
        if let Ok(Some(s)) = child.try_wait() {
            // A companion that ends by itself (exit 0) saw the session end: nothing to say.
            if !s.success() {
                status.clear();
                let how = describe_exit(self.name, exit_of(s));
                eprintln!("qmarc-starter: {how}; {}", self.goes_on);
            }
            self.child = None;
        }
    }

    /// The session has ended: the companion ends too.
    pub(crate) fn stop(mut self) {
        let Some(child) = self.child.as_mut() else { return };
        qmarc_program::process::send(child, nix::sys::signal::Signal::SIGTERM);
        let since = Instant::now();
        while since.elapsed() < Duration::from_secs(3) {
            if let Ok(Some(_)) = child.try_wait() {
                return;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
        let _ = child.kill();
        let _ = child.wait();
    }
}

fn exit_of(s: std::process::ExitStatus) -> Exit {
    use std::os::unix::process::ExitStatusExt;
    match (s.code(), s.signal()) {
        (Some(code), _) => Exit::Code(code),
        (None, Some(sig)) => Exit::Signal(sig),
        _ => Exit::Code(-1),
    }
}
