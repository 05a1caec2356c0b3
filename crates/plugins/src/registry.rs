//! The registry: every trajectory generator and servo law by name. Adding one is one new
//! type plus one line here; the settings file, the command line and the console list and
//! choose from these tables (see `docs/extending.md`).

use crate::check::Check;
use crate::grip::Here;
use crate::homing::Homing;
use crate::linear::LinearMove;
use crate::moveto::Jog;
use crate::online::OnlineMove;
use crate::pick::PickCycle;
use crate::pidff::PidFf;
use crate::pvt::Pvt;
use crate::source::TrajBuildError;
use crate::spline::CubicSpline;
use crate::step::Step;
use qmarc_config::Settings;
use qmarc_controller::law::ServoLaw;
use qmarc_controller::traj::TrajectoryGenerator;

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

/// What a generator follows, which says where the command line and the console offer it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum GeneratorKind {
    /// A path read from a knot file (`run --method`, which needs `--knots`).
    KnotPath,
    /// A path of its own from the settings (`step`, also a `run --method`).
    OwnPath,
    /// A mode of its own (`home`, `check`, `jog`, `move`, `linear`): never `run`'s.
    Mode,
}

impl GeneratorEntry {
    /// It reads a knot file.
    pub fn needs_knots(&self) -> bool {
        self.kind == GeneratorKind::KnotPath
    }
}

/// A registered trajectory generator.
#[derive(Clone, Copy)]
pub struct GeneratorEntry {
    /// Name (`step`, or `trajectory.method` / `--method` for `run`).
    pub name: &'static str,
    /// One line for lists.
    pub description: &'static str,
    /// What it follows: a path `run` names (from a knot file, or `step`'s own), or a mode
    /// of its own.
    pub kind: GeneratorKind,
    /// Builds the generator from validated settings; reads and checks a knot file if one is
    /// named (streams are read when the move starts).
    pub build: fn(&Settings) -> Result<Box<dyn TrajectoryGenerator>, TrajBuildError>,
}

/// Every servo law.
pub const LAWS: &[LawEntry] = &[LawEntry {
    name: "pidff",
    description: "PID + velocity/acceleration feed-forward, PMAC form, with notch (thesis eq. 3-1, 3-2)",
    build: |s| Box::new(PidFf::from_settings(s)),
}];

/// Every trajectory generator.
pub const GENERATORS: &[GeneratorEntry] = &[
    GeneratorEntry {
        name: "step",
        description: "ideal step of [step] size on every motor, held for [step] duration",
        kind: GeneratorKind::OwnPath,
        build: |s| Ok(Box::new(Step::from_settings(s)?)),
    },
    GeneratorEntry {
        name: "spline",
        description: "offline natural cubic spline through time/position knots (thesis 3.12.1)",
        kind: GeneratorKind::KnotPath,
        build: |s| Ok(Box::new(CubicSpline::from_settings(s)?)),
    },
    GeneratorEntry {
        name: "home",
        description: "homing on the top limit switches, one motor at a time (thesis 3.10.1.1)",
        kind: GeneratorKind::Mode,
        build: |s| Ok(Box::new(Homing::from_settings(s))),
    },
    GeneratorEntry {
        name: "check",
        description: "the open-loop first motion: [check] volts on each motor in turn, watched",
        kind: GeneratorKind::Mode,
        build: |s| Ok(Box::new(Check::from_settings(s))),
    },
    GeneratorEntry {
        name: "jog",
        description: "one motor by [jog] counts, jerk-limited from rest to rest (Ruckig)",
        kind: GeneratorKind::Mode,
        build: |s| match s.jog.axis {
            Some(_) => Ok(Box::new(LinearMove::jog(s)?)),
            None => Ok(Box::new(Jog::from_settings(s)?)),
        },
    },
    GeneratorEntry {
        name: "move",
        description: "to a target from where the motors are, jerk-limited and time-optimal (online Ruckig)",
        kind: GeneratorKind::Mode,
        build: |s| match s.motion.target.counts() {
            // `move --grip on|off` alone: where the robot is.
            [] if s.motion.grip.is_some() => Ok(crate::grip::at_end(s, Box::<Here>::default())),
            _ => Ok(crate::grip::at_end(s, Box::new(OnlineMove::from_settings(s)?))),
        },
    },
    GeneratorEntry {
        name: "linear",
        description: "to a point along a straight line, jerk-limited, every joint within its limits",
        kind: GeneratorKind::Mode,
        build: |s| Ok(crate::grip::at_end(s, Box::new(LinearMove::from_settings(s)?))),
    },
    GeneratorEntry {
        name: "pvt",
        description: "online position-velocity-time cubics, from a file or a stream (thesis 3.12.2)",
        kind: GeneratorKind::KnotPath,
        build: |s| Ok(Box::new(Pvt::from_settings(s)?)),
    },
    GeneratorEntry {
        name: "pick",
        description: "the pick-and-place cycle of [pick]: time-optimal jerk-limited legs at the motors' limits",
        kind: GeneratorKind::OwnPath,
        build: |s| Ok(Box::new(PickCycle::from_settings(s)?)),
    },
];

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

/// The names the settings accept from the plug-ins: the laws and the path generators (the
/// settings crate knows none of them; they are handed to it from here).
pub fn names() -> qmarc_config::Names {
    qmarc_config::Names { laws: law_names(), methods: path_generator_names(), any_plugin: false }
}

/// Names of the generators `run` accepts: every one that follows a path (not a mode of its
/// own: homing, jog, the check, a move to a target).
pub fn path_generator_names() -> Vec<&'static str> {
    GENERATORS.iter().filter(|e| e.kind != GeneratorKind::Mode).map(|e| e.name).collect()
}
