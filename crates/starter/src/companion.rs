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
        if let Some(child) = self.child.as_mut() {
            qmarc_program::process::terminate(child, Duration::from_secs(3));
        }
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

/// How long the starter waits for its robot to join the cell: the companion's own wait for
/// the cell's camera, and some.
const JOIN_WAIT: Duration = Duration::from_secs(45);

/// Starts the cell's companion `program` (`qmarc-cell robot`) on the run's file `run` and
/// waits until it has joined the cell (its messages to `log`, if given): the companion, and
/// when the cell's world began on this host's monotonic clock (the run's `epoch_ns`: the
/// simulated belt is the cell camera's). `Err` with the exit code when it did not join: 3
/// when the cell refused the robot (the companion said why), 130 on a stop signal.
pub(crate) fn join_cell(
    program: &Path,
    run: &Path,
    log: Option<&std::fs::File>,
    stop: &std::sync::atomic::AtomicBool,
) -> Result<(Companion, u64), (u8, String)> {
    use std::io::BufRead;
    use std::sync::atomic::Ordering;
    let args = ["robot".to_string(), format!("--settings={}", run.display())];
    let mut child = supervise::command_logged(program, &args, log)
        .and_then(|mut cmd| cmd.stdout(std::process::Stdio::piped()).spawn())
        .map_err(|e| {
            (qmarc_proto::exit::INTERNAL, format!("cannot start {}: {e}", program.display()))
        })?;
    let stdout = child.stdout.take();
    let (tx, lines) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        for line in std::io::BufReader::new(stdout?).lines() {
            tx.send(line.ok()?).ok()?;
        }
        Some(())
    });
    let since = Instant::now();
    let ended = |child: &mut Child, code: u8, why: String| {
        let _ = child.kill();
        let _ = child.wait();
        Err((code, why))
    };
    loop {
        if let Ok(line) = lines.recv_timeout(Duration::from_millis(20)) {
            if let Some(epoch) = line.strip_prefix(qmarc_proto::cell::JOINED) {
                return match epoch.trim().parse() {
                    Ok(e) => Ok((
                        Companion { name: "qmarc-cell", goes_on: CELL_GOES_ON, child: Some(child) },
                        e,
                    )),
                    Err(_) => ended(
                        &mut child,
                        qmarc_proto::exit::INTERNAL,
                        format!("qmarc-cell said `{line}`"),
                    ),
                };
            }
            continue;
        }
        if stop.load(Ordering::Relaxed) {
            return ended(
                &mut child,
                qmarc_proto::exit::INTERRUPTED,
                "stopped while joining the cell".into(),
            );
        }
        if let Ok(Some(s)) = child.try_wait() {
            let how = describe_exit("qmarc-cell", exit_of(s));
            let code = if s.code() == Some(i32::from(qmarc_proto::exit::REFUSED)) {
                qmarc_proto::exit::REFUSED
            } else {
                qmarc_proto::exit::INTERNAL
            };
            return Err((code, format!("this robot did not join the cell ({how})")));
        }
        if since.elapsed() > JOIN_WAIT {
            return ended(
                &mut child,
                qmarc_proto::exit::INTERNAL,
                format!("qmarc-cell did not join the cell in {} s", JOIN_WAIT.as_secs()),
            );
        }
    }
}

/// What goes on when a robot's cell companion dies.
const CELL_GOES_ON: &str =
    "the session goes on with the parts it knows, out of the cell (the others see it gone)";

/// Joins the cell through its companion `program` (`None`: the run joins none), on the
/// run's file `run` holding `spec`, whose world's epoch the run then takes: the simulated
/// belt is the cell camera's. A robot that does not join leaves none of the run's files at
/// `location` behind; the error is [`join_cell`]'s.
pub(crate) fn join(
    program: Option<&Path>,
    (spec, location, run): (&qmarc_config::RunSpec, &IpcLocation, &Path),
    log: Option<&std::fs::File>,
    stop: &std::sync::atomic::AtomicBool,
) -> Result<Option<Companion>, (u8, String)> {
    let Some(program) = program else { return Ok(None) };
    let joined = join_cell(program, run, log, stop).and_then(|(companion, epoch_ns)| {
        let spec = qmarc_config::RunSpec { epoch_ns, ..spec.clone() };
        spec.write(run).map_err(|e| (qmarc_proto::exit::INTERNAL, e.to_string()))?;
        Ok(companion)
    });
    if joined.is_err() {
        location.remove_files();
    }
    joined.map(Some)
}

/// `--zenoh-config` configures the bridge's session or the cell's: with neither it would be
/// ignored, so it is refused.
pub(crate) fn zenoh_for(command: &crate::cli::Command, in_cell: bool) -> Result<(), String> {
    if let crate::cli::Command::Serve(a)
    | crate::cli::Command::Conveyor(crate::cli::ConveyorArgs { serve: a, .. }) = command
        && a.zenoh_config.is_some()
        && !a.bridge
        && !in_cell
    {
        return Err(
            "--zenoh-config configures the Zenoh session of --bridge or of --cell: give one".into(),
        );
    }
    Ok(())
}
