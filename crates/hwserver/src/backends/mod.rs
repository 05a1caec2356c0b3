//! The backend registry: every hardware the server can drive, by name. A backend is one file
//! in this folder plus one line in [`BACKENDS`]; the settings (`hwserver.backend`,
//! `--backend`) choose from it, and the conformance suite (`crate::conformance`,
//! `tests/conformance.rs`) runs on every entry.

use crate::backend::{Backend, BackendOpenError};
use crate::conformance::Rig;
use qmarc_config::{ConfigLoadError, Mode, Names, RunSpec, Settings};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::service::IpcLocation;

pub mod s626;
pub mod sim;
pub mod state;

/// Opens a backend from the settings; the flag is lock-step (simulated) time.
pub type OpenFn = fn(&Settings, bool) -> Result<Box<dyn Backend>, BackendOpenError>;

/// A registered backend.
#[derive(Clone, Copy)]
pub struct BackendEntry {
    /// Name used in `hwserver.backend` and `--backend`.
    pub name: &'static str,
    /// One line for lists.
    pub description: &'static str,
    /// Opens the hardware of the settings; `lockstep`: simulated time, where the backend has
    /// it (`--deterministic`).
    pub open: OpenFn,
    /// Checks, without keeping or driving anything, that the settings' hardware is there and
    /// usable: the starter runs it before it spawns anything, so a bad set-up fails at once.
    pub check: fn(&Settings, bool) -> Result<(), BackendOpenError>,
    /// A rig for the conformance suite, or `None` where none is at hand.
    pub rig: fn() -> Option<Box<dyn Rig>>,
}

/// Every backend.
pub const BACKENDS: &[BackendEntry] = &[
    BackendEntry {
        name: "sim",
        description: "the simulated Deltabot: velocity-mode amplifiers, 24-bit counters, limit switches",
        open: |s, lockstep| Ok(Box::new(sim::SimDeltabot::open(s, lockstep)?)),
        check: sim::SimDeltabot::check,
        rig: || Some(Box::new(sim::SimRig::default())),
    },
    BackendEntry {
        name: "s626",
        description: "the Sensoray 626 through the kernel's comedi driver (--device /dev/comediN)",
        open: |s, lockstep| Ok(Box::new(s626::S626::open(s, lockstep)?)),
        check: s626::S626::check,
        rig: || Some(Box::new(s626::FakeRig::default())),
    },
];

/// The backend named `name`.
pub fn backend(name: &str) -> Option<&'static BackendEntry> {
    BACKENDS.iter().find(|b| b.name == name)
}

/// Names of every backend.
pub fn names() -> Vec<&'static str> {
    BACKENDS.iter().map(|b| b.name).collect()
}

/// The registry entry of the backend the settings name.
fn entry_of(s: &Settings) -> Result<&'static BackendEntry, BackendOpenError> {
    backend(&s.hwserver.backend).ok_or_else(|| BackendOpenError::Unknown {
        name: s.hwserver.backend.clone(),
        available: names().join(", "),
    })
}

/// Opens the backend the settings name.
pub fn open(s: &Settings, lockstep: bool) -> Result<Box<dyn Backend>, BackendOpenError> {
    (entry_of(s)?.open)(s, lockstep)
}

/// Checks the backend the settings name ([`BackendEntry::check`]).
pub fn check(s: &Settings, lockstep: bool) -> Result<(), BackendOpenError> {
    (entry_of(s)?.check)(s, lockstep)
}

/// A run of the server alone — for its tests, its benchmark and debugging by hand: the
/// settings file `text` (with the `[[motor]]` tables it lacks added) at `location`, in
/// lock-step when `lockstep`.
pub fn standalone_run(
    text: &str,
    location: &IpcLocation,
    lockstep: bool,
) -> Result<RunSpec, ConfigLoadError> {
    let table = "\n[[motor]]\nkp = 0.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n";
    let text = format!("{text}{}", table.repeat(MAX_MOTORS));
    let names = Names::backends_only(names());
    Ok(RunSpec {
        settings: Settings::parse("standalone.toml".as_ref(), &text, &names)?,
        mode: Mode::Step,
        deterministic: lockstep,
        unpaced: false,
        unhomed: false,
        iox_prefix: location.prefix.clone(),
        iox_root: location.root.clone(),
    })
}

/// The settings file `toml` (read as `q.toml`) with three motors of unit gains appended: what
/// the backends' unit tests parse, knowing only the backends' names.
#[cfg(test)]
pub(crate) fn test_settings(toml: &str) -> Settings {
    let names = Names::backends_only(names());
    let motors = "[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n".repeat(3);
    Settings::parse(std::path::Path::new("q.toml"), &format!("{toml}{motors}"), &names).unwrap()
}
