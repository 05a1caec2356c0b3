//! The command line of a move (`qmarc-starter` and `qmarc home|step|run`): its global options
//! ([`MoveOptions`]) and subcommand ([`Command`]), applied to the settings file once, into the
//! one [`Settings`] value both children get.

use clap::{Args, Subcommand};
use qmarc_config::{ConfigLoadError, Mode, Names, Settings};
use std::path::PathBuf;

/// Options of every move; flags override the settings file for this run. They are global:
/// they go before or after the subcommand (`qmarc-starter --out x step` or
/// `qmarc-starter step --out x`).
#[derive(Debug, Clone, PartialEq, Args)]
pub struct MoveOptions {
    /// Settings file.
    #[arg(long, global = true, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Directory for gather.csv, gather.m and summary.json (default: `gather.out_dir`); for
    /// `path`, the knot file to write.
    #[arg(long, global = true)]
    pub out: Option<PathBuf>,
    /// Gather every N-th servo cycle (default: `gather.every`).
    #[arg(long, global = true)]
    pub gather_every: Option<u32>,
    /// Servo period in µs (default: `general.period_us`).
    #[arg(long, global = true)]
    pub period_us: Option<u32>,
    /// Number of motors (default: `general.n_motors`; each needs its `[[motor]]` table).
    #[arg(long, global = true)]
    pub motors: Option<usize>,
    /// Lock-step simulated clock: two runs produce byte-identical data files.
    #[arg(long, global = true)]
    pub deterministic: bool,
    /// Lock-step (implies --deterministic) and not paced by the timer: each cycle follows the
    /// last at once, so a move takes only its computing time, with the data of the paced
    /// lock-step run. Only on the simulated robot.
    #[arg(long, global = true)]
    pub unpaced: bool,
    /// Move although the frame is not homed; software position limits are then off.
    #[arg(long, global = true)]
    pub unhomed: bool,
    /// Hardware backend (default: `hwserver.backend`): `sim`, the simulated Deltabot, or
    /// `s626`, the Sensoray 626 through the kernel's comedi driver.
    #[arg(long, global = true)]
    pub backend: Option<String>,
    /// The Sensoray 626's comedi device (default: `s626.device`, /dev/comedi0).
    #[arg(long, global = true)]
    pub device: Option<PathBuf>,
    /// How the servo thread waits for its period (default: `timer.method`): `timerfd`,
    /// `nanosleep` or `timerfd-periodic`.
    #[arg(long, global = true)]
    pub timer: Option<qmarc_config::TimerMethod>,
    /// A file of timing bounds over the settings' (`[hwserver] watchdog_periods`,
    /// `response_timeout_periods`, `[safety] max_missed_in_row` only): to rehearse on the
    /// fake card (--device fake) on a machine without PREEMPT_RT
    /// (config/rehearse-without-rt.toml); refused on a card that drives a robot.
    #[arg(long, global = true, value_name = "FILE")]
    pub timing_overrides: Option<PathBuf>,
}

impl MoveOptions {
    /// Lock-step simulated time: `--deterministic`, or implied by `--unpaced`.
    pub fn lockstep(&self) -> bool {
        self.deterministic || self.unpaced
    }

    /// Loads the settings file and applies the overrides, the names it accepts from `names`.
    pub fn load(&self, names: &Names) -> Result<Settings, ConfigLoadError> {
        let mut s = Settings::load(&self.config, names)?;
        let timing = self.timing_overrides.as_deref().map(qmarc_config::TimingOverrides::load);
        if let Some(p) = self.period_us {
            s.set_period_us(p)?;
        }
        if let Some(n) = self.gather_every {
            s.set_gather_every(n)?;
        }
        if let Some(n) = self.motors {
            s.set_n_motors(n)?;
        }
        if let Some(out) = &self.out {
            s.gather.out_dir = out.clone();
        }
        if let Some(b) = &self.backend {
            s.set_backend(b)?;
        }
        if let Some(d) = &self.device {
            s.set_device(d)?;
        }
        if let Some(t) = self.timer {
            s.timer.method = t;
        }
        if let Some(o) = timing.transpose()? {
            s.apply_timing_overrides(&o)?;
            eprintln!(
                "qmarc-starter: timing bounds from {}: {} (a rehearsal's, not the robot's)",
                o.file.display(),
                o.describe()
            );
        }
        Ok(s)
    }
}

/// What to do, with the subcommand's own options.
#[derive(Debug, Clone, PartialEq, Subcommand)]
pub enum Command {
    /// Step every motor by `--size` counts and hold for `--duration` s (tuning, thesis 3.4).
    Step(StepArgs),
    /// Run a path from a knot file or stream (thesis 3.12, A.2.3).
    Run(RunArgs),
    /// Home the robot on its top limit switches, one motor at a time (thesis 3.10.1.1).
    Home,
    /// Move one motor by hand: `--counts` from where it is, jerk-limited and slow (`[jog]`),
    /// the others held; within the software limits where homed, slower where not.
    Jog(JogArgs),
    /// The first motion of a new robot: with the loop open, each motor in turn gets a small,
    /// short voltage (`[check]`) while its counter is watched; says which way it went, how fast
    /// against the feed-forward, and which of dac_sign / counter_sign to change. Exit 2 when a
    /// motor fails it.
    Check,
    /// Move to a target from where the motors are, at rest at the end: every motor starts and
    /// arrives together, the slowest as fast as its velocity, acceleration and jerk limits
    /// (`[[motor]] max_*`) allow — Ruckig's time-optimal, jerk-limited profile. Needs a homed
    /// frame (or --unhomed).
    Move(MoveArgs),
    /// Enable the robot and hold it where it is; take commands while it holds and moves:
    /// over the iceoryx2 service `qmarc/command` and from `qmarc cmd move|stop|wait|status|
    /// quit`. Ends on `qmarc cmd quit` (or Ctrl-C) as any move ends, its data files written
    /// (the last `gather.stream_max_s` of it). Needs a homed frame (or --unhomed).
    Serve(ServeArgs),
    /// A serving session at the belt (`[conveyor]`, `[camera]`): the belt runs, the camera
    /// sees its parts, the robot picks them; after --seconds it ends at rest, its data files
    /// written (gather.csv with the belt's `conv`). Commanded like `serve` while it runs.
    /// Needs a homed frame.
    Conveyor(ConveyorArgs),
}

/// Options of `conveyor`.
#[derive(Debug, Clone, PartialEq, Args, Default)]
pub struct ConveyorArgs {
    /// How long it runs, s (default `conveyor.run_s`).
    #[arg(long, value_name = "S")]
    pub seconds: Option<f64>,
    /// The simulated belt's speed, mm/s (default `conveyor.speed_mm_s`).
    #[arg(long, value_name = "V")]
    pub belt_mm_s: Option<f64>,
    /// The simulated camera's parts a minute (default `camera.parts_per_min`).
    #[arg(long, value_name = "N")]
    pub parts_per_min: Option<f64>,
    /// The simulated parts' seed (default `camera.seed`).
    #[arg(long, value_name = "K")]
    pub seed: Option<u64>,
    /// The camera: `sim` (the parts reported as the simulation has them) or `images` (found
    /// in frames: `[camera]` source, calibration, detection; docs/vision.md) (default
    /// `camera.backend`).
    #[arg(long, value_name = "BACKEND")]
    pub camera: Option<String>,
    /// Join the cell NAME: robots on one belt sharing the parts of the cell's camera
    /// (`qmarc-cell camera --cell NAME`) over Zenoh, this one as `[cell] robot` at `[cell]
    /// belt_offset_mm` (docs/cell.md); the session's Zenoh is rmw_zenoh's default (a peer,
    /// a router at tcp/localhost:7447) or --zenoh-config's. Refused, saying why, when the
    /// robot's belt is not the cell's.
    #[arg(long, value_name = "NAME", conflicts_with = "camera")]
    pub cell: Option<String>,
    /// The bridge beside the session, as `serve` starts it (its `/diagnostics` say the parts
    /// queued, picked and missed).
    #[command(flatten)]
    pub serve: ServeArgs,
}

impl ConveyorArgs {
    /// Applies the options to `s`.
    fn apply(&self, s: &mut Settings) -> Result<(), ConfigLoadError> {
        if let Some(v) = self.seconds {
            s.set_conveyor_seconds(v)?;
        }
        if let Some(v) = self.belt_mm_s {
            s.set_belt_speed(v)?;
        }
        if let Some(n) = self.parts_per_min {
            s.set_parts_per_min(n)?;
        }
        if let Some(k) = self.seed {
            s.camera.seed = k;
        }
        if let Some(b) = &self.camera {
            s.set_camera_backend(b)?;
        }
        if let Some(name) = &self.cell {
            s.set_cell(name, self.serve.zenoh_config.as_deref())?;
        }
        Ok(())
    }
}

/// Options of `serve` (and of `conveyor`): the bridge beside the session.
#[derive(Debug, Clone, PartialEq, Args, Default)]
pub struct ServeArgs {
    /// Start `qmarc-bridge` beside the controller and the hwserver, and stop it with them: the
    /// session as a ROS 2 node over Zenoh, on rmw_zenoh's defaults (a peer connecting to a
    /// router at tcp/localhost:7447, domain 0, no namespace; run `qmarc-bridge` yourself for
    /// others, or give the three options below). Its end, or its death, ends nothing else;
    /// a bridge that cannot serve (a node of its name alive in its domain) says why and the
    /// session goes on without it.
    #[arg(long)]
    pub bridge: bool,
    /// The bridge's ROS namespace: `/robot1` (qmarc-bridge --namespace).
    #[arg(long, requires = "bridge", value_parser = ros_namespace)]
    pub namespace: Option<String>,
    /// The bridge's ROS domain id, 0‥232 (qmarc-bridge --domain).
    #[arg(long, requires = "bridge", value_parser = clap::value_parser!(u32).range(0..=232))]
    pub domain: Option<u32>,
    /// The Zenoh configuration file, JSON5, of the bridge (qmarc-bridge --zenoh-config) and
    /// of the cell (`conveyor --cell`).
    #[arg(long)]
    pub zenoh_config: Option<PathBuf>,
    /// Start `qmarc-foxglove live` beside the session and stop it with it: the session's live
    /// view for Foxglove (the Foxglove WebSocket protocol, `foxglove.websocket.v1`) at ADDR,
    /// `host:port` (default 127.0.0.1:8765): the robot drawn, its joint states, the effector,
    /// the rows and the log (docs/foxglove.md). Its end, or its death, ends nothing else.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = qmarc_foxglove::live::DEFAULT_ADDR)]
    pub foxglove: Option<String>,
}

impl ServeArgs {
    /// The bridge's own options, as `qmarc-bridge` takes them.
    pub fn bridge_args(&self) -> Vec<String> {
        let mut args = Vec::new();
        if let Some(ns) = &self.namespace {
            args.push(format!("--namespace={ns}"));
        }
        if let Some(d) = self.domain {
            args.push(format!("--domain={d}"));
        }
        if let Some(f) = &self.zenoh_config {
            args.push(format!("--zenoh-config={}", f.display()));
        }
        args
    }
}

/// A ROS namespace (`qmarc_config::program::check_ros_namespace`).
fn ros_namespace(v: &str) -> Result<String, String> {
    qmarc_program::cli::check_ros_namespace(v).map(|()| v.to_string())
}

/// Options of `move`.
#[derive(Debug, Clone, PartialEq, Args, Default)]
#[command(group(clap::ArgGroup::new("target").args(["to", "xyz"])))]
pub struct MoveArgs {
    /// The target in joint counts, one per motor: `--to 1000,-500,250`.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_name = "C1,C2,C3")]
    pub to: Option<Vec<f64>>,
    /// The target effector point in mm (the base frame of `[robot]`): `--xyz 0,50,-600`;
    /// a joint-space move to the inverse kinematics' counts, or a straight line with --linear.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, value_name = "X,Y,Z")]
    pub xyz: Option<Vec<f64>>,
    /// A straight line in Cartesian space to the --xyz point, jerk-limited along the line,
    /// every joint within its limits.
    #[arg(long, requires = "xyz")]
    pub linear: bool,
    /// A fraction of the motors' limits, 0 < F ≤ 1: velocity × F, acceleration × F², jerk × F³
    /// (default 1).
    #[arg(long, value_name = "F")]
    pub speed: Option<f64>,
    /// Close (`on`) or open (`off`) the gripper at the end of the move; the move ends once
    /// it is there. Without --to or --xyz: where the robot is.
    #[arg(long, value_name = "on|off", value_parser = qmarc_program::cli::parse_on_off)]
    pub grip: Option<bool>,
}

impl MoveArgs {
    /// Applies the move's target, line and speed to `s`.
    pub fn apply(&self, s: &mut Settings) -> Result<(), ConfigLoadError> {
        if self.to.is_none() && self.xyz.is_none() && self.grip.is_none() {
            return Err(ConfigLoadError::Override {
                flag: "move",
                message: "where to? --to C1,C2,C3 or --xyz X,Y,Z (or --grip on|off alone, in \
                          place)"
                    .into(),
            });
        }
        if let Some(to) = &self.to {
            s.set_move_to(to)?;
        }
        if let Some(xyz) = &self.xyz {
            let mm: [f64; 3] =
                xyz.as_slice().try_into().map_err(|_| ConfigLoadError::Override {
                    flag: "--xyz",
                    message: format!("a point is three numbers X,Y,Z in mm, found {}", xyz.len()),
                })?;
            s.set_move_xyz(mm)?;
        }
        if self.linear {
            s.set_move_linear()?;
        }
        if let Some(f) = self.speed {
            s.set_move_speed(f)?;
        }
        if let Some(close) = self.grip {
            s.set_move_grip(close)?;
        }
        Ok(())
    }
}

/// Options of `jog`.
#[derive(Debug, Clone, PartialEq, Args, Default)]
pub struct JogArgs {
    /// The motor, 1-based (default: `jog.motor`).
    #[arg(long, conflicts_with = "axis")]
    pub motor: Option<usize>,
    /// How far, counts, either way (default: `jog.counts`).
    #[arg(long, allow_negative_numbers = true, conflicts_with = "axis")]
    pub counts: Option<i64>,
    /// The effector along `x`, `y` or `z` instead: a straight line, in the homed frame.
    #[arg(long, value_name = "x|y|z")]
    pub axis: Option<String>,
    /// How far along --axis, mm, either way (default: `jog.mm`).
    #[arg(long, allow_negative_numbers = true, requires = "axis")]
    pub mm: Option<f64>,
}

/// Options of `run`.
#[derive(Debug, Clone, PartialEq, Args, Default)]
pub struct RunArgs {
    /// Knot file, or `-` for standard input (default: `trajectory.knots`).
    #[arg(long)]
    pub knots: Option<PathBuf>,
    /// `spline` (offline cubic spline), `pvt` (online PVT) or `step` (default:
    /// `trajectory.method`).
    #[arg(long)]
    pub method: Option<String>,
    /// First move from where the motors are to the path's start: jerk-limited at
    /// `trajectory.approach_speed` of the motors' limits, reported apart from the path
    /// (default: `trajectory.approach`).
    #[arg(long)]
    pub approach: bool,
}

/// Options of `step`.
#[derive(Debug, Clone, PartialEq, Args, Default)]
pub struct StepArgs {
    /// Step size in counts (default: `step.size`).
    #[arg(long, allow_negative_numbers = true)]
    pub size: Option<i64>,
    /// Duration in s (default: `step.duration_s`).
    #[arg(long)]
    pub duration: Option<f64>,
}

impl Command {
    /// The mode it runs.
    pub fn mode(&self) -> Mode {
        match self {
            Command::Step(_) => Mode::Step,
            Command::Run(_) => Mode::Run,
            Command::Home => Mode::Home,
            Command::Jog(_) => Mode::Jog,
            Command::Check => Mode::Check,
            Command::Move(_) => Mode::Move,
            Command::Serve(_) => Mode::Serve,
            Command::Conveyor(_) => Mode::Conveyor,
        }
    }

    /// Applies the subcommand's options to `s`.
    pub fn apply(&self, s: &mut Settings, names: &Names) -> Result<(), ConfigLoadError> {
        match self {
            Command::Step(a) => {
                if let Some(size) = a.size {
                    s.set_step_size(size)?;
                }
                if let Some(d) = a.duration {
                    s.set_step_duration(d)?;
                }
            }
            Command::Run(a) => {
                if let Some(k) = &a.knots {
                    s.set_knots(k);
                }
                if let Some(m) = &a.method {
                    s.set_method(m, names)?;
                }
                s.trajectory.approach |= a.approach;
            }
            Command::Jog(a) => match &a.axis {
                Some(axis) => s.set_jog_axis(axis, a.mm)?,
                None => {
                    s.set_jog(a.motor.unwrap_or(s.jog.motor), a.counts.unwrap_or(s.jog.counts))?
                }
            },
            Command::Move(a) => a.apply(s)?,
            Command::Conveyor(a) => a.apply(s)?,
            Command::Home | Command::Check | Command::Serve(_) => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    #[derive(Parser, Debug)]
    struct T {
        #[command(flatten)]
        opts: MoveOptions,
        #[command(subcommand)]
        command: Command,
    }

    #[test]
    fn options_go_before_or_after_the_subcommand() {
        let before = T::parse_from([
            "x",
            "--out",
            "/tmp/o",
            "--period-us",
            "500",
            "--backend",
            "s626",
            "--device",
            "/dev/c1",
            "step",
            "--size",
            "-250",
        ]);
        let after = T::parse_from([
            "x",
            "step",
            "--size",
            "-250",
            "--out",
            "/tmp/o",
            "--period-us",
            "500",
            "--device",
            "/dev/c1",
            "--backend",
            "s626",
        ]);
        assert_eq!(before.opts.device, Some(PathBuf::from("/dev/c1")));
        assert_eq!(before.opts.backend.as_deref(), Some("s626"));
        assert_eq!(before.opts, after.opts);
        assert_eq!(before.command, after.command);
        assert_eq!(after.command, Command::Step(StepArgs { size: Some(-250), duration: None }));
        assert_eq!(after.command.mode(), Mode::Step);
    }

    /// Issue 42, item 4: a comma list of numbers may start with a minus, as typed (before,
    /// clap took `-150,0,-600` for a flag).
    #[test]
    fn negative_coordinates_are_values_not_flags() {
        let xyz = T::try_parse_from(["x", "move", "--xyz", "-150,0,-600", "--linear"]).unwrap();
        let Command::Move(m) = xyz.command else { panic!("a move") };
        assert_eq!((m.xyz, m.linear), (Some(vec![-150.0, 0.0, -600.0]), true));
        let to = T::try_parse_from(["x", "move", "--to", "-100,0,0"]).unwrap();
        let Command::Move(m) = to.command else { panic!("a move") };
        assert_eq!(m.to, Some(vec![-100.0, 0.0, 0.0]));
    }

    /// Issue 44: a conveyor session takes the bridge's options as `serve` does, and only
    /// with --bridge.
    #[test]
    fn a_conveyor_session_takes_the_bridges_options() {
        let t = T::try_parse_from(["x", "conveyor", "--bridge", "--namespace=/r1", "--domain=3"])
            .unwrap();
        let Command::Conveyor(c) = t.command else { panic!("a conveyor session") };
        assert!(c.serve.bridge);
        assert_eq!(c.serve.bridge_args(), ["--namespace=/r1", "--domain=3"]);
        assert!(T::try_parse_from(["x", "conveyor", "--namespace=/r1"]).is_err());
    }

    /// Issue 45: `--foxglove` alone serves at Foxglove's default address, with a value there.
    #[test]
    fn the_live_view_takes_an_address_or_the_default() {
        let foxglove = |args: &[&str]| {
            let t = T::try_parse_from(args).unwrap();
            match t.command {
                Command::Serve(a) | Command::Conveyor(ConveyorArgs { serve: a, .. }) => a.foxglove,
                _ => panic!("a serving session"),
            }
        };
        assert_eq!(foxglove(&["x", "serve"]), None);
        assert_eq!(foxglove(&["x", "serve", "--foxglove"]).as_deref(), Some("127.0.0.1:8765"));
        let addr = foxglove(&["x", "conveyor", "--foxglove", "0.0.0.0:9000", "--seconds=3"]);
        assert_eq!(addr.as_deref(), Some("0.0.0.0:9000"));
        let before_flag = foxglove(&["x", "conveyor", "--foxglove", "--seconds=3"]);
        assert_eq!(before_flag.as_deref(), Some("127.0.0.1:8765"));
    }
}
