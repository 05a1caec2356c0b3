//! Running a move: `qmarc-starter` is spawned with the chosen mode and the settings file, its
//! output is streamed line by line into the log, and an abort sends it SIGTERM — it forwards
//! the stop to both children, which disable the motors and write their data.

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::{Instant, SystemTime};

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Mode {
    /// `home`.
    Home,
    /// `run` (the settings' method and knots).
    Run,
    /// `step`.
    Step,
}

impl Mode {
    /// The starter's subcommand.
    pub fn arg(self) -> &'static str {
        match self {
            Mode::Home => "home",
            Mode::Run => "run",
            Mode::Step => "step",
        }
    }
}

/// A move in progress.
#[derive(Debug)]
pub struct Running {
    child: Child,
    lines: Receiver<String>,
    /// What runs.
    pub mode: Mode,
    /// Since when.
    pub started: Instant,
    /// Since when, wall clock (results older than this are not this move's).
    pub started_wall: SystemTime,
    /// An abort was sent.
    pub aborted: bool,
}

fn forward(stream: impl std::io::Read + Send + 'static, tx: Sender<String>) {
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
}

impl Running {
    /// Spawns `starter EXTRA… --config=CONFIG MODE` in `cwd` (relative paths of the settings
    /// are relative to it, as for the starter run by hand).
    pub fn start(
        starter: &Path,
        extra: &[String],
        config: &Path,
        mode: Mode,
        cwd: &Path,
    ) -> std::io::Result<Running> {
        let started_wall = SystemTime::now();
        let mut child = Command::new(starter)
            .args(extra)
            .arg(format!("--config={}", config.display()))
            .arg(mode.arg())
            .current_dir(cwd)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()?;
        let (tx, lines) = channel();
        if let Some(out) = child.stdout.take() {
            forward(out, tx.clone());
        }
        if let Some(err) = child.stderr.take() {
            forward(err, tx);
        }
        Ok(Running { child, lines, mode, started: Instant::now(), started_wall, aborted: false })
    }

    /// Lines printed since the last call.
    pub fn drain(&self) -> Vec<String> {
        self.lines.try_iter().collect()
    }

    /// Asks the move to stop: SIGTERM to the starter, which stops both children (motors
    /// disabled, data written).
    pub fn abort(&mut self) {
        // SAFETY: kill(2) on our own child, not yet reaped.
        unsafe { libc::kill(self.child.id() as libc::pid_t, libc::SIGTERM) };
        self.aborted = true;
    }

    /// The exit status once the starter has ended.
    pub fn finished(&mut self) -> Option<ExitStatus> {
        self.child.try_wait().ok().flatten()
    }
}
