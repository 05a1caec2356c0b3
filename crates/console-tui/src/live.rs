//! The live charts of a running move: the console subscribes to the move's telemetry
//! (`qmarc/telemetry` of the run's prefix, [`qmarc_telemetry::reader`]) and keeps the last
//! [`WINDOW_S`] seconds as a [`Series`], which the charts page draws as it draws a finished
//! move's `gather.csv` — command and actual, following error and the servo period — redrawn
//! with every turn of the console's loop (≥ 10 Hz). It lets go of the move on its last
//! sample, when its publisher goes, or when the move ends.

use qmarc_proto::service::IpcLocation;
use qmarc_report::series::Series;
use qmarc_session::client::CommandClient;
use qmarc_session::wire::{CommandKind, CommandRequest, ConveyorStatus};
use qmarc_telemetry::reader::{TelemetryReader, is_last};
use std::time::{Duration, Instant};

/// Seconds of the move the live charts show (the newest).
pub const WINDOW_S: f64 = 4.0;

/// How often a reader is tried until the move's telemetry is there.
const RETRY: Duration = Duration::from_millis(100);

/// How often a conveyor session is asked for its belt and parts.
pub const BELT_EVERY: Duration = Duration::from_millis(250);

/// The live view of one move.
pub struct Live {
    location: IpcLocation,
    reader: Option<TelemetryReader>,
    tried: Option<Instant>,
    /// The move said it ended, or its publisher went: nothing more comes.
    pub ended: bool,
    /// The last [`WINDOW_S`] seconds.
    pub series: Series,
    /// Samples received.
    pub samples: u64,
    /// Samples lost (gaps in their numbers).
    pub lost: u64,
    /// The run's progress page (its phase and, homing, motor and stage), once it is there.
    progress: Option<qmarc_proto::progress::Progress>,
    /// Homing's motor and stage as the CLI says them: `homing motor 2: backing off the top
    /// switch`.
    pub stage: Option<String>,
    /// The robot's geometry, to show where the effector is (none: not a Delta).
    robot: Option<qmarc_kinematics::Robot>,
    /// Where the effector is, mm, by the last sample (through the forward kinematics).
    pub effector_mm: Option<[f64; 3]>,
    /// The gripper, by the last sample.
    pub gripper: qmarc_proto::Gripper,
    /// A conveyor session's belt and parts are asked for ([`Live::with_belt`]): the command
    /// client once connected, and when it last asked.
    belt_asked: Option<(Option<CommandClient>, Option<Instant>)>,
    /// The belt and its parts, by the session's last status.
    pub belt: Option<ConveyorStatus>,
}

impl std::fmt::Debug for Live {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Live")
            .field("location", &self.location)
            .field("attached", &self.reader.is_some())
            .field("samples", &self.samples)
            .finish()
    }
}

impl Live {
    /// The live view of the move whose iceoryx2 files are at `location` (not attached yet).
    pub fn new(location: IpcLocation) -> Live {
        // The terminal is the console's: iceoryx2 says nothing on it (its errors neither:
        // quieted once for good first, so that no node made later sets them back).
        qmarc_proto::service::quiet_iceoryx2();
        iceoryx2::prelude::set_log_level(iceoryx2::prelude::LogLevel::Fatal);
        Live {
            location,
            reader: None,
            tried: None,
            ended: false,
            series: Series::default(),
            samples: 0,
            progress: None,
            stage: None,
            lost: 0,
            robot: None,
            effector_mm: None,
            gripper: qmarc_proto::Gripper(qmarc_proto::Gripper::ABSENT),
            belt_asked: None,
            belt: None,
        }
    }

    /// Shows a conveyor session's belt, queue and parts picked and missed (`belt`): asked of
    /// its command service every [`BELT_EVERY`].
    pub fn with_belt(mut self, belt: bool) -> Live {
        self.belt_asked = belt.then_some((None, None));
        self
    }

    /// Asks the session for its belt and parts, when due.
    fn ask_belt(&mut self) {
        let Some((client, asked)) = &mut self.belt_asked else { return };
        if asked.is_some_and(|t| t.elapsed() < BELT_EVERY) {
            return;
        }
        *asked = Some(Instant::now());
        if client.is_none() {
            *client = CommandClient::connect(&self.location).ok();
        }
        let Some(c) = client else { return };
        match c.send(CommandRequest::of(CommandKind::Status)) {
            Ok(s) if s.conveyor.active == 1 => self.belt = Some(s.conveyor),
            Ok(_) => {}
            // The session has ended (or is not there yet): connect again next time.
            Err(_) => *client = None,
        }
    }

    /// Shows where the effector of `robot` is, as the samples come.
    pub fn with_robot(mut self, robot: Option<qmarc_kinematics::Robot>) -> Live {
        self.robot = robot;
        self
    }

    /// Where the effector is and the gripper, for the title bar: ` · effector -12.3 4.5
    /// -650.0 mm · gripper closed` (empty before the first sample).
    pub fn whereabouts(&self) -> String {
        let mut s = String::new();
        if let Some([x, y, z]) = self.effector_mm {
            s.push_str(&format!(" · effector {x:.1} {y:.1} {z:.1} mm"));
        }
        if self.gripper.code() >= 0 {
            s.push_str(&format!(" · gripper {}", self.gripper.name()));
        }
        if let Some(belt) = &self.belt {
            s.push_str(&format!(" · {}", belt.describe()));
        }
        s
    }

    /// The live view of the move the starter `starter_pid` runs with `starter_args` (its
    /// `--iox-prefix`, or its own default `qmarc_<pid>_`) under `iox_root`.
    pub fn for_move(starter_args: &[String], iox_root: &str, starter_pid: u32) -> Live {
        let prefix = starter_args.iter().find_map(|a| a.strip_prefix("--iox-prefix=")).map_or_else(
            || format!("{}{starter_pid}_", qmarc_session::discovery::PREFIX_STEM),
            str::to_string,
        );
        Live::new(IpcLocation::new(&prefix, iox_root))
    }

    /// The charts page's line about it.
    pub fn title(&self) -> String {
        format!(
            "LIVE: the last {WINDOW_S} s · {} samples, {} lost · the move's results when it ends",
            self.samples, self.lost
        )
    }

    /// Attaches when the move's telemetry is there, takes what arrived, lets go at the end;
    /// reads homing's stage from the run's progress page.
    pub fn poll(&mut self) {
        use qmarc_proto::progress::Progress;
        if self.progress.is_none() {
            self.progress = Progress::open(&Progress::path(&self.location.prefix)).ok();
        }
        self.stage = self
            .progress
            .as_ref()
            .and_then(|p| qmarc_plugins::homing::describe_progress(p.read().detail));
        if self.ended {
            return;
        }
        self.ask_belt();
        if self.reader.is_none() {
            if self.tried.is_some_and(|t| t.elapsed() < RETRY) {
                return;
            }
            self.tried = Some(Instant::now());
            self.reader = TelemetryReader::open_run(&self.location).ok();
        }
        let Some(reader) = &mut self.reader else { return };
        let got: Vec<_> = std::iter::from_fn(|| reader.receive().ok().flatten()).collect();
        let ended = reader.end().is_some();
        (self.samples, self.lost) = (reader.received(), reader.lost());
        for s in got.iter().filter(|s| !is_last(s)) {
            self.push(s);
        }
        if ended {
            self.ended = true;
            self.reader = None;
        }
    }

    /// Adds sample `s` and drops what is older than the window.
    fn push(&mut self, s: &qmarc_proto::telemetry::TelemetrySample) {
        if let Some(robot) = &self.robot
            && let Ok(mm) = robot.mm_of(&[s.act[0], s.act[1], s.act[2]])
        {
            self.effector_mm = Some(mm);
        }
        self.gripper = qmarc_proto::Gripper(s.gripper);
        let n = (s.n_motors as usize).min(s.cmd.len());
        let series = &mut self.series;
        series.cmd.resize_with(n, Vec::new);
        series.act.resize_with(n, Vec::new);
        series.dac.resize_with(n, Vec::new);
        let t = s.time_ns as f64 / 1e9;
        series.cycle.push(s.cycle as f64);
        series.t.push(t);
        for m in 0..n {
            series.cmd[m].push(s.cmd[m]);
            series.act[m].push(s.act[m]);
            series.dac[m].push(f64::from(s.dac[m]));
        }
        if s.period_ns > 0 {
            series.period_us.push((t, f64::from(s.period_ns) / 1e3));
        }
        let old = series.t.partition_point(|&x| x < t - WINDOW_S);
        if old > series.t.len() / 2 {
            // Trimmed in bulk: a window's worth at a time, not a shift per sample.
            series.cycle.drain(..old);
            series.t.drain(..old);
            for v in series.cmd.iter_mut().chain(&mut series.act).chain(&mut series.dac) {
                v.drain(..old.min(v.len()));
            }
            let p = series.period_us.partition_point(|&(x, _)| x < t - WINDOW_S);
            series.period_us.drain(..p);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Issue 30: the effector's place (through the forward kinematics of the samples' actual
    /// positions) and the gripper, for the title bar; nothing before a sample or without a
    /// Delta.
    #[test]
    fn the_effector_and_the_gripper_are_shown_from_the_samples() {
        let s = qmarc_config::Settings::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml"),
            &qmarc_config::Names::any(),
        )
        .unwrap();
        let robot = s.robot().unwrap();
        let location = IpcLocation::new("qmarc_livexyz_", "/tmp/iceoryx2");
        let mut live = Live::new(location.clone()).with_robot(Some(robot));
        assert_eq!(live.whereabouts(), "");
        let counts = robot.counts_of(&qmarc_kinematics::Point::new(0.02, -0.01, -0.64)).unwrap();
        let sample = qmarc_proto::telemetry::TelemetrySample {
            act: [counts[0], counts[1], counts[2], 0.0],
            n_motors: 3,
            gripper: qmarc_proto::Gripper::CLOSE,
            ..Default::default()
        };
        live.push(&sample);
        assert_eq!(live.whereabouts(), " · effector 20.0 -10.0 -640.0 mm · gripper closing");
        let mut plain = Live::new(location);
        plain.push(&qmarc_proto::telemetry::TelemetrySample {
            gripper: qmarc_proto::Gripper::ABSENT,
            ..sample
        });
        assert_eq!(plain.whereabouts(), "", "no Delta, no gripper");
    }

    /// Issue 28, item 9: while homing runs, the console has its motor and stage from the
    /// run's progress page, as the CLI's status line (before: only "home running 11 s").
    #[test]
    fn homing_shows_its_motor_and_stage() {
        use qmarc_proto::progress::Progress;
        let prefix = format!("qmarc_livestage{}_", std::process::id());
        let mut live = Live::new(IpcLocation::new(&prefix, "/tmp/iceoryx2"));
        live.poll();
        assert_eq!(live.stage, None, "no progress page yet");
        let path = Progress::path(&prefix);
        let page = Progress::create(&path).unwrap();
        page.set_cycle(1234, 2 << 8 | 3);
        live.poll();
        let _ = std::fs::remove_file(&path);
        assert_eq!(live.stage.as_deref(), Some("homing motor 2: backing off the top switch"));
        page.set_cycle(1235, 0);
        live.poll();
        assert_eq!(live.stage, None, "not homing");
    }
}
