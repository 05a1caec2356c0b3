//! The QMARC settings: `config/qmarc.toml` and the command line, loaded and checked once into
//! one [`Settings`] value, which the starter hands to both children as a [`RunSpec`].
//!
//! The file is parsed into raw structs that keep every value's position, then checked section
//! by section (one module each) into [`Settings`]. Every error names the file, line, column
//! and field (`config/qmarc.toml:31:6: motor[2].kp: ...`); unknown keys are errors. Each
//! default is defined once, in its section's `Default`. The crate knows nothing of the
//! plug-ins: the names it accepts for the law and the trajectory method are given to it
//! ([`Names`], from the registries). Of the hardware it knows which backends there are
//! ([`BackendKind`]), not what they are.
//!
//! ```
//! use qmarc_config::{Names, Settings};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let names = Names { laws: vec!["pidff"], methods: vec!["spline", "pvt"], any_plugin: false };
//! let table = "[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n";
//! let s = Settings::parse("q.toml".as_ref(), &format!("[general]\nn_motors = 1\n{table}"), &names)?;
//! assert_eq!((s.n_motors, s.period_us, s.hwserver.watchdog_periods), (1, 400, 250));
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

mod cell;
mod check;
mod conveyor;
mod error;
mod gather;
mod general;
mod homing;
mod hwserver;
mod jog;
mod motion;
mod motor;
mod overrides;
mod pick;
mod robot;
mod run;
mod s626;
mod sim;
mod source;
mod step;
mod telemetry;
mod timer;
mod trajectory;
mod tune;

pub use cell::{CellSettings, MAX_CELL_NAME, cell_name_problem};
pub use check::{CheckSettings, MAX_CHECK_PULSE_S, MAX_CHECK_VOLTS};
pub use conveyor::{
    CAMERA_BACKENDS, CameraSettings, ConveyorSettings, FrameSource, ImageSettings, MAX_BELT_MM,
    MAX_BELT_MM_S, MAX_SPEED_STEPS, POLARITIES,
};
pub use error::ConfigLoadError;
pub use gather::{GatherFields, GatherSettings};
pub use homing::HomingSettings;
pub use hwserver::{BackendKind, ExplicitTiming, HwServerSettings, HwWait, TimingDefaults};
pub use jog::{AXES, JogSettings, MAX_JOG_COUNTS, MAX_JOG_MM};
pub use motion::{MAX_TARGET_COUNTS, MoveSettings, MoveTarget, TargetError};
pub use motor::{MotorGains, MotorSafety, effective_gains_problem, gains_problem};
pub use overrides::TimingOverrides;
pub use pick::{MAX_DWELL_S, MAX_PICK_MM, PickSettings};
pub use robot::{RobotSettings, WORK_CENTRE_M};
pub use run::{Mode, RunSpec, RunSpecError};
pub use s626::{S626_DIO_CHANNELS, S626Settings};
pub use sim::{DEFAULT_SIM_STATE_FILE, SimPlant, SimSettings};
pub use source::{
    MAX_CONFIG_BYTES, in_exponent_notation, num, read_bounded, read_config, toml_file_error,
};
pub use step::{MAX_STEP_COUNTS, StepSettings};
pub use telemetry::{MAX_TELEMETRY_EVERY, TelemetrySettings};
pub use timer::{TimerMethod, TimerSettings};
pub use trajectory::{DEFAULT_MAX_DURATION_S, TrajectorySettings};
pub use tune::{
    TUNE_OBJECTIVES, TUNE_PARAMS, TuneObjective, TuneParam, TuneSettings, check_params,
};

use qmarc_proto::MAX_MOTORS;
use serde::{Deserialize, Serialize};
use source::Source;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// The names the settings may use, from the registries of the crates that implement them.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct Names {
    /// Servo laws (`general.law`).
    pub laws: Vec<&'static str>,
    /// Trajectory generators that follow a path (`trajectory.method`, `--method`).
    pub methods: Vec<&'static str>,
    /// Accept any law and method name: for a process that runs none of them (the
    /// hwserver's selftest), which cannot know the plug-ins' registry.
    pub any_plugin: bool,
}

impl Names {
    /// The names of a process that runs no plug-in (the hwserver) and so cannot know their
    /// registry: any law and method name is taken ([`Names::any_plugin`]).
    pub fn any() -> Names {
        Names { any_plugin: true, ..Names::default() }
    }
}

/// The checked settings.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Settings {
    /// The file they came from.
    pub source: PathBuf,
    /// Motors driven (1‥[`MAX_MOTORS`]).
    pub n_motors: usize,
    /// Servo period in µs.
    pub period_us: u32,
    /// The servo period the gains were tuned at, µs: gains that act per period are rescaled
    /// to `period_us` ([`Settings::effective_gains`]).
    pub gains_period_us: u32,
    /// Registered name of the servo law.
    pub law: String,
    /// The `pidff` law's scale of the following-error and integral terms of eq. 3-1: PMAC's
    /// Ix08 = 96, kept on them as the thesis' gains need (docs/deltabot.md); 1 reads eq. 3-1
    /// literally.
    pub fe_scale: f64,
    /// Encoder counts per motor revolution (post-quadrature).
    pub counts_per_rev: f64,
    /// Motor revolutions per arm revolution.
    pub gear_ratio: f64,
    /// Timer settings.
    pub timer: TimerSettings,
    /// Data gathering.
    pub gather: GatherSettings,
    /// The step move.
    pub step: StepSettings,
    /// The `run` move.
    pub trajectory: TrajectorySettings,
    /// `[jog]`: moving one motor by hand.
    #[serde(default)]
    pub jog: JogSettings,
    /// `move`: the target of an online move (from the command line, not the file).
    #[serde(default)]
    pub motion: MoveSettings,
    /// `[pick]`: the pick-and-place cycle as a path (`run --method pick`).
    #[serde(default)]
    pub pick: PickSettings,
    /// `[check]`: the open-loop first motion.
    #[serde(default)]
    pub check: CheckSettings,
    /// Homing.
    pub homing: HomingSettings,
    /// Missed periods in a row that end a move (`overrun`).
    pub max_missed_in_row: u64,
    /// The hwserver link.
    pub hwserver: HwServerSettings,
    /// The simulator.
    pub sim: SimSettings,
    /// The Sensoray 626.
    pub s626: S626Settings,
    /// The robot's geometry and joint-count frame (`[robot]`), if the file describes it.
    #[serde(default)]
    pub robot: Option<RobotSettings>,
    /// `[tune]`: `qmarc-starter tune`.
    pub tune: TuneSettings,
    /// `[telemetry]`: the live samples of the loop.
    #[serde(default)]
    pub telemetry: TelemetrySettings,
    /// `[conveyor]`: the belt the robot picks from.
    #[serde(default)]
    pub conveyor: ConveyorSettings,
    /// `[camera]`: the camera upstream of the robot, and the parts it sees.
    #[serde(default)]
    pub camera: CameraSettings,
    /// `[cell]`: the robot in a cell of robots on one belt.
    #[serde(default)]
    pub cell: CellSettings,
    /// Gains of every `[[motor]]` table (at least `n_motors`, at most [`MAX_MOTORS`]).
    pub motors: Vec<MotorGains>,
    /// Limits and homing of every `[[motor]]` table.
    pub safety: Vec<MotorSafety>,
    /// Which backend-dependent values the file set ([`TimingDefaults`]).
    pub explicit: ExplicitTiming,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    general: general::RawGeneral,
    #[serde(default)]
    timer: timer::RawTimer,
    #[serde(default)]
    gather: gather::RawGather,
    #[serde(default)]
    step: step::RawStep,
    #[serde(default)]
    jog: jog::RawJog,
    #[serde(default)]
    pick: pick::RawPick,
    #[serde(default)]
    check: check::RawCheck,
    #[serde(default)]
    trajectory: trajectory::RawTrajectory,
    #[serde(default)]
    homing: homing::RawHoming,
    #[serde(default)]
    safety: hwserver::RawSafety,
    #[serde(default)]
    hwserver: hwserver::RawHwServer,
    #[serde(default)]
    sim: sim::RawSim,
    #[serde(default)]
    s626: s626::RawS626,
    #[serde(default)]
    tune: tune::RawTune,
    #[serde(default)]
    telemetry: telemetry::RawTelemetry,
    #[serde(default)]
    conveyor: conveyor::RawConveyor,
    #[serde(default)]
    camera: conveyor::RawCamera,
    #[serde(default)]
    cell: cell::RawCell,
    #[serde(default)]
    robot: Option<Spanned<robot::RawRobot>>,
    #[serde(default)]
    motor: Vec<Spanned<motor::RawMotor>>,
}

impl RawFile {
    /// Checks the sections in the file's order of importance: the first error is the one
    /// reported.
    fn check(self, src: &Source<'_>, names: &Names) -> Result<Settings, ConfigLoadError> {
        let general = self.general.check(src, names)?;
        let n_motors = general.n_motors;
        let timer = self.timer.check(src)?;
        let gather = self.gather.check(src)?;
        let trajectory = self.trajectory.check(src, names)?;
        let step = self.step.check(src, trajectory.max_duration_s)?;
        let jog = self.jog.check(src, n_motors)?;
        let pick = self.pick.check(src)?;
        let check = self.check.check(src)?;
        let hwserver = self.hwserver.check(src)?;
        self.hwserver.check_spin_cpu(src, &hwserver, &timer)?;
        let sim = self.sim.check(src, n_motors)?;
        let s626 = self.s626.check(src, n_motors, hwserver.backend == BackendKind::S626)?;
        let robot = match &self.robot {
            Some(r) => Some(r.get_ref().check(src, r.span())?),
            None => None,
        };
        if self.motor.len() > MAX_MOTORS {
            return Err(src.invalid(
                self.motor[MAX_MOTORS].span(),
                &format!("motor[{}]", MAX_MOTORS + 1),
                format!("at most {MAX_MOTORS} [[motor]] tables"),
            ));
        }
        if self.motor.len() < n_motors {
            return Err(src.invalid(
                self.general.n_motors_span(),
                "general.n_motors",
                format!(
                    "{n_motors} motors need {n_motors} [[motor]] tables, found {}",
                    self.motor.len()
                ),
            ));
        }
        let mut motors = Vec::with_capacity(self.motor.len());
        let mut safety = Vec::with_capacity(self.motor.len());
        let cx = motor::MotorContext {
            fe_scale: general.fe_scale,
            periods_us: (general.gains_period_us, general.period_us),
            encoder_max_counts_per_s: hwserver.max_counts_per_s,
        };
        for (i, m) in self.motor.iter().enumerate() {
            let (g, s) = motor::check_motor(src, m, i + 1, cx)?;
            motors.push(g);
            safety.push(s);
        }
        let homing = self.homing.check(src)?;
        let fastest = homing.velocity_counts_per_s.max(homing.creep_counts_per_s);
        if let Some((m, s)) = safety
            .iter()
            .enumerate()
            .take(n_motors)
            .find(|(_, s)| fastest > s.max_velocity_counts_per_s)
        {
            return Err(src.invalid(
                self.homing.velocity_span(),
                "homing.velocity_counts_per_s",
                format!(
                    "homing would move motor {} at {} counts/s, faster than its \
                     max_velocity_counts_per_s = {}",
                    m + 1,
                    source::num(fastest),
                    source::num(s.max_velocity_counts_per_s)
                ),
            ));
        }
        let tune = self.tune.check(src)?;
        let telemetry = self.telemetry.check(src)?;
        let conveyor = self.conveyor.check(src, &s626.counter_channels)?;
        let camera = self.camera.check(src, &conveyor)?;
        let cell = self.cell.check(src)?;
        let longest: f64 = safety.iter().map(|s| homing.longest_s(s.home_offset_counts)).sum();
        if longest > trajectory.max_duration_s {
            return Err(src.invalid(
                self.homing.velocity_span(),
                "homing.velocity_counts_per_s",
                format!(
                    "homing could take {longest:.0} s, longer than the longest move \
                     (trajectory.max_duration_s = {} s): raise the homing speeds or lower \
                     max_travel_counts",
                    trajectory.max_duration_s
                ),
            ));
        }
        Ok(Settings {
            source: src.path.to_path_buf(),
            n_motors,
            period_us: general.period_us,
            gains_period_us: general.gains_period_us,
            law: general.law,
            fe_scale: general.fe_scale,
            counts_per_rev: general.counts_per_rev,
            gear_ratio: general.gear_ratio,
            timer,
            gather,
            step,
            trajectory,
            jog,
            motion: MoveSettings::default(),
            pick,
            check,
            homing,
            max_missed_in_row: self.safety.check(src, hwserver.backend)?,
            sim,
            explicit: ExplicitTiming {
                watchdog_periods: self.hwserver.sets_watchdog(),
                max_missed_in_row: self.safety.sets_max_missed(),
            },
            hwserver,
            s626,
            robot,
            tune,
            telemetry,
            conveyor,
            camera,
            cell,
            motors,
            safety,
        })
    }
}

impl Settings {
    /// Reads (at most [`MAX_CONFIG_BYTES`]) and checks `path`.
    pub fn load(path: &Path, names: &Names) -> Result<Settings, ConfigLoadError> {
        Settings::parse(path, &read_config(path)?, names)
    }

    /// Checks `text`, which came from `path` (a leading byte-order mark is dropped).
    pub fn parse(path: &Path, text: &str, names: &Names) -> Result<Settings, ConfigLoadError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let src = Source { path, text };
        let raw: RawFile = toml::from_str(text).map_err(|e| src.toml_error(&e))?;
        raw.check(&src, names)
    }

    /// The servo period in ns.
    pub fn period_ns(&self) -> u64 {
        u64::from(self.period_us) * 1_000
    }

    /// The servo period in s.
    pub fn period_s(&self) -> f64 {
        f64::from(self.period_us) * 1e-6
    }

    /// The gains of `motor` at the servo period in use. The law works in counts per period:
    /// a velocity in counts/period scales with T, an acceleration with T², a sum of errors
    /// with 1/T. Gains tuned at `gains_period_us` = T₀ keep the loop they were tuned for at
    /// `period_us` = T when Kd and Kvff are multiplied by T₀/T, Kaff by (T₀/T)² and Ki by
    /// T/T₀; Kp and the notch (which acts per sample) are kept.
    pub fn effective_gains(&self, motor: usize) -> MotorGains {
        motor::rescaled(self.motors[motor], (self.gains_period_us, self.period_us))
    }

    /// True when the gains are rescaled ([`Settings::effective_gains`]).
    pub fn gains_rescaled(&self) -> bool {
        self.gains_period_us != self.period_us
    }

    /// The robot in its joint-count frame, if `[robot]` describes it and three motors are
    /// driven (the Delta has three arms).
    pub fn robot(&self) -> Option<qmarc_kinematics::Robot> {
        let r = self.robot.filter(|_| self.n_motors == qmarc_kinematics::ARMS)?;
        Some(r.robot(self.counts_per_rad()))
    }

    /// Encoder counts per radian of arm rotation: counts_per_rev · gear_ratio / 2π.
    pub fn counts_per_rad(&self) -> f64 {
        self.counts_per_rev * self.gear_ratio / std::f64::consts::TAU
    }

    /// Overrides the servo period (`--period-us`).
    pub fn set_period_us(&mut self, period_us: u32) -> Result<(), ConfigLoadError> {
        let flag = "--period-us";
        general::check_period(i64::from(period_us))
            .map_err(|message| ConfigLoadError::Override { flag, message })?;
        for (m, g) in self.motors.iter().enumerate().take(self.n_motors) {
            let periods = (self.gains_period_us, period_us);
            if let Some((key, why)) = motor::effective_gains_problem(g, self.fe_scale, periods) {
                let file = self.source.display();
                let message = format!("motor[{}].{key} of {file}: {why}", m + 1);
                return Err(ConfigLoadError::Override { flag, message });
            }
        }
        self.period_us = period_us;
        Ok(())
    }

    /// Overrides the gathering interval (`--gather-every`).
    pub fn set_gather_every(&mut self, every: u32) -> Result<(), ConfigLoadError> {
        if every == 0 {
            return Err(ConfigLoadError::Override {
                flag: "--gather-every",
                message: "must be at least 1".into(),
            });
        }
        self.gather.every = every;
        Ok(())
    }

    /// Overrides the number of motors (`--motors`).
    pub fn set_n_motors(&mut self, n: usize) -> Result<(), ConfigLoadError> {
        let flag = "--motors";
        if !(1..=MAX_MOTORS).contains(&n) {
            return Err(ConfigLoadError::Override {
                flag,
                message: format!("must be 1‥{MAX_MOTORS}, found {n}"),
            });
        }
        if n > self.motors.len() {
            return Err(ConfigLoadError::Override {
                flag,
                message: format!(
                    "{n} motors need {n} [[motor]] tables in {}, found {}",
                    self.source.display(),
                    self.motors.len()
                ),
            });
        }
        if self.jog.motor > n {
            return Err(ConfigLoadError::Override {
                flag,
                message: format!(
                    "jog.motor = {} in {} is not one of {n} motors",
                    self.jog.motor,
                    self.source.display()
                ),
            });
        }
        self.n_motors = n;
        self.check_s626_wiring(flag)
    }

    /// Overrides the hardware backend (`--backend`); the timing bounds the file does not set
    /// become the new backend's defaults.
    pub fn set_backend(&mut self, backend: &str) -> Result<(), ConfigLoadError> {
        let backend: BackendKind = backend
            .parse()
            .map_err(|message| ConfigLoadError::Override { flag: "--backend", message })?;
        self.hwserver.backend = backend;
        let d = TimingDefaults::of(backend);
        if !self.explicit.watchdog_periods {
            self.hwserver.watchdog_periods = d.watchdog_periods;
        }
        if !self.explicit.max_missed_in_row {
            self.max_missed_in_row = d.max_missed_in_row;
        }
        self.check_s626_wiring("--backend")
    }

    /// Overrides the jog (`--motor`, `--counts`).
    pub fn set_jog(&mut self, motor: usize, counts: i64) -> Result<(), ConfigLoadError> {
        if !(1..=self.n_motors).contains(&motor) {
            return Err(ConfigLoadError::Override {
                flag: "--motor",
                message: format!("must be a motor in use, 1‥{}, found {motor}", self.n_motors),
            });
        }
        jog::check_jog_counts(counts)
            .map_err(|message| ConfigLoadError::Override { flag: "--counts", message })?;
        self.jog.motor = motor;
        self.jog.counts = counts;
        Ok(())
    }

    /// Makes the jog a Cartesian one (`--axis x|y|z`, `--mm D`): the effector along that
    /// axis by `mm` (default `jog.mm`), a straight line; the `[robot]` table must describe
    /// the robot.
    pub fn set_jog_axis(&mut self, axis: &str, mm: Option<f64>) -> Result<(), ConfigLoadError> {
        let refused = |flag, message| ConfigLoadError::Override { flag, message };
        let a = jog::AXES
            .iter()
            .position(|n| *n == axis)
            .ok_or_else(|| refused("--axis", format!("`{axis}` is not an axis: x, y or z")))?;
        if self.robot().is_none() {
            return Err(refused(
                "--axis",
                format!(
                    "{} has no [robot] table for 3 motors: a Cartesian jog needs the Delta's \
                     geometry",
                    self.source.display()
                ),
            ));
        }
        let mm = mm.unwrap_or(self.jog.mm);
        jog::check_jog_mm(mm).map_err(|m| refused("--mm", m))?;
        self.jog.axis = Some(a);
        self.jog.mm = mm;
        Ok(())
    }

    /// Overrides the knot file (`--knots`).
    pub fn set_knots(&mut self, path: &Path) {
        self.trajectory.knots = Some(path.to_path_buf());
    }

    /// Overrides the trajectory method (`--method`).
    pub fn set_method(&mut self, method: &str, names: &Names) -> Result<(), ConfigLoadError> {
        if !names.any_plugin && !names.methods.contains(&method) {
            return Err(ConfigLoadError::Override {
                flag: "--method",
                message: format!(
                    "unknown trajectory method `{method}`; registered: {}",
                    names.methods.join(", ")
                ),
            });
        }
        self.trajectory.method = method.to_string();
        Ok(())
    }

    /// Overrides the step size (`--size`).
    pub fn set_step_size(&mut self, size: i64) -> Result<(), ConfigLoadError> {
        step::check_step_size(size)
            .map_err(|message| ConfigLoadError::Override { flag: "--size", message })?;
        self.step.size = size;
        Ok(())
    }

    /// Overrides the step duration (`--duration`).
    pub fn set_step_duration(&mut self, duration_s: f64) -> Result<(), ConfigLoadError> {
        step::check_duration(duration_s, self.trajectory.max_duration_s)
            .map_err(|message| ConfigLoadError::Override { flag: "--duration", message })?;
        self.step.duration_s = duration_s;
        Ok(())
    }
}

#[cfg(test)]
mod tests;
