//! [`RunSpec`]: one run as the starter hands it to both children — the checked settings, the
//! mode and how to run it — so that no child parses a command line or a settings file again.
//!
//! It travels as a JSON file (`--settings FILE`), which the children deserialize as it is:
//! the same way whether the starter wrote it (next to the run's iceoryx2 files, removed with
//! them) or a developer did (`qmarc-starter --print-settings … > run.json`), to run a child
//! by hand.

use crate::Settings;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What a move does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// Step every motor (thesis 3.4, tuning).
    Step,
    /// Follow a path (thesis 3.12).
    Run,
    /// Home on the top switches (thesis 3.10.1.1).
    Home,
    /// Move one motor by hand, jerk-limited (`[jog]`).
    Jog,
    /// The open-loop first motion: a small voltage on each motor in turn (`[check]`).
    Check,
    /// An online, jerk-limited move to a target (`move`, [`crate::MoveSettings`]).
    Move,
    /// Hold, and move as commands arrive over `qmarc/command` (`serve`).
    Serve,
    /// A serving session at a belt (`conveyor`): the belt runs, the camera sees its parts and
    /// the robot picks them, for `conveyor.run_s`.
    Conveyor,
}

impl Mode {
    /// A serving session: it takes commands while it runs (`serve`, `conveyor`).
    pub fn serving(self) -> bool {
        matches!(self, Mode::Serve | Mode::Conveyor)
    }
}

impl std::fmt::Display for Mode {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Mode::Step => "step",
            Mode::Run => "run",
            Mode::Home => "home",
            Mode::Jog => "jog",
            Mode::Check => "check",
            Mode::Move => "move",
            Mode::Serve => "serve",
            Mode::Conveyor => "conveyor",
        })
    }
}

impl std::str::FromStr for Mode {
    type Err = String;
    fn from_str(s: &str) -> Result<Mode, String> {
        match s {
            "step" => Ok(Mode::Step),
            "run" => Ok(Mode::Run),
            "home" => Ok(Mode::Home),
            "jog" => Ok(Mode::Jog),
            "check" => Ok(Mode::Check),
            "move" => Ok(Mode::Move),
            "serve" => Ok(Mode::Serve),
            "conveyor" => Ok(Mode::Conveyor),
            other => Err(format!(
                "unknown mode `{other}`: step, run, home, jog, check, move, serve or conveyor"
            )),
        }
    }
}

/// One run, for both children.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunSpec {
    /// The checked settings, every override applied.
    pub settings: Settings,
    /// What the move does.
    pub mode: Mode,
    /// Lock-step simulated time.
    pub deterministic: bool,
    /// Lock-step and not paced by the timer (`--unpaced`): each cycle follows the last at
    /// once, so a move takes what its computing takes; the data are those of the paced
    /// lock-step run. Only on the simulated robot.
    #[serde(default)]
    pub unpaced: bool,
    /// Move in a frame that may not be homed (software limits off).
    pub unhomed: bool,
    /// Prefix of the run's iceoryx2 files.
    pub iox_prefix: String,
    /// iceoryx2 root directory.
    pub iox_root: String,
    /// `CLOCK_MONOTONIC` ns at which the run's world starts: the simulated belt is at 0 then
    /// and its speed steps count from then, and the simulated camera's parts arrive on that
    /// belt — one world for every process of the run. The starter's clock as it writes the
    /// run; 0 (unset) starts each process's world when that process starts.
    #[serde(default)]
    pub epoch_ns: u64,
}

/// A run file could not be written or read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum RunSpecError {
    /// Reading or writing the file failed.
    #[error("{file}: {reason}")]
    Io {
        /// The file.
        file: PathBuf,
        /// Why.
        reason: std::io::Error,
    },
    /// The file is not a run file of this version.
    #[error(
        "{file}: not a QMARC run file: {reason} (write it with `qmarc-starter --print-settings`)"
    )]
    Format {
        /// The file.
        file: PathBuf,
        /// serde's message.
        reason: String,
    },
}

impl RunSpec {
    /// The run as JSON.
    pub fn to_json(&self) -> String {
        // Plain data of strings, numbers and paths: serializing it cannot fail.
        serde_json::to_string_pretty(self).unwrap_or_default()
    }

    /// Writes the run to `path`.
    pub fn write(&self, path: &Path) -> Result<(), RunSpecError> {
        std::fs::write(path, self.to_json() + "\n")
            .map_err(|reason| RunSpecError::Io { file: path.to_path_buf(), reason })
    }

    /// Reads a run written by [`RunSpec::write`].
    pub fn read(path: &Path) -> Result<RunSpec, RunSpecError> {
        let io = |reason| RunSpecError::Io { file: path.to_path_buf(), reason };
        let too_large = || {
            io(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                format!(
                    "larger than {} bytes, the most a run file may have",
                    crate::MAX_CONFIG_BYTES
                ),
            ))
        };
        let raw = crate::read_bounded(path, crate::MAX_CONFIG_BYTES)
            .map_err(io)?
            .ok_or_else(too_large)?;
        serde_json::from_slice(&raw)
            .map_err(|e| RunSpecError::Format { file: path.to_path_buf(), reason: e.to_string() })
    }
}
