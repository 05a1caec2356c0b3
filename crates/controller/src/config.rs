//! The settings file (`config/qmarc.toml`): its model, defaults and validation.
//!
//! The file is parsed into raw structs that keep every value's position, then checked once
//! into [`Settings`]. Every error names the file, line, column and field
//! (`config/qmarc.toml:31:6: motor[2].kp: ...`); unknown keys are errors. Nothing here runs
//! after a motor is enabled. Missing sections and keys take the thesis defaults, except the
//! gains: every motor in use needs its `[[motor]]` table with all five gains.

use crate::registry;
use qmarc_proto::MAX_MOTORS;
use qmarc_timer::TickerKind;
use serde::Deserialize;
use std::ops::Range;
use std::path::{Path, PathBuf};
use toml::Spanned;

/// The settings file could not be loaded.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigLoadError {
    /// The file could not be read. (The OS error is part of the message, not a source: each
    /// error is printed on one line, its reason once.)
    #[error("{file}: cannot read the settings file: {reason}")]
    Read {
        /// The file.
        file: PathBuf,
        /// Why.
        reason: std::io::Error,
    },
    /// The file is larger than a settings file may be.
    #[error("{file}: the file has more than {limit} bytes, the most a settings file may have")]
    TooLarge {
        /// The file.
        file: PathBuf,
        /// [`MAX_CONFIG_BYTES`].
        limit: u64,
    },
    /// A value is missing, unknown, of the wrong type or out of range.
    #[error("{file}:{line}:{column}: {field}: {message}")]
    Invalid {
        /// The file.
        file: PathBuf,
        /// 1-based line.
        line: usize,
        /// 1-based column.
        column: usize,
        /// Dotted path of the field, e.g. `motor[2].kp` (motors 1-based).
        field: String,
        /// What is wrong and what is expected.
        message: String,
    },
    /// A command-line override is out of range.
    #[error("{flag}: {message}")]
    Override {
        /// The flag, e.g. `--period-us`.
        flag: &'static str,
        /// What is wrong.
        message: String,
    },
}

/// Gains of one motor for the PID feed-forward law (thesis eq. 3-1, PMAC Ix30–Ix35) and its
/// notch (eq. 3-2, PMAC Ix36–Ix39).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct MotorGains {
    /// Proportional gain Kp.
    pub kp: f64,
    /// Integral gain Ki.
    pub ki: f64,
    /// Derivative gain Kd (on the actual velocity).
    pub kd: f64,
    /// Velocity feed-forward gain Kvff.
    pub kvff: f64,
    /// Acceleration feed-forward gain Kaff.
    pub kaff: f64,
    /// Notch coefficients `[n1, n2, d1, d2]`; all zero = no notch.
    pub notch: [f64; 4],
}

/// Limits and homing of one motor (thesis 3.10; PMAC Ixx11 for the instantaneous limit).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MotorSafety {
    /// Software position limits `[min, max]`, counts in the homed frame (active once homed).
    pub soft_limits: [f64; 2],
    /// Largest |command − actual|, counts, before the move is stopped.
    pub max_following_error_counts: f64,
    /// Largest |Σ (command − actual)| over the move (eq. 3-1's IE), counts.
    pub max_integrated_error_counts: f64,
    /// Homing: where home is, counts from the top switch (away from it).
    pub home_offset_counts: f64,
    /// Homing: the direction of the top switch, −1 or +1 counts.
    pub top_direction: f64,
}

impl Default for MotorSafety {
    fn default() -> MotorSafety {
        MotorSafety {
            soft_limits: [-9_000.0, 10_000.0],
            max_following_error_counts: 2_000.0,
            max_integrated_error_counts: 200_000.0,
            home_offset_counts: 9_500.0,
            top_direction: -1.0,
        }
    }
}

/// How homing moves (thesis 3.10.1.1).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HomingSettings {
    /// Speed toward the top switch and to the home offset, counts/s.
    pub velocity_counts_per_s: f64,
    /// Speed backing off the switch, counts/s.
    pub creep_counts_per_s: f64,
    /// The switch must clear within this many counts of backing off (thesis: 10).
    pub clear_within_counts: f64,
    /// The switch must be found within this travel, counts.
    pub max_travel_counts: f64,
    /// Time each motor rests at home before the next one starts, s.
    pub settle_s: f64,
}

/// Timer and real-time priorities.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimerSettings {
    /// How the servo thread waits.
    pub method: TickerKind,
    /// SCHED_FIFO priority of the servo thread; 0 = SCHED_OTHER.
    pub servo_priority: i32,
    /// SCHED_FIFO priority of the hwserver; 0 = SCHED_OTHER.
    pub hwserver_priority: i32,
    /// Lock all memory of both processes.
    pub lock_memory: bool,
}

/// Data gathering (thesis 3.4, 4.2).
#[derive(Debug, Clone, PartialEq)]
pub struct GatherSettings {
    /// Gather every N-th servo cycle.
    pub every: u32,
    /// Directory the data files go to.
    pub out_dir: PathBuf,
    /// Which fields go into the files (thesis 3.4: time, DAC, command, actual position).
    pub fields: GatherFields,
}

/// Which per-cycle fields the data files carry; `cycle` is always there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GatherFields {
    /// `time_s`.
    pub time: bool,
    /// `cmdM`.
    pub cmd: bool,
    /// `actM`.
    pub act: bool,
    /// `dacM`.
    pub dac: bool,
}

impl Default for GatherFields {
    fn default() -> GatherFields {
        GatherFields { time: true, cmd: true, act: true, dac: true }
    }
}

impl GatherFields {
    /// The names used in `gather.fields`.
    pub const NAMES: [&'static str; 4] = ["time", "cmd", "act", "dac"];

    /// Parses a list of names; the error names the first unknown one.
    pub fn from_names<'a>(
        names: impl IntoIterator<Item = &'a str>,
    ) -> Result<GatherFields, String> {
        let mut f = GatherFields { time: false, cmd: false, act: false, dac: false };
        for n in names {
            match n {
                "time" => f.time = true,
                "cmd" => f.cmd = true,
                "act" => f.act = true,
                "dac" => f.dac = true,
                other => {
                    return Err(format!(
                        "unknown field `{other}`: the fields are time, cmd, act, dac"
                    ));
                }
            }
        }
        Ok(f)
    }

    /// The names of the selected fields.
    pub fn names(&self) -> Vec<&'static str> {
        let on = [self.time, self.cmd, self.act, self.dac];
        GatherFields::NAMES.iter().zip(on).filter(|(_, on)| *on).map(|(n, _)| *n).collect()
    }
}

/// The step move (thesis 3.4 "Step Motor").
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StepSettings {
    /// Step size in counts, applied to every motor.
    pub size: i64,
    /// Duration of the move in s.
    pub duration_s: f64,
}

/// The `run` move (thesis 3.12, A.2.3).
#[derive(Debug, Clone, PartialEq)]
pub struct TrajectorySettings {
    /// Longest move, s: a knot file's path, a stream's, a step (it bounds every count and
    /// allocation that follows from a time).
    pub max_duration_s: f64,
    /// Registered generator that reads knots (`spline`, `pvt`).
    pub method: String,
    /// Knot file; `-` is standard input. `None` until given.
    pub knots: Option<PathBuf>,
    /// The path must start within this many counts of where each motor is.
    pub start_tolerance_counts: f64,
    /// A stream's first knots must arrive within this many seconds.
    pub stream_wait_s: f64,
    /// When a stream runs dry: hold the last command this long, then disable, ms.
    pub starve_hold_ms: f64,
    /// When a path ends (`step` and `run`): hold its last command with the loop closed this
    /// long before disabling, s.
    pub settle_s: f64,
}

/// The link to the hardware server.
#[derive(Debug, Clone, PartialEq)]
pub struct HwServerSettings {
    /// Backend name (`sim`).
    pub backend: String,
    /// Controller silence, in periods, after which the hwserver disables everything.
    pub watchdog_periods: u32,
    /// A response later than this many periods makes the controller check whether the
    /// hwserver process is still alive.
    pub deadline_periods: u32,
    /// No response within this many periods means the hwserver is lost.
    pub response_timeout_periods: u32,
    /// Fastest an encoder can physically count, counts/s; a larger jump is an encoder fault.
    pub max_counts_per_s: f64,
}

/// The simulated Deltabot (`../shared/notes/deltabot.md`; the geometry is an assumption).
#[derive(Debug, Clone, PartialEq)]
pub struct SimSettings {
    /// Amplifier gain, counts/s per volt.
    pub kv: f64,
    /// Velocity lag of an enabled amplifier, s.
    pub tau_s: f64,
    /// Coasting time constant of a disabled motor, s.
    pub coast_tau_s: f64,
    /// Start position per motor, counts.
    pub start_counts: Vec<f64>,
    /// Top limit switch position, counts.
    pub top_switch_counts: f64,
    /// Bottom limit switch position, counts.
    pub bottom_switch_counts: f64,
    /// The robot starts homed (see `hwserver::SimParams::homed`).
    pub homed: bool,
    /// Offset of an unhomed counter frame, counts.
    pub counter_offset: i64,
    /// Fault injection: this motor (1-based) does not move.
    pub stall_motor: Option<usize>,
    /// Fault injection: this motor's (1-based) top switch sticks once tripped.
    pub stuck_top_motor: Option<usize>,
    /// Where the simulator writes its event log when it ends.
    pub events_file: Option<PathBuf>,
    /// Where the simulator keeps its homed frame between runs; `None`: nowhere.
    pub state_file: Option<PathBuf>,
}

/// The checked settings.
#[derive(Debug, Clone, PartialEq)]
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
    /// Homing.
    pub homing: HomingSettings,
    /// Missed periods in a row that end a move (`overrun`).
    pub max_missed_in_row: u64,
    /// The hwserver link.
    pub hwserver: HwServerSettings,
    /// The simulator.
    pub sim: SimSettings,
    /// Gains of every `[[motor]]` table (at least `n_motors`, at most [`MAX_MOTORS`]).
    pub motors: Vec<MotorGains>,
    /// Limits and homing of every `[[motor]]` table.
    pub safety: Vec<MotorSafety>,
    /// Which backend-dependent values the file set ([`TimingDefaults`]).
    pub explicit: ExplicitTiming,
}

/// Which of the [`TimingDefaults`] the settings file set itself.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ExplicitTiming {
    /// `hwserver.watchdog_periods` is in the file.
    pub watchdog_periods: bool,
    /// `safety.max_missed_in_row` is in the file.
    pub max_missed_in_row: bool,
}

impl Settings {
    /// The rules knot files are checked by: the motors driven, the longest path.
    pub fn knot_rules(&self) -> crate::knots::KnotRules {
        crate::knots::KnotRules::new(self.n_motors).max_duration_s(self.trajectory.max_duration_s)
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
        let g = self.motors[motor];
        let r = f64::from(self.gains_period_us) / f64::from(self.period_us);
        MotorGains { ki: g.ki / r, kd: g.kd * r, kvff: g.kvff * r, kaff: g.kaff * r * r, ..g }
    }

    /// True when the gains are rescaled ([`Settings::effective_gains`]).
    pub fn gains_rescaled(&self) -> bool {
        self.gains_period_us != self.period_us
    }

    /// Encoder counts per radian of arm rotation: counts_per_rev · gear_ratio / 2π.
    pub fn counts_per_rad(&self) -> f64 {
        self.counts_per_rev * self.gear_ratio / std::f64::consts::TAU
    }

    /// Reads (at most [`MAX_CONFIG_BYTES`]) and checks `path`.
    pub fn load(path: &Path) -> Result<Settings, ConfigLoadError> {
        Settings::parse(path, &read_config(path)?)
    }

    /// Checks `text`, which came from `path` (a leading byte-order mark is dropped).
    pub fn parse(path: &Path, text: &str) -> Result<Settings, ConfigLoadError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let src = Source { path, text };
        let raw: RawFile = toml::from_str(text).map_err(|e| src.toml_error(&e))?;
        raw.check(&src)
    }

    /// Overrides the servo period (`--period-us`).
    pub fn set_period_us(&mut self, period_us: u32) -> Result<(), ConfigLoadError> {
        check_period(period_us)
            .map_err(|message| ConfigLoadError::Override { flag: "--period-us", message })?;
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
        self.n_motors = n;
        Ok(())
    }

    /// Overrides the hardware backend (`--backend`).
    pub fn set_backend(&mut self, backend: &str) -> Result<(), ConfigLoadError> {
        check_backend(backend)
            .map_err(|message| ConfigLoadError::Override { flag: "--backend", message })?;
        self.hwserver.backend = backend.to_string();
        let d = TimingDefaults::of(backend);
        if !self.explicit.watchdog_periods {
            self.hwserver.watchdog_periods = d.watchdog_periods;
        }
        if !self.explicit.max_missed_in_row {
            self.max_missed_in_row = d.max_missed_in_row;
        }
        Ok(())
    }

    /// Overrides the knot file (`--knots`).
    pub fn set_knots(&mut self, path: &Path) {
        self.trajectory.knots = Some(path.to_path_buf());
    }

    /// Overrides the trajectory method (`--method`).
    pub fn set_method(&mut self, method: &str) -> Result<(), ConfigLoadError> {
        check_method(method)
            .map_err(|message| ConfigLoadError::Override { flag: "--method", message })?;
        self.trajectory.method = method.to_string();
        Ok(())
    }

    /// Overrides the step size (`--size`).
    pub fn set_step_size(&mut self, size: i64) -> Result<(), ConfigLoadError> {
        check_step_size(size)
            .map_err(|message| ConfigLoadError::Override { flag: "--size", message })?;
        self.step.size = size;
        Ok(())
    }

    /// Overrides the step duration (`--duration`).
    pub fn set_step_duration(&mut self, duration_s: f64) -> Result<(), ConfigLoadError> {
        check_duration(duration_s, self.trajectory.max_duration_s)
            .map_err(|message| ConfigLoadError::Override { flag: "--duration", message })?;
        self.step.duration_s = duration_s;
        Ok(())
    }
}

/// Where the simulated robot keeps its homed frame between runs by default: on the tmpfs
/// `/dev/shm`, which a reboot clears.
pub const DEFAULT_SIM_STATE_FILE: &str = "/dev/shm/qmarc-sim.state";

/// Largest settings file, bytes.
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;

/// Reads the settings file `path`, refusing more than [`MAX_CONFIG_BYTES`] (`/dev/zero`
/// included) and text that is not UTF-8.
pub fn read_config(path: &Path) -> Result<String, ConfigLoadError> {
    use std::io::Read;
    let file = || path.to_path_buf();
    let mut raw = Vec::new();
    std::fs::File::open(path)
        .and_then(|f| f.take(MAX_CONFIG_BYTES + 1).read_to_end(&mut raw))
        .map_err(|reason| ConfigLoadError::Read { file: file(), reason })?;
    if raw.len() as u64 > MAX_CONFIG_BYTES {
        return Err(ConfigLoadError::TooLarge { file: file(), limit: MAX_CONFIG_BYTES });
    }
    String::from_utf8(raw).map_err(|e| ConfigLoadError::Read {
        file: file(),
        reason: std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()),
    })
}
/// Largest step, counts.
pub const MAX_STEP_COUNTS: i64 = 1 << 23;

fn check_period(us: u32) -> Result<(), String> {
    if (100..=100_000).contains(&us) {
        Ok(())
    } else {
        Err(format!("servo period must be 100‥100000 µs, found {us}"))
    }
}

/// The hardware backends `qmarc-hwserver` has.
pub const BACKENDS: [&str; 1] = ["sim"];

/// Timing bounds whose defaults depend on the backend. Real hardware keeps the tight bounds a
/// PREEMPT_RT machine meets (thesis 4.2; PMAC and Mesa watchdogs are a few periods). The
/// simulated robot runs on ordinary desktops and VMs, whose host stalls reach tens of ms
/// (`../shared/notes/realtime-linux.md`): nothing physical is at stake there, so its bounds
/// ride those out. A value set in the file or on the command line holds for every backend.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct TimingDefaults {
    /// `hwserver.watchdog_periods`.
    pub watchdog_periods: u32,
    /// `safety.max_missed_in_row`.
    pub max_missed_in_row: u64,
}

impl TimingDefaults {
    /// On real hardware: 10 periods (4 ms at 400 µs) and 25 periods (10 ms).
    pub const HARDWARE: TimingDefaults =
        TimingDefaults { watchdog_periods: 10, max_missed_in_row: 25 };
    /// On the simulated robot: 250 periods (100 ms at 400 µs) for both.
    pub const SIMULATED: TimingDefaults =
        TimingDefaults { watchdog_periods: 250, max_missed_in_row: 250 };

    /// The defaults of `backend`.
    pub fn of(backend: &str) -> TimingDefaults {
        if backend == "sim" { TimingDefaults::SIMULATED } else { TimingDefaults::HARDWARE }
    }
}

fn check_backend(backend: &str) -> Result<(), String> {
    if BACKENDS.contains(&backend) {
        Ok(())
    } else {
        Err(format!("unknown backend `{backend}`; available: {}", BACKENDS.join(", ")))
    }
}

fn check_method(method: &str) -> Result<(), String> {
    match registry::generator(method) {
        Some(g) if g.name != "home" => Ok(()),
        _ => Err(format!(
            "unknown trajectory method `{method}`; registered: {}",
            registry::path_generator_names().join(", ")
        )),
    }
}

fn check_step_size(size: i64) -> Result<(), String> {
    if size.abs() <= MAX_STEP_COUNTS {
        Ok(())
    } else {
        Err(format!("step size must be within ±{MAX_STEP_COUNTS} counts, found {size}"))
    }
}

fn check_duration(s: f64, max: f64) -> Result<(), String> {
    if s.is_finite() && s > 0.0 && s <= max {
        Ok(())
    } else {
        Err(format!("duration must be > 0 and ≤ {max} s (trajectory.max_duration_s), found {s}"))
    }
}

/// The text of the file, for turning byte offsets into lines and fields.
struct Source<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Source<'_> {
    fn line_col(&self, offset: usize) -> (usize, usize) {
        let before = &self.text[..offset.min(self.text.len())];
        let line = before.matches('\n').count() + 1;
        let column = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
        (line, column)
    }

    fn invalid(
        &self,
        span: Range<usize>,
        field: &str,
        message: impl Into<String>,
    ) -> ConfigLoadError {
        let (line, column) = self.line_col(span.start);
        ConfigLoadError::Invalid {
            file: self.path.to_path_buf(),
            line,
            column,
            field: field.to_string(),
            message: message.into(),
        }
    }

    /// The dotted field path at `offset`: the enclosing table header (with the 1-based
    /// index of an array of tables) and the key on that line.
    fn field_at(&self, offset: usize) -> String {
        let mut table = String::new();
        let mut counts: Vec<(String, usize)> = Vec::new();
        let mut line_start = 0;
        for line in self.text.split_inclusive('\n') {
            if line_start > offset {
                break;
            }
            let t = line.trim();
            let is_array = t.starts_with("[[");
            if let Some(name) = t
                .strip_prefix("[[")
                .and_then(|r| r.split("]]").next())
                .or_else(|| t.strip_prefix('[').and_then(|r| r.split(']').next()))
            {
                let name = name.trim().to_string();
                table = if is_array {
                    let n = match counts.iter_mut().find(|(k, _)| *k == name) {
                        Some((_, n)) => {
                            *n += 1;
                            *n
                        }
                        None => {
                            counts.push((name.clone(), 1));
                            1
                        }
                    };
                    format!("{name}[{n}]")
                } else {
                    name
                };
            }
            line_start += line.len();
        }
        let (line_no, _) = self.line_col(offset);
        let key = self
            .text
            .lines()
            .nth(line_no - 1)
            .and_then(|l| l.split_once('='))
            .map(|(k, _)| k.trim().to_string())
            .unwrap_or_default();
        match (table.is_empty(), key.is_empty()) {
            (true, _) => key,
            (false, true) => table,
            (false, false) => format!("{table}.{key}"),
        }
    }

    fn toml_error(&self, e: &toml::de::Error) -> ConfigLoadError {
        let span = e.span().unwrap_or(0..0);
        let field = self.field_at(span.start);
        let message = e.message().trim().to_string();
        self.invalid(span, if field.is_empty() { "(file)" } else { &field }, message)
    }
}

type S<T> = Option<Spanned<T>>;

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawFile {
    #[serde(default)]
    general: RawGeneral,
    #[serde(default)]
    timer: RawTimer,
    #[serde(default)]
    gather: RawGather,
    #[serde(default)]
    step: RawStep,
    #[serde(default)]
    trajectory: RawTrajectory,
    #[serde(default)]
    homing: RawHoming,
    #[serde(default)]
    safety: RawSafety,
    #[serde(default)]
    hwserver: RawHwServer,
    #[serde(default)]
    sim: RawSim,
    #[serde(default)]
    motor: Vec<Spanned<RawMotor>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawGeneral {
    n_motors: S<i64>,
    period_us: S<i64>,
    gains_period_us: S<i64>,
    law: S<String>,
    counts_per_rev: S<f64>,
    gear_ratio: S<f64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawTimer {
    method: S<String>,
    servo_priority: S<i64>,
    hwserver_priority: S<i64>,
    lock_memory: S<bool>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawGather {
    every: S<i64>,
    out_dir: S<String>,
    fields: S<Vec<String>>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawStep {
    size: S<i64>,
    duration_s: S<f64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawTrajectory {
    method: S<String>,
    knots: S<String>,
    start_tolerance_counts: S<f64>,
    stream_wait_s: S<f64>,
    starve_hold_ms: S<f64>,
    settle_s: S<f64>,
    max_duration_s: S<f64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawHoming {
    velocity_counts_per_s: S<f64>,
    creep_counts_per_s: S<f64>,
    clear_within_counts: S<f64>,
    max_travel_counts: S<f64>,
    settle_s: S<f64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawSafety {
    max_missed_in_row: S<i64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawHwServer {
    backend: S<String>,
    watchdog_periods: S<i64>,
    deadline_periods: S<i64>,
    response_timeout_periods: S<i64>,
    max_counts_per_s: S<f64>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawSim {
    kv: S<f64>,
    tau_s: S<f64>,
    coast_tau_s: S<f64>,
    start_counts: S<Vec<f64>>,
    top_switch_counts: S<f64>,
    bottom_switch_counts: S<f64>,
    homed: S<bool>,
    counter_offset: S<i64>,
    stall_motor: S<i64>,
    stuck_top_motor: S<i64>,
    events_file: S<String>,
    state_file: S<String>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMotor {
    kp: S<f64>,
    ki: S<f64>,
    kd: S<f64>,
    kvff: S<f64>,
    kaff: S<f64>,
    notch: S<Vec<f64>>,
    soft_limits: S<Vec<f64>>,
    max_following_error_counts: S<f64>,
    max_integrated_error_counts: S<f64>,
    home_offset_counts: S<f64>,
    top_direction: S<i64>,
}

/// Takes an optional spanned value or its default, checking it with `ok`.
fn take<T: Clone>(
    src: &Source<'_>,
    v: &S<T>,
    field: &str,
    default: T,
    ok: impl FnOnce(&T) -> Result<(), String>,
) -> Result<T, ConfigLoadError> {
    match v {
        None => Ok(default),
        Some(s) => {
            ok(s.get_ref()).map_err(|m| src.invalid(s.span(), field, m))?;
            Ok(s.get_ref().clone())
        }
    }
}

fn in_range(lo: i64, hi: i64) -> impl FnOnce(&i64) -> Result<(), String> {
    move |v| {
        if (lo..=hi).contains(v) { Ok(()) } else { Err(format!("must be {lo}‥{hi}, found {v}")) }
    }
}

/// 1-based motor number, 0 meaning none.
fn motor_or_none(v: i64) -> Option<usize> {
    (v > 0).then_some(v as usize)
}

fn finite(v: &f64) -> Result<(), String> {
    if v.is_finite() { Ok(()) } else { Err(format!("must be a finite number, found {v}")) }
}

fn positive(v: &f64) -> Result<(), String> {
    if v.is_finite() && *v > 0.0 {
        Ok(())
    } else {
        Err(format!("must be a finite number > 0, found {v}"))
    }
}

fn non_negative(v: &f64) -> Result<(), String> {
    if v.is_finite() && *v >= 0.0 {
        Ok(())
    } else {
        Err(format!("must be a finite number ≥ 0, found {v}"))
    }
}

/// The notch denominator 1 + d1·z⁻¹ + d2·z⁻² is stable iff |d2| < 1 and |d1| < 1 + d2.
fn check_notch(n: &[f64]) -> Result<(), String> {
    if n.len() != 4 {
        return Err(format!("must be 4 numbers [n1, n2, d1, d2], found {}", n.len()));
    }
    if let Some(bad) = n.iter().find(|x| !x.is_finite()) {
        return Err(format!("must be finite numbers, found {bad}"));
    }
    let (d1, d2) = (n[2], n[3]);
    if !(d2.abs() < 1.0 && d1.abs() < 1.0 + d2) {
        return Err(format!(
            "the denominator 1 + d1·z⁻¹ + d2·z⁻² with d1 = {d1}, d2 = {d2} is unstable \
             (needs |d2| < 1 and |d1| < 1 + d2)"
        ));
    }
    Ok(())
}

impl RawFile {
    fn check(self, src: &Source<'_>) -> Result<Settings, ConfigLoadError> {
        let g = &self.general;
        let n_motors =
            take(src, &g.n_motors, "general.n_motors", 3, in_range(1, MAX_MOTORS as i64))? as usize;
        let period_us = take(src, &g.period_us, "general.period_us", 400, |v| {
            u32::try_from(*v)
                .map_err(|_| format!("servo period must be 100‥100000 µs, found {v}"))
                .and_then(check_period)
        })? as u32;
        let gains_period_us = take(src, &g.gains_period_us, "general.gains_period_us", 400, |v| {
            u32::try_from(*v)
                .map_err(|_| format!("servo period must be 100‥100000 µs, found {v}"))
                .and_then(check_period)
        })? as u32;
        let law = take(src, &g.law, "general.law", "pidff".to_string(), |v| {
            if registry::law(v).is_some() {
                Ok(())
            } else {
                Err(format!(
                    "unknown servo law `{v}`; registered: {}",
                    registry::law_names().join(", ")
                ))
            }
        })?;
        let counts_per_rev =
            take(src, &g.counts_per_rev, "general.counts_per_rev", 4096.0, positive)?;
        let gear_ratio = take(src, &g.gear_ratio, "general.gear_ratio", 12.0, positive)?;

        let t = &self.timer;
        let method = take(src, &t.method, "timer.method", "timerfd".to_string(), |v| {
            TickerKind::from_name(v)
                .map(|_| ())
                .ok_or_else(|| format!("must be \"timerfd\" or \"nanosleep\", found \"{v}\""))
        })?;
        let servo_priority =
            take(src, &t.servo_priority, "timer.servo_priority", 80, in_range(0, 98))? as i32;
        let hwserver_priority =
            take(src, &t.hwserver_priority, "timer.hwserver_priority", 85, in_range(0, 98))? as i32;
        if servo_priority > 0 && hwserver_priority > 0 && hwserver_priority < servo_priority {
            let span = t.hwserver_priority.as_ref().map_or(0..0, Spanned::span);
            return Err(src.invalid(
                span,
                "timer.hwserver_priority",
                format!(
                    "must be at least timer.servo_priority ({servo_priority}): the servo thread \
                     waits on the hwserver, so the hwserver must not be preempted by it"
                ),
            ));
        }
        let lock_memory = take(src, &t.lock_memory, "timer.lock_memory", true, |_| Ok(()))?;

        let every =
            take(src, &self.gather.every, "gather.every", 1, in_range(1, 1_000_000))? as u32;
        let out_dir = take(src, &self.gather.out_dir, "gather.out_dir", "out".to_string(), |v| {
            if v.trim().is_empty() { Err("must not be empty".into()) } else { Ok(()) }
        })?;
        let all_fields = GatherFields::NAMES.map(str::to_string).to_vec();
        let field_names = take(src, &self.gather.fields, "gather.fields", all_fields, |v| {
            GatherFields::from_names(v.iter().map(String::as_str)).map(|_| ())
        })?;
        let fields =
            GatherFields::from_names(field_names.iter().map(String::as_str)).unwrap_or_default();

        let tr = &self.trajectory;
        let max_duration_s = take(
            src,
            &tr.max_duration_s,
            "trajectory.max_duration_s",
            crate::knots::DEFAULT_MAX_DURATION_S,
            |v| {
                if v.is_finite() && *v > 0.0 && *v <= 1e7 {
                    Ok(())
                } else {
                    Err(format!("must be > 0 and ≤ 10000000 s, found {v}"))
                }
            },
        )?;
        let size = take(src, &self.step.size, "step.size", 1000, |v| check_step_size(*v))?;
        let duration_s = take(src, &self.step.duration_s, "step.duration_s", 2.0, |v| {
            check_duration(*v, max_duration_s)
        })?;

        let trajectory = TrajectorySettings {
            max_duration_s,
            method: take(src, &tr.method, "trajectory.method", "spline".to_string(), |v| {
                check_method(v)
            })?,
            knots: take(src, &tr.knots, "trajectory.knots", String::new(), |v| {
                if v.trim().is_empty() { Err("must not be empty".into()) } else { Ok(()) }
            })
            .map(|k| (!k.is_empty()).then(|| PathBuf::from(k)))?,
            start_tolerance_counts: take(
                src,
                &tr.start_tolerance_counts,
                "trajectory.start_tolerance_counts",
                100.0,
                non_negative,
            )?,
            stream_wait_s: take(
                src,
                &tr.stream_wait_s,
                "trajectory.stream_wait_s",
                10.0,
                positive,
            )?,
            starve_hold_ms: take(
                src,
                &tr.starve_hold_ms,
                "trajectory.starve_hold_ms",
                50.0,
                |v| {
                    if v.is_finite() && (0.0..=10_000.0).contains(v) {
                        Ok(())
                    } else {
                        Err(format!("must be 0‥10000 ms, found {v}"))
                    }
                },
            )?,
            settle_s: take(src, &tr.settle_s, "trajectory.settle_s", 0.2, |v| {
                if v.is_finite() && (0.0..=10.0).contains(v) {
                    Ok(())
                } else {
                    Err(format!("must be 0‥10 s, found {v}"))
                }
            })?,
        };

        let h = &self.hwserver;
        let backend =
            take(src, &h.backend, "hwserver.backend", "sim".to_string(), |v| check_backend(v))?;
        let timing_defaults = TimingDefaults::of(&backend);
        let watchdog_periods = take(
            src,
            &h.watchdog_periods,
            "hwserver.watchdog_periods",
            i64::from(timing_defaults.watchdog_periods),
            in_range(2, 1_000_000),
        )? as u32;
        let deadline_periods =
            take(src, &h.deadline_periods, "hwserver.deadline_periods", 5, in_range(1, 1_000_000))?
                as u32;
        let response_timeout_periods = take(
            src,
            &h.response_timeout_periods,
            "hwserver.response_timeout_periods",
            250,
            in_range(i64::from(deadline_periods), 1_000_000),
        )? as u32;

        let max_counts_per_s =
            take(src, &h.max_counts_per_s, "hwserver.max_counts_per_s", 500_000.0, positive)?;

        let s = &self.sim;
        let sim = SimSettings {
            kv: take(src, &s.kv, "sim.kv", 25_000.0, positive)?,
            tau_s: take(src, &s.tau_s, "sim.tau_s", 0.004, positive)?,
            coast_tau_s: take(src, &s.coast_tau_s, "sim.coast_tau_s", 0.05, positive)?,
            start_counts: take(src, &s.start_counts, "sim.start_counts", vec![], |v| {
                if v.len() > MAX_MOTORS {
                    return Err(format!("at most {MAX_MOTORS} positions, found {}", v.len()));
                }
                match v.iter().find(|x| !(x.is_finite() && x.abs() < f64::from(1u32 << 23))) {
                    Some(bad) => Err(format!(
                        "positions must be finite and within ±2^23 counts, found {bad}"
                    )),
                    None => Ok(()),
                }
            })?,
            top_switch_counts: take(
                src,
                &s.top_switch_counts,
                "sim.top_switch_counts",
                -9_500.0,
                finite,
            )?,
            bottom_switch_counts: take(
                src,
                &s.bottom_switch_counts,
                "sim.bottom_switch_counts",
                10_500.0,
                finite,
            )?,
            homed: take(src, &s.homed, "sim.homed", true, |_| Ok(()))?,
            counter_offset: take(
                src,
                &s.counter_offset,
                "sim.counter_offset",
                0,
                in_range(-(1 << 23), 1 << 23),
            )?,
            stall_motor: motor_or_none(take(
                src,
                &s.stall_motor,
                "sim.stall_motor",
                0,
                in_range(0, n_motors as i64),
            )?),
            stuck_top_motor: motor_or_none(take(
                src,
                &s.stuck_top_motor,
                "sim.stuck_top_motor",
                0,
                in_range(0, n_motors as i64),
            )?),
            events_file: take(src, &s.events_file, "sim.events_file", String::new(), |_| Ok(()))
                .map(|f| (!f.is_empty()).then(|| PathBuf::from(f)))?,
            state_file: take(
                src,
                &s.state_file,
                "sim.state_file",
                DEFAULT_SIM_STATE_FILE.to_string(),
                |_| Ok(()),
            )
            .map(|f| (!f.is_empty()).then(|| PathBuf::from(f)))?,
        };
        if sim.top_switch_counts == sim.bottom_switch_counts {
            let span = s.bottom_switch_counts.as_ref().map_or(0..0, Spanned::span);
            return Err(src.invalid(
                span,
                "sim.bottom_switch_counts",
                "must differ from sim.top_switch_counts",
            ));
        }

        if self.motor.len() > MAX_MOTORS {
            return Err(src.invalid(
                self.motor[MAX_MOTORS].span(),
                &format!("motor[{}]", MAX_MOTORS + 1),
                format!("at most {MAX_MOTORS} [[motor]] tables"),
            ));
        }
        if self.motor.len() < n_motors {
            let span = g.n_motors.as_ref().map_or(0..0, Spanned::span);
            return Err(src.invalid(
                span,
                "general.n_motors",
                format!(
                    "{n_motors} motors need {n_motors} [[motor]] tables, found {}",
                    self.motor.len()
                ),
            ));
        }
        let mut motors = Vec::with_capacity(self.motor.len());
        let mut safety = Vec::with_capacity(self.motor.len());
        for (i, m) in self.motor.iter().enumerate() {
            let name = |k: &str| format!("motor[{}].{k}", i + 1);
            let need = |v: &S<f64>, k: &str| -> Result<f64, ConfigLoadError> {
                match v {
                    None => Err(src.invalid(m.span(), &name(k), format!("missing key `{k}`"))),
                    Some(_) => take(src, v, &name(k), 0.0, finite),
                }
            };
            let r = m.get_ref();
            let notch = take(src, &r.notch, &name("notch"), vec![0.0; 4], |v| check_notch(v))?;
            motors.push(MotorGains {
                kp: need(&r.kp, "kp")?,
                ki: need(&r.ki, "ki")?,
                kd: need(&r.kd, "kd")?,
                kvff: need(&r.kvff, "kvff")?,
                kaff: need(&r.kaff, "kaff")?,
                notch: [notch[0], notch[1], notch[2], notch[3]],
            });
            let d = MotorSafety::default();
            let soft = take(
                src,
                &r.soft_limits,
                &name("soft_limits"),
                d.soft_limits.to_vec(),
                |v| match v.as_slice() {
                    [lo, hi] if lo.is_finite() && hi.is_finite() && lo < hi => Ok(()),
                    _ => Err(format!("must be [min, max] with min < max, found {v:?}")),
                },
            )?;
            let positive = |v: &f64| {
                if v.is_finite() && *v > 0.0 {
                    Ok(())
                } else {
                    Err(format!("must be a finite number > 0, found {v}"))
                }
            };
            safety.push(MotorSafety {
                soft_limits: [soft[0], soft[1]],
                max_following_error_counts: take(
                    src,
                    &r.max_following_error_counts,
                    &name("max_following_error_counts"),
                    d.max_following_error_counts,
                    positive,
                )?,
                max_integrated_error_counts: take(
                    src,
                    &r.max_integrated_error_counts,
                    &name("max_integrated_error_counts"),
                    d.max_integrated_error_counts,
                    positive,
                )?,
                home_offset_counts: take(
                    src,
                    &r.home_offset_counts,
                    &name("home_offset_counts"),
                    d.home_offset_counts,
                    non_negative,
                )?,
                top_direction: take(src, &r.top_direction, &name("top_direction"), -1, |v| {
                    if *v == 1 || *v == -1 {
                        Ok(())
                    } else {
                        Err(format!("must be -1 or 1, found {v}"))
                    }
                })? as f64,
            });
        }

        let hm = &self.homing;
        let homing = HomingSettings {
            velocity_counts_per_s: take(
                src,
                &hm.velocity_counts_per_s,
                "homing.velocity_counts_per_s",
                1_000.0,
                positive,
            )?,
            creep_counts_per_s: take(
                src,
                &hm.creep_counts_per_s,
                "homing.creep_counts_per_s",
                100.0,
                positive,
            )?,
            clear_within_counts: take(
                src,
                &hm.clear_within_counts,
                "homing.clear_within_counts",
                10.0,
                positive,
            )?,
            max_travel_counts: take(
                src,
                &hm.max_travel_counts,
                "homing.max_travel_counts",
                30_000.0,
                positive,
            )?,
            settle_s: take(src, &hm.settle_s, "homing.settle_s", 0.2, |v| {
                if v.is_finite() && (0.0..=10.0).contains(v) {
                    Ok(())
                } else {
                    Err(format!("must be 0‥10 s, found {v}"))
                }
            })?,
        };
        let max_missed_in_row = take(
            src,
            &self.safety.max_missed_in_row,
            "safety.max_missed_in_row",
            timing_defaults.max_missed_in_row as i64,
            in_range(1, 1_000_000),
        )? as u64;

        Ok(Settings {
            source: src.path.to_path_buf(),
            n_motors,
            period_us,
            gains_period_us,
            law,
            counts_per_rev,
            gear_ratio,
            timer: TimerSettings {
                method: TickerKind::from_name(&method).unwrap_or_default(),
                servo_priority,
                hwserver_priority,
                lock_memory,
            },
            gather: GatherSettings { every, out_dir: PathBuf::from(out_dir), fields },
            step: StepSettings { size, duration_s },
            trajectory,
            homing,
            max_missed_in_row,
            hwserver: HwServerSettings {
                max_counts_per_s,
                backend,
                watchdog_periods,
                deadline_periods,
                response_timeout_periods,
            },
            sim,
            motors,
            safety,
            explicit: ExplicitTiming {
                watchdog_periods: h.watchdog_periods.is_some(),
                max_missed_in_row: self.safety.max_missed_in_row.is_some(),
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const MOTOR: &str = "[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n";

    fn parse(text: &str) -> Result<Settings, ConfigLoadError> {
        Settings::parse(Path::new("q.toml"), text)
    }

    fn check(text: &str, expected: &str) {
        match parse(text) {
            Ok(_) => panic!("accepted:\n{text}"),
            Err(e) => assert_eq!(e.to_string(), expected),
        }
    }

    #[test]
    fn shipped_settings_are_the_thesis_defaults() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
        let s = Settings::load(&path).unwrap();
        assert_eq!((s.n_motors, s.period_us, s.law.as_str()), (3, 400, "pidff"));
        let table_5_1 = [(182_000.0, 119_000.0), (182_000.0, 103_500.0), (183_000.0, 104_000.0)];
        for (m, (kp, kvff)) in s.motors.iter().zip(table_5_1) {
            assert_eq!((m.kp, m.ki, m.kd, m.kvff, m.kaff), (kp, 100.0, 3_000.0, kvff, 100.0));
            assert_eq!(m.notch, [0.0; 4]);
        }
        assert!((s.counts_per_rad() - 7_822.78).abs() < 0.01, "{}", s.counts_per_rad());
        assert_eq!(s.timer.method, TickerKind::TimerFd);
    }

    #[test]
    fn minimal_file_takes_defaults() {
        let s = parse(&MOTOR.repeat(3)).unwrap();
        assert_eq!((s.n_motors, s.period_us, s.gather.every, s.step.size), (3, 400, 1, 1000));
        assert_eq!(s.hwserver.watchdog_periods, 250, "the simulated robot's default");
    }

    #[test]
    fn errors_name_file_line_column_and_field() {
        check(
            "[general]\nperiod_us = 50\n",
            "q.toml:2:13: general.period_us: servo period must be 100‥100000 µs, found 50",
        );
        check("[general]\nn_motors = 5\n", "q.toml:2:12: general.n_motors: must be 1‥4, found 5");
        check(
            "[general]\nn_motors = 2\n[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n",
            "q.toml:2:12: general.n_motors: 2 motors need 2 [[motor]] tables, found 1",
        );
        check(
            &format!("{MOTOR}{MOTOR}[[motor]]\nkp = 1.0\nkpp = 2\n"),
            "q.toml:15:1: motor[3].kpp: unknown field `kpp`, expected one of `kp`, `ki`, `kd`, `kvff`, `kaff`, `notch`, `soft_limits`, `max_following_error_counts`, `max_integrated_error_counts`, `home_offset_counts`, `top_direction`",
        );
        check(
            &format!("{MOTOR}{MOTOR}[[motor]]\nkp = \"big\"\n"),
            "q.toml:14:6: motor[3].kp: invalid type: string \"big\", expected f64",
        );
        check(
            &format!("{MOTOR}[[motor]]\nkp = 1.0\n{MOTOR}"),
            "q.toml:7:1: motor[2].ki: missing key `ki`",
        );
        check(
            &format!(
                "{}[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\nnotch = [0, 0, -2.5, 0.9]\n",
                MOTOR.repeat(2)
            ),
            "q.toml:19:9: motor[3].notch: the denominator 1 + d1·z⁻¹ + d2·z⁻² with d1 = -2.5, d2 = 0.9 is unstable (needs |d2| < 1 and |d1| < 1 + d2)",
        );
        check(
            "[general]\nlaw = \"lqr\"\n",
            "q.toml:2:7: general.law: unknown servo law `lqr`; registered: pidff",
        );
        check(
            "[timer]\nmethod = \"posix\"\n",
            "q.toml:2:10: timer.method: must be \"timerfd\" or \"nanosleep\", found \"posix\"",
        );
        check(
            "[bogus]\nx = 1\n",
            "q.toml:1:2: bogus: unknown field `bogus`, expected one of `general`, `timer`, `gather`, `step`, `trajectory`, `homing`, `safety`, `hwserver`, `sim`, `motor`",
        );
        check(
            "[trajectory]\nmethod = \"home\"\n",
            "q.toml:2:10: trajectory.method: unknown trajectory method `home`; registered: step, spline, pvt",
        );
        check(
            "[general]\nperiod_us = \n",
            "q.toml:2:13: general.period_us: string values must be quoted, expected literal string",
        );
        check(
            "[step]\nduration_s = nan\n",
            "q.toml:2:14: step.duration_s: duration must be > 0 and ≤ 86400 s (trajectory.max_duration_s), found NaN",
        );
        check(
            "[timer]\nservo_priority = 90\nhwserver_priority = 80\n",
            "q.toml:3:21: timer.hwserver_priority: must be at least timer.servo_priority (90): the servo thread waits on the hwserver, so the hwserver must not be preempted by it",
        );
    }

    #[test]
    fn overrides_are_checked() {
        let mut s = parse(&MOTOR.repeat(3)).unwrap();
        assert_eq!(
            s.set_period_us(99).unwrap_err().to_string(),
            "--period-us: servo period must be 100‥100000 µs, found 99"
        );
        assert_eq!(
            s.set_gather_every(0).unwrap_err().to_string(),
            "--gather-every: must be at least 1"
        );
        assert_eq!(
            s.set_step_duration(-1.0).unwrap_err().to_string(),
            "--duration: duration must be > 0 and ≤ 86400 s (trajectory.max_duration_s), found -1"
        );
        s.set_period_us(1000).unwrap();
        s.set_step_size(-500).unwrap();
        assert_eq!((s.period_us, s.step.size), (1000, -500));
    }

    #[test]
    fn missing_file_is_named() {
        let e = Settings::load(Path::new("/nonexistent/q.toml")).unwrap_err().to_string();
        assert!(e.starts_with("/nonexistent/q.toml: cannot read the settings file: "), "{e}");
    }
}
