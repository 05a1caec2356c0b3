//! The registry: every trajectory generator and servo law by name. Adding one is one new
//! type plus one line here; the settings file, the command line and the console list and
//! choose from these tables.

use crate::config::Settings;
use crate::law::{PidFf, ServoLaw};
use crate::traj::{Step, TrajectoryGenerator};

/// A registered servo law.
#[derive(Clone, Copy)]
pub struct LawEntry {
    /// Name used in `general.law`.
    pub name: &'static str,
    /// One line for lists.
    pub description: &'static str,
    /// Builds the law from validated settings.
    pub build: fn(&Settings) -> Box<dyn ServoLaw>,
}

/// A registered trajectory generator.
#[derive(Clone, Copy)]
pub struct GeneratorEntry {
    /// Name (the command-line mode or `trajectory.method`).
    pub name: &'static str,
    /// One line for lists.
    pub description: &'static str,
    /// Builds the generator from validated settings.
    pub build: fn(&Settings) -> Box<dyn TrajectoryGenerator>,
}

/// Every servo law.
pub const LAWS: &[LawEntry] = &[LawEntry {
    name: "pidff",
    description: "PID + velocity/acceleration feed-forward, PMAC form, with notch (thesis eq. 3-1, 3-2)",
    build: |s| Box::new(PidFf::from_settings(s)),
}];

/// Every trajectory generator.
pub const GENERATORS: &[GeneratorEntry] = &[GeneratorEntry {
    name: "step",
    description: "ideal step of [step] size on every motor, held for [step] duration",
    build: |s| Box::new(Step::from_settings(s)),
}];

/// The law named `name`.
pub fn law(name: &str) -> Option<&'static LawEntry> {
    LAWS.iter().find(|e| e.name == name)
}

/// The generator named `name`.
pub fn generator(name: &str) -> Option<&'static GeneratorEntry> {
    GENERATORS.iter().find(|e| e.name == name)
}

/// Names of every law.
pub fn law_names() -> Vec<&'static str> {
    LAWS.iter().map(|e| e.name).collect()
}

/// Names of every generator.
pub fn generator_names() -> Vec<&'static str> {
    GENERATORS.iter().map(|e| e.name).collect()
}
