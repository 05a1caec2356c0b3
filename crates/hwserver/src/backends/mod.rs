//! The backend registry: every hardware the server can drive, by name. A backend is one file
//! in this folder plus one line in [`BACKENDS`]; the settings (`hwserver.backend`,
//! `--backend`) choose from it, and the conformance suite (`crate::conformance`,
//! `tests/conformance.rs`) runs on every entry.

use crate::backend::{Backend, BackendOpenError};
use crate::conformance::Rig;
use qmarc_config::{ConfigLoadError, Mode, Names, RunSpec, Settings};
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::service::IpcLocation;

pub mod sim;

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
    /// A rig for the conformance suite, or `None` where none is at hand (a card whose device
    /// no environment variable names).
    pub rig: fn() -> Option<Box<dyn Rig>>,
}

/// Every backend.
pub const BACKENDS: &[BackendEntry] = &[BackendEntry {
    name: "sim",
    description: "the simulated Deltabot: velocity-mode amplifiers, 24-bit counters, limit switches",
    open: |s, lockstep| Ok(Box::new(sim::SimDeltabot::open(s, lockstep)?)),
    rig: || Some(Box::new(sim::SimRig)),
}];

/// The backend named `name`.
pub fn backend(name: &str) -> Option<&'static BackendEntry> {
    BACKENDS.iter().find(|b| b.name == name)
}

/// Names of every backend.
pub fn names() -> Vec<&'static str> {
    BACKENDS.iter().map(|b| b.name).collect()
}

/// Opens the backend the settings name.
pub fn open(s: &Settings, lockstep: bool) -> Result<Box<dyn Backend>, BackendOpenError> {
    let entry = backend(&s.hwserver.backend).ok_or_else(|| BackendOpenError::Unknown {
        name: s.hwserver.backend.clone(),
        available: names().join(", "),
    })?;
    (entry.open)(s, lockstep)
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
    let names = Names { laws: vec!["pidff"], methods: vec![], backends: names() };
    Ok(RunSpec {
        settings: Settings::parse("standalone.toml".as_ref(), &text, &names)?,
        mode: Mode::Step,
        deterministic: lockstep,
        unhomed: false,
        iox_prefix: location.prefix.clone(),
        iox_root: location.root.clone(),
    })
}
