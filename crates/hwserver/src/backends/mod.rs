//! The backend registry: every hardware the server can drive, one entry per
//! `qmarc_config::BackendKind`. A backend is one file in this folder, its variant there and
//! one line in [`BACKENDS`]; the settings (`hwserver.backend`, `--backend`) choose from it, and the conformance suite (`crate::conformance`,
//! `tests/conformance.rs`) runs on every entry.
//!
//! The recipe, for a card `foo` (this example is compiled and run by `cargo test`): its
//! variant in `qmarc_config::BackendKind` (the settings' closed set of hardware), the card in
//! `crates/hwserver/src/backends/foo.rs`, then `pub mod foo;` and its entry in [`BACKENDS`].
//! `--backend foo` and `hwserver.backend = "foo"` then work.
//!
//! ```
//! use qmarc_hwserver::HwCore;
//! use qmarc_hwserver::backend::{Backend, BackendOpenError, HwFault, Inputs};
//! use qmarc_hwserver::backends::BackendEntry;
//! use qmarc_config::{BackendKind, Names, Settings};
//! use qmarc_proto::{COUNTER_ZERO, HwMsg, MAX_MOTORS};
//!
//! /// The card (`backends/foo.rs`): its counters, DACs, enables and switches.
//! pub struct Foo {
//!     counters: [u32; MAX_MOTORS],
//!     n_motors: usize,
//! }
//!
//! impl Foo {
//!     /// Opens the card of the settings (`[foo]`, if it has settings of its own).
//!     pub fn open(s: &Settings, _lockstep: bool) -> Result<Foo, BackendOpenError> {
//!         Ok(Foo { counters: [COUNTER_ZERO; MAX_MOTORS], n_motors: s.n_motors })
//!     }
//!
//!     /// Whether the card is there and usable as the settings describe it, keeping and
//!     /// driving nothing: the starter asks before it spawns anything.
//!     pub fn check(s: &Settings, lockstep: bool) -> Result<(), BackendOpenError> {
//!         Foo::open(s, lockstep).map(drop)
//!     }
//! }
//!
//! impl Backend for Foo {
//!     fn name(&self) -> &'static str { "foo" }
//!     fn n_motors(&self) -> usize { self.n_motors }
//!     fn read_inputs(&mut self, inputs: &mut Inputs) -> Result<(), HwFault> {
//!         inputs.counters = self.counters;
//!         Ok(())
//!     }
//!     fn write_dacs(&mut self, _codes: &[i32; MAX_MOTORS]) -> Result<(), HwFault> { Ok(()) }
//!     fn set_amp_enable(&mut self, _motor: usize, _on: bool) -> Result<(), HwFault> { Ok(()) }
//!     fn load_counter(&mut self, motor: usize, raw: u32) -> Result<(), HwFault> {
//!         self.counters[motor] = raw;
//!         Ok(())
//!     }
//!     fn safe_state(&mut self) {}
//!     fn now_ns(&self) -> u64 { qmarc_timer::clock::monotonic_now_ns() }
//! }
//!
//! // Its line in BACKENDS (`backends/mod.rs`).
//! const FOO: BackendEntry = BackendEntry {
//!     // Its variant of `qmarc_config::BackendKind` (`Foo`, named "foo" there); the 626's
//!     // here, so that this example compiles.
//!     kind: BackendKind::S626,
//!     description: "the Foo card",
//!     open: |s, lockstep| Ok(Box::new(Foo::open(s, lockstep)?)),
//!     check: Foo::check,
//!     // A fake of the card's driver for the conformance suite (`conformance::Rig`), or
//!     // None where there is none at hand.
//!     rig: || None,
//! };
//!
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let names = Names { laws: vec!["pidff"], methods: vec!["spline"], any_plugin: false };
//! let toml = "[general]\nn_motors = 1\n\
//!             [[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n";
//! let settings = Settings::parse("q.toml".as_ref(), toml, &names)?;
//! (FOO.check)(&settings, false)?;
//! let mut core = HwCore::new((FOO.open)(&settings, false)?);
//! let read = core.handle(&HwMsg::read_all_encoders());
//! assert!(read.status().is_ok());
//! assert_eq!(read.data[0], 0.0);
//! # Ok(()) }
//! ```

use crate::backend::{Backend, BackendOpenError};
use crate::conformance::Rig;
use qmarc_config::{BackendKind, ConfigLoadError, Mode, Names, RunSpec, Settings};
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
    /// Which it is (`hwserver.backend`, `--backend`: its name).
    pub kind: BackendKind,
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
        kind: BackendKind::Sim,
        description: "the simulated Deltabot: velocity-mode amplifiers, 24-bit counters, limit switches",
        open: |s, lockstep| Ok(Box::new(sim::SimDeltabot::open(s, lockstep)?)),
        check: sim::SimDeltabot::check,
        rig: || Some(Box::new(sim::SimRig::default())),
    },
    BackendEntry {
        kind: BackendKind::S626,
        description: "the Sensoray 626 through the kernel's comedi driver (--device /dev/comediN)",
        open: |s, lockstep| Ok(Box::new(s626::S626::open(s, lockstep)?)),
        check: s626::S626::check,
        rig: || Some(Box::new(s626::FakeRig::default())),
    },
];

/// The registry entry of `kind`.
pub fn backend(kind: BackendKind) -> Option<&'static BackendEntry> {
    BACKENDS.iter().find(|b| b.kind == kind)
}

/// The registry entry of the backend the settings name.
fn entry_of(s: &Settings) -> Result<&'static BackendEntry, BackendOpenError> {
    backend(s.hwserver.backend).ok_or_else(|| BackendOpenError::Unknown {
        name: s.hwserver.backend.to_string(),
        available: BACKENDS.iter().map(|b| b.kind.name()).collect::<Vec<_>>().join(", "),
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
    let names = Names::any();
    Ok(RunSpec {
        settings: Settings::parse("standalone.toml".as_ref(), &text, &names)?,
        mode: Mode::Step,
        deterministic: lockstep,
        unpaced: false,
        unhomed: false,
        iox_prefix: location.prefix.clone(),
        iox_root: location.root.clone(),
        epoch_ns: 0,
    })
}

/// The settings file `toml` (read as `q.toml`) with three motors of unit gains appended: what
/// the backends' unit tests parse, knowing only the backends' names.
#[cfg(test)]
pub(crate) fn test_settings(toml: &str) -> Settings {
    let names = Names::any();
    let motors = "[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n".repeat(3);
    Settings::parse(std::path::Path::new("q.toml"), &format!("{toml}{motors}"), &names).unwrap()
}
