//! `qmarc-bench pick`: the classic Delta pick-and-place cycle through a serving session, as a
//! cell program drives it over `qmarc/command`: grip at the pick point, lift 25 mm, cross
//! 300 mm, set down, release, and back — every move an online, time-optimal one at the motor
//! limits (`move --xyz`), each sent when the last has ended (or, with `--blend MM`, when the
//! command is within MM of its target: the next takes over from the moving state).
//!
//! The figures come from the loop, not from the client's clock: the telemetry samples carry
//! the gripper's output, so a cycle is the time from one grip to the next on the loop's clock;
//! the tracking error is the samples' following error and, through the forward kinematics, the
//! effector's distance from its commanded point. They are set beside the thesis' X-Z path
//! (5.2.1: the same 25/300 mm there and back, 0.354 s of motion in a 0.4 s path, about 0.5 s
//! a cycle on the robot, 120 cycles a minute).

use crate::session::Session;
use qmarc_proto::telemetry::TelemetrySample;
use qmarc_session::client::{CommandClient, Fate, OrderLedger};
use qmarc_session::wire::{CommandKind, CommandRequest, CommandResponse};
use qmarc_telemetry::reader::TelemetryReader;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// The thesis' X-Z path (5.2.1, `knots/xz-pick-place-waypoints.txt`): motion between its
/// rests, s.
const THESIS_MOTION_S: f64 = 0.354_24;
/// The same path with its rests, s.
const THESIS_PATH_S: f64 = 0.4;

/// Options of `pick`.
#[derive(Debug, clap::Args)]
pub struct PickArgs {
    /// Cycles measured.
    #[arg(long, default_value_t = 10)]
    pub cycles: u32,
    /// The pick point, mm (x, y, z in the base frame): the thesis path's start.
    #[arg(long, value_delimiter = ',', allow_hyphen_values = true, default_value = "-150,0,-600")]
    pub at: Vec<f64>,
    /// How far the place point is along x, mm.
    #[arg(long, default_value_t = 300.0)]
    pub cross_mm: f64,
    /// How high the part is lifted, mm.
    #[arg(long, default_value_t = 25.0)]
    pub lift_mm: f64,
    /// A fraction of the motors' limits, 0 < F ≤ 1.
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
    /// Send the next target when the command is within this distance of the current one, mm
    /// (0: each move ends at rest first).
    #[arg(long, default_value_t = 0.0)]
    pub blend_mm: f64,
    /// Settings file of the session.
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Directory holding qmarc-starter and its children (default: next to this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
}

/// Runs `pick`.
pub fn run(a: &PickArgs) -> anyhow::Result<()> {
    anyhow::ensure!(a.cycles >= 1, "--cycles must be ≥ 1");
    anyhow::ensure!(a.at.len() == 3, "--at: a point is three numbers X,Y,Z in mm");
    anyhow::ensure!(a.blend_mm >= 0.0 && a.blend_mm < a.lift_mm, "--blend-mm: 0 ≤ MM < --lift-mm");
    let settings = qmarc_config::Settings::load(&a.config, &qmarc_plugins::registry::names())
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let robot = settings.robot().ok_or_else(|| anyhow::anyhow!("no [robot] table"))?;
    let mask = settings
        .s626
        .gripper_dio
        .map(|c| 1u32 << c)
        .ok_or_else(|| anyhow::anyhow!("no gripper: set [s626] gripper_dio"))?;
    let session = Session::start(&a.config, a.bin_dir.as_deref(), "pick")?;
    let measured = session.client().and_then(|client| {
        let reader = TelemetryReader::open(&session.location)
            .map_err(|e| anyhow::anyhow!("telemetry: {e:?}"))?;
        let mut cell = Cell { client, reader, robot, mask, track: Track::default(), a };
        cell.cycles()?;
        Ok(cell.track)
    });
    let ended = session.quit();
    let track = measured?;
    ended?;
    report(a, &settings, &track);
    lock_step(a, &settings)
}

/// The same cycle as a path in lock-step (`run --method pick`, `[pick]`): the controller's
/// own tracking, without the host stalls of a paced session on a VM.
fn lock_step(a: &PickArgs, s: &qmarc_config::Settings) -> anyhow::Result<()> {
    let p = &s.pick;
    if p.at_mm[..] != a.at[..]
        || (p.cross_mm, p.lift_mm, p.speed) != (a.cross_mm, a.lift_mm, a.speed)
    {
        println!("  (the cycle in lock-step runs [pick] of the settings: give it these options)");
        return Ok(());
    }
    let starter = qmarc_program::process::bin_dir(a.bin_dir.as_deref())?.join("qmarc-starter");
    let out =
        std::env::temp_dir().join(format!("qmarc-bench-pick-lockstep-{}", std::process::id()));
    let status = std::process::Command::new(starter)
        .arg(format!("--config={}", a.config.display()))
        .arg(format!("--out={}", out.display()))
        .args(["--unpaced", "run", "--method=pick", "--approach"])
        .stdout(std::process::Stdio::null())
        .status()?;
    let summary = qmarc_report::Summary::read(&out).map_err(anyhow::Error::msg);
    let _ = std::fs::remove_dir_all(&out);
    anyhow::ensure!(status.success(), "the lock-step cycle failed: {status}");
    let e = summary?.effector.ok_or_else(|| anyhow::anyhow!("no effector figures"))?.distance;
    println!(
        "  the same cycle in lock-step (`run --method pick`, no host stall): effector max \
         {:.3} mm, RMS {:.3} mm",
        e.max_mm, e.rms_mm
    );
    Ok(())
}

/// What the telemetry showed while measuring.
#[derive(Default)]
struct Track {
    measuring: bool,
    /// When the gripper's output went on, ns of the loop's clock.
    grips: Vec<u64>,
    last_outputs: u32,
    /// Largest |following error| per motor, counts.
    max_error: [f64; 3],
    /// The effector's distance from its commanded point: largest, and Σ of squares.
    max_mm: f64,
    sum_sq_mm: f64,
    samples: u64,
    lost: u64,
}

/// The session and what it measures.
struct Cell<'a> {
    client: CommandClient,
    reader: TelemetryReader,
    robot: qmarc_kinematics::Robot,
    mask: u32,
    track: Track,
    a: &'a PickArgs,
}

impl Cell<'_> {
    /// To the pick point, then the cycles.
    fn cycles(&mut self) -> anyhow::Result<()> {
        let [x, y, z] = [self.a.at[0], self.a.at[1], self.a.at[2]];
        let (pick, place) = ([x, y, z], [x + self.a.cross_mm, y, z]);
        let up = |p: [f64; 3]| [p[0], p[1], p[2] + self.a.lift_mm];
        self.send(CommandRequest::grip(false))?;
        self.to(pick, 0.0)?;
        for k in 0..=self.a.cycles {
            // The first grip starts the clock, the one after the last cycle stops it.
            self.track.measuring = true;
            self.send(CommandRequest::grip(true))?;
            self.settle()?;
            if k == self.a.cycles {
                break;
            }
            let blend = self.a.blend_mm;
            for (p, b) in [(up(pick), blend), (up(place), blend), (place, 0.0)] {
                self.to(p, b)?;
            }
            self.send(CommandRequest::grip(false))?;
            self.settle()?;
            for (p, b) in [(up(place), blend), (up(pick), blend), (pick, 0.0)] {
                self.to(p, b)?;
            }
        }
        self.drain()
    }

    /// A command, which must be accepted.
    fn send(&mut self, r: CommandRequest) -> anyhow::Result<CommandResponse> {
        let answer = self.client.send(r)?;
        if let Some(refusal) = answer.refused() {
            anyhow::bail!("refused ({}): {}", refusal.name(), answer.reason());
        }
        Ok(answer)
    }

    /// A move to `p`; returns when the command is within `blend` mm of it (0: at rest there).
    fn to(&mut self, p: [f64; 3], blend: f64) -> anyhow::Result<()> {
        self.send(CommandRequest::move_xyz(p, false, self.a.speed))?;
        if blend == 0.0 {
            return self.settle();
        }
        self.poll(|s| {
            let d = (0..3).map(|i| (s.robot.effector_mm[i] - p[i]).powi(2)).sum::<f64>().sqrt();
            s.orders.taken >= s.orders.accepted && d <= blend
        })
    }

    /// Until the last command accepted has settled (at rest, the gripper there).
    fn settle(&mut self) -> anyhow::Result<()> {
        self.poll(|s| OrderLedger::of(s).fate(s.orders.accepted) == Fate::Settled)
    }

    /// Polls the status (every 200 µs, reading the telemetry in between) until `done`.
    fn poll(&mut self, done: impl Fn(&CommandResponse) -> bool) -> anyhow::Result<()> {
        let started = Instant::now();
        loop {
            self.drain()?;
            let s = self.send(CommandRequest::of(CommandKind::Status))?;
            anyhow::ensure!(s.robot.fault == 0, "the session faulted (fault {})", s.robot.fault);
            let not_taken = OrderLedger::of(&s).fate(s.orders.accepted) == Fate::NotTaken;
            anyhow::ensure!(!not_taken, "move {} was not taken", s.orders.accepted);
            if done(&s) {
                return Ok(());
            }
            anyhow::ensure!(started.elapsed() < Duration::from_secs(30), "no end in 30 s");
            std::thread::sleep(Duration::from_micros(200));
        }
    }

    /// Reads every telemetry sample queued.
    fn drain(&mut self) -> anyhow::Result<()> {
        while let Some(s) = self.reader.receive().map_err(|e| anyhow::anyhow!(e))? {
            self.see(&s);
        }
        self.track.lost = self.reader.lost();
        Ok(())
    }

    fn see(&mut self, s: &TelemetrySample) {
        let t = &mut self.track;
        let rising = s.outputs & self.mask != 0 && t.last_outputs & self.mask == 0;
        t.last_outputs = s.outputs;
        if !t.measuring {
            return;
        }
        if rising {
            t.grips.push(s.time_ns);
        }
        for (m, e) in t.max_error.iter_mut().enumerate() {
            *e = e.max(s.following_error[m].abs());
        }
        let at = |c: &[f64; 4]| self.robot.point_of(&[c[0], c[1], c[2]]).ok();
        if let (Some(c), Some(x)) = (at(&s.cmd), at(&s.act)) {
            let mm = (c - x).norm() * 1e3;
            t.max_mm = t.max_mm.max(mm);
            t.sum_sq_mm += mm * mm;
            t.samples += 1;
        }
    }
}

/// Prints the figures.
fn report(a: &PickArgs, s: &qmarc_config::Settings, t: &Track) {
    let mut cycles: Vec<f64> = t.grips.windows(2).map(|w| (w[1] - w[0]) as f64 * 1e-9).collect();
    cycles.sort_by(f64::total_cmp);
    let n = cycles.len().max(1);
    let mean = cycles.iter().sum::<f64>() / n as f64;
    let median = cycles.get(cycles.len() / 2).copied().unwrap_or(f64::NAN);
    let worst = cycles.last().copied().unwrap_or(f64::NAN);
    let grip_s = 2.0 * s.s626.gripper_close_s;
    println!(
        "qmarc-bench pick: {} cycles at ({}, {}, {}) mm: grip, lift {} mm, cross {} mm, set \
         down, release, and back; speed {}, blend {} mm",
        cycles.len(),
        a.at[0],
        a.at[1],
        a.at[2],
        a.lift_mm,
        a.cross_mm,
        a.speed,
        a.blend_mm
    );
    println!(
        "  cycle, grip to grip (the loop's clock): mean {mean:.3} s, median {median:.3} s, \
         worst {worst:.3} s → {:.0} picks/min",
        60.0 / mean
    );
    println!(
        "  of which the gripper {grip_s:.3} s (closing and opening, {} s each); moving and \
         waiting {:.3} s",
        s.s626.gripper_close_s,
        mean - grip_s
    );
    println!(
        "  thesis X-Z path (5.2.1, no gripper): {THESIS_MOTION_S:.3} s of motion in a \
         {THESIS_PATH_S} s path, ≈ 0.5 s a cycle, 120 cycles/min on the robot"
    );
    let rms = (t.sum_sq_mm / t.samples.max(1) as f64).sqrt();
    println!(
        "  tracking error ({} telemetry samples, every {} cycles, {} lost): effector max \
         {:.3} mm, RMS {rms:.3} mm; motors max |e| {:.1} {:.1} {:.1} counts",
        t.samples,
        s.telemetry.every,
        t.lost,
        t.max_mm,
        t.max_error[0],
        t.max_error[1],
        t.max_error[2]
    );
}
