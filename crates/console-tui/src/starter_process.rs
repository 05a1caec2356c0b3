//! Running a move: `qmarc-starter` is spawned with the chosen mode and the settings file, its
//! output (written to an unlinked file, see [`Running::start`]) is streamed line by line into
//! the log, and an abort sends it SIGTERM — it forwards
//! the stop to both children, which disable the motors and write their data. A [`Running`]
//! dropped while its move runs stops it the same way.

use std::ffi::OsString;
use std::fs::{File, OpenOptions};
use std::io::Read;
use std::os::unix::fs::OpenOptionsExt;
use std::os::unix::process::CommandExt;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::{Duration, Instant};

/// What to run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Mode {
    /// `home`.
    Home,
    /// `run` (the settings' method and knots).
    Run,
    /// `step`.
    Step,
    /// `tune run`: the gains tuned on the settings' path.
    Tune,
    /// `jog --motor M --counts N`: one motor moved by hand.
    Jog {
        /// 1-based motor.
        motor: usize,
        /// How far, counts.
        counts: i64,
    },
    /// `jog --axis A --mm D`: the effector along x, y or z.
    JogAxis {
        /// 0 x, 1 y, 2 z.
        axis: usize,
        /// How far, mm.
        mm: f64,
    },
    /// `move --xyz X,Y,Z`: go to a point (mm).
    GoTo {
        /// The point, mm.
        xyz: [f64; 3],
    },
    /// `move --grip on|off`: close or open the gripper where the robot is.
    Grip {
        /// Close it.
        close: bool,
    },
    /// `conveyor`: pick the parts off the belt for `conveyor.run_s` (issue 44).
    Conveyor,
}

impl Mode {
    /// The starter's subcommand, as the console names it.
    pub fn arg(self) -> &'static str {
        match self {
            Mode::Home => "home",
            Mode::Run => "run",
            Mode::Step => "step",
            Mode::Tune => "tune",
            Mode::Jog { .. } | Mode::JogAxis { .. } => "jog",
            Mode::GoTo { .. } | Mode::Grip { .. } => "move",
            Mode::Conveyor => "conveyor",
        }
    }

    /// The starter's arguments after `--config`.
    pub fn args(self) -> Vec<String> {
        let fixed: &[&str] = match self {
            Mode::Home => &["home"],
            // The path, from wherever the motors are: an approach to its start first.
            Mode::Run => &["run", "--approach"],
            Mode::Step => &["step"],
            Mode::Tune => &["tune", "run"],
            Mode::Conveyor => &["conveyor"],
            Mode::Jog { motor, counts } => {
                return vec![
                    "jog".into(),
                    format!("--motor={motor}"),
                    format!("--counts={counts}"),
                ];
            }
            Mode::JogAxis { axis, mm } => {
                let axis = qmarc_config::AXES[axis.min(2)];
                return vec!["jog".into(), format!("--axis={axis}"), format!("--mm={mm}")];
            }
            Mode::GoTo { xyz: [x, y, z] } => {
                return vec!["move".into(), format!("--xyz={x},{y},{z}")];
            }
            Mode::Grip { close } => {
                return vec!["move".into(), format!("--grip={}", if close { "on" } else { "off" })];
            }
        };
        fixed.iter().map(|a| a.to_string()).collect()
    }
}

/// A move in progress.
#[derive(Debug)]
pub struct Running {
    child: Child,
    lines: Receiver<String>,
    /// Set when the starter has ended: the output file is then complete.
    done: Arc<AtomicBool>,
    /// What runs.
    pub mode: Mode,
    /// Since when.
    pub started: Instant,
    /// When an abort was sent, if one was.
    pub aborted: Option<Instant>,
    /// Where its results will be (the settings' output folder when it started).
    pub out_dir: PathBuf,
    /// (Kp, Kd, Kvff) per motor it runs with.
    pub gains: Vec<(f64, f64, f64)>,
    /// The starter had to be killed (it could not remove its files).
    pub killed: bool,
}

/// The starter's output goes to a file, not a pipe: if the console dies, the starter and its
/// children must not meet a closed pipe while they stop the move. The file is unlinked as soon
/// as it is open (a writer for the starter, a reader of our own), so nothing is left behind.
fn output_file() -> std::io::Result<(File, File)> {
    static N: AtomicU32 = AtomicU32::new(0);
    let n = N.fetch_add(1, Ordering::Relaxed);
    let path = std::env::temp_dir().join(format!("qmarc-console-{}-{n}.log", std::process::id()));
    let writer = OpenOptions::new().append(true).create_new(true).mode(0o600).open(&path)?;
    let reader = File::open(&path);
    let _ = std::fs::remove_file(&path);
    Ok((writer, reader?))
}

/// Sends the file's lines as they are written, until `done` (the writers have all ended) and
/// the file is read to its end.
fn tail(mut file: File, done: Arc<AtomicBool>, tx: Sender<String>) {
    std::thread::spawn(move || {
        let mut pending: Vec<u8> = Vec::new();
        let mut buf = [0u8; 4096];
        loop {
            // Read after looking at `done`: a read that finds the end then has seen everything.
            let finished = done.load(Ordering::Acquire);
            match file.read(&mut buf) {
                Ok(0) if finished => {
                    if !pending.is_empty() {
                        let _ = tx.send(String::from_utf8_lossy(&pending).into_owned());
                    }
                    return;
                }
                Ok(0) => std::thread::sleep(Duration::from_millis(20)),
                Ok(n) => {
                    pending.extend_from_slice(&buf[..n]);
                    while let Some(i) = pending.iter().position(|&b| b == b'\n') {
                        let line: Vec<u8> = pending.drain(..=i).collect();
                        let text = String::from_utf8_lossy(&line[..i]).into_owned();
                        if tx.send(text).is_err() {
                            return;
                        }
                    }
                }
                Err(_) => return,
            }
        }
    });
}

impl Running {
    /// Spawns `starter EXTRA… --config=CONFIG MODE…` in `cwd` (relative paths of the settings
    /// are relative to it, as for the starter run by hand). The starter gets a process group
    /// of its own, so signals of the terminal reach only the console, which decides what
    /// stops the move; and SIGTERM if the console dies, so no move outlives it.
    pub fn start(
        starter: &Path,
        extra: &[String],
        config: &Path,
        mode: Mode,
        cwd: &Path,
    ) -> std::io::Result<Running> {
        let mut config_arg = OsString::from("--config=");
        config_arg.push(config);
        let (writer, reader) = output_file()?;
        let mut cmd = Command::new(starter);
        cmd.args(extra)
            .arg(config_arg)
            .args(mode.args())
            .current_dir(cwd)
            .stdin(Stdio::null())
            .stdout(Stdio::from(writer.try_clone()?))
            .stderr(Stdio::from(writer))
            .process_group(0);
        // The starter's own spawn rules: SIGTERM when the console dies, at once if it is gone.
        qmarc_program::process::with_parent_death_signal(&mut cmd);
        let child = cmd.spawn()?;
        // `cmd` holds the writer's copies: gone with it, so only the starter's side stays open.
        drop(cmd);
        let (tx, lines) = channel();
        let done = Arc::new(AtomicBool::new(false));
        tail(reader, Arc::clone(&done), tx);
        Ok(Running {
            child,
            lines,
            done,
            mode,
            started: Instant::now(),
            aborted: None,
            out_dir: cwd.to_path_buf(),
            gains: Vec::new(),
            killed: false,
        })
    }

    /// Lines printed since the last call.
    pub fn drain(&self) -> Vec<String> {
        self.lines.try_iter().collect()
    }

    /// The rest of the output once the starter has ended: lines until the file is read to its
    /// end, for at most `timeout`.
    pub fn drain_to_end(&self, timeout: Duration) -> Vec<String> {
        let end = Instant::now() + timeout;
        let mut out = Vec::new();
        while let Some(left) = end.checked_duration_since(Instant::now()) {
            match self.lines.recv_timeout(left) {
                Ok(l) => out.push(l),
                Err(_) => break, // read to the end, or out of time
            }
        }
        out
    }

    /// Asks the move to stop (once; later calls do nothing): SIGTERM to the starter, which
    /// stops both children (motors disabled, data written).
    pub fn abort(&mut self) {
        if self.aborted.is_none() {
            qmarc_program::process::send(&self.child, nix::sys::signal::Signal::SIGTERM);
            self.aborted = Some(Instant::now());
        }
    }

    /// Kills a starter that does not stop: its children then get SIGTERM from the kernel
    /// (their parent-death signal) and stop as they would have for it.
    pub fn kill(&mut self) {
        let _ = self.child.kill();
        self.killed = true;
        self.aborted.get_or_insert_with(Instant::now);
    }

    /// The starter's process id.
    pub fn pid(&self) -> u32 {
        self.child.id()
    }

    /// The exit status once the starter has ended.
    pub fn finished(&mut self) -> Option<ExitStatus> {
        let status = self.child.try_wait().ok().flatten();
        if status.is_some() {
            self.done.store(true, Ordering::Release);
        }
        status
    }
}

impl Drop for Running {
    /// A move is never left behind: however the console lets go of it (a panic included), the
    /// starter is stopped and waited for — SIGTERM, then SIGKILL after 30 s.
    fn drop(&mut self) {
        if self.finished().is_some() {
            return;
        }
        self.abort();
        let end = Instant::now() + Duration::from_secs(30);
        while Instant::now() < end {
            if self.finished().is_some() {
                return;
            }
            std::thread::sleep(Duration::from_millis(20));
        }
        self.kill();
        let _ = self.child.wait();
        self.done.store(true, Ordering::Release);
    }
}
