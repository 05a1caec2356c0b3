//! `qmarc-cell camera`: the cell's camera, on the camera's PC. It runs the camera server of
//! its settings (`qmarc-camera`, the sim or images backend, with an iceoryx2 prefix of its
//! own), merges the frames of one part into one part numbered for the whole cell
//! ([`qmarc_conveyor::PartQueue::detect`]), and publishes each part once, its exposure on the
//! system clock and its place on the cell's belt (the camera's belt coordinates). It answers
//! the robots that join with the cell's belt ([`CellBelt`]) and the parts of the last
//! seconds, and its liveliness token says the cell has its camera. One camera a cell.

use crate::keys::key;
use crate::session::{self, failed, json};
use crate::wire::{CellBelt, WirePart};
use qmarc_config::{Mode, RunSpec, Settings};
use qmarc_conveyor::{Belt, BeltMotion, Detection, PartQueue};
use qmarc_proto::camera::open_camera_service;
use qmarc_proto::service::{IpcLocation, create_node, run_file};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};
use zenoh::Wait;

/// How often the camera node looks for detections and queries.
const POLL: Duration = Duration::from_millis(1);
/// The parts a robot that (re)joins is told of: those of the last seconds.
pub const RECENT_S: f64 = 10.0;
/// How far past its field the camera remembers a part, mm: beyond, a detection is a new part.
const FORGET_PAST_MM: f64 = 100.0;

/// The cell's camera, as `qmarc-cell camera` was told to run it.
#[derive(Debug, Clone)]
pub struct CameraNode {
    /// The cell.
    pub cell: String,
    /// The camera's settings (`[conveyor]` the belt, `[camera]` the camera).
    pub settings: Settings,
    /// The Zenoh session's file (`None`: rmw_zenoh's default).
    pub zenoh_config: Option<PathBuf>,
    /// The iceoryx2 root of its camera server.
    pub iox_root: String,
    /// Where `qmarc-camera` is.
    pub bin_dir: PathBuf,
    /// How long it runs, s (0: until a stop signal).
    pub seconds: f64,
}

/// What the camera saw, at its end.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Seen {
    /// Parts, each once.
    pub parts: u32,
    /// Detections (a part is seen in several frames).
    pub detections: u64,
}

/// The camera node's state.
struct Numbering {
    queue: PartQueue,
    belt: Belt,
    motion: BeltMotion,
    epoch_mono_ns: u64,
    realtime_offset_ns: i64,
    recent: VecDeque<WirePart>,
    seen: Seen,
    /// The belt's furthest count seen, once a detection said one.
    last_counts: Option<i64>,
}

impl Numbering {
    /// A detection: the part it is, if new.
    fn detect(&mut self, d: &qmarc_proto::camera::PartDetection) -> Option<WirePart> {
        self.seen.detections += 1;
        // A camera that latched the belt's encoder says where; else the belt's own motion.
        let counts = if d.latched() {
            d.latched_counts
        } else {
            let t_s = d.exposure_ns.saturating_sub(self.epoch_mono_ns) as f64 * 1e-9;
            (self.motion.at(t_s).0 / self.belt.mm_per_count).floor() as i64
        };
        self.last_counts = Some(self.last_counts.map_or(counts, |c| c.max(counts)));
        let seen = Detection {
            t_ns: d.exposure_ns,
            latched_counts: counts,
            belt_mm: d.belt_mm,
            across_mm: d.across_mm,
        };
        let id = self.queue.detect(seen, &self.belt)?;
        self.seen.parts += 1;
        let t_ns = (d.exposure_ns as i64 + self.realtime_offset_ns).max(0) as u64;
        let part = WirePart { id, t_ns, belt_mm: d.belt_mm, across_mm: d.across_mm };
        self.recent.push_back(part);
        let keep_from = t_ns.saturating_sub((RECENT_S * 1e9) as u64);
        while self.recent.front().is_some_and(|p| p.t_ns < keep_from) {
            self.recent.pop_front();
        }
        Some(part)
    }
}

impl CameraNode {
    /// Runs the cell's camera until a stop signal (or `seconds`): what it saw.
    pub fn run(&self) -> anyhow::Result<Seen> {
        qmarc_timer::stop::install()?;
        let session = session::open(self.zenoh_config.as_deref())?;
        let token_key = key(&self.cell, "camera");
        if let Some(other) = session::alive(&session, &token_key, Duration::from_secs(2))?.first() {
            let why = format!("it has its camera already (its token {other}): one camera a cell");
            return Err(crate::Refused { cell: self.cell.clone(), why }.into());
        }
        let epoch_mono_ns = qmarc_timer::clock::monotonic_now_ns();
        let realtime_offset_ns = qmarc_timer::clock::realtime_offset_ns();
        let epoch_ns = (epoch_mono_ns as i64 + realtime_offset_ns) as u64;
        let belt = CellBelt::of(&self.cell, &self.settings, epoch_ns);
        let location =
            IpcLocation::checked(&format!("qmarc_cellcam_{}_", std::process::id()), &self.iox_root)
                .map_err(anyhow::Error::msg)?;
        let spec = RunSpec {
            settings: self.settings.clone(),
            mode: Mode::Conveyor,
            deterministic: false,
            unpaced: false,
            unhomed: false,
            iox_prefix: location.prefix.clone(),
            iox_root: location.root.clone(),
            epoch_ns: epoch_mono_ns,
        };
        let run = run_file(&location.prefix);
        spec.write(&run)?;
        let result =
            self.serve(&session, &location, &run, &belt, (epoch_mono_ns, realtime_offset_ns));
        location.remove_files();
        let _ = std::fs::remove_file(&run);
        result
    }

    /// The camera server's detections, numbered and published, until the end.
    fn serve(
        &self,
        session: &zenoh::Session,
        location: &IpcLocation,
        run: &Path,
        belt: &CellBelt,
        (epoch_mono_ns, realtime_offset_ns): (u64, i64),
    ) -> anyhow::Result<Seen> {
        let node = create_node::<iceoryx2::prelude::ipc::Service>("qmarc-cell-camera", location)?;
        let detections = open_camera_service(&node)?
            .subscriber_builder()
            .create()
            .map_err(|e| anyhow::anyhow!("the camera's subscriber: {e:?}"))?;
        let program = self.bin_dir.join("qmarc-camera");
        let mut cmd = std::process::Command::new(&program);
        cmd.arg(format!("--settings={}", run.display()));
        qmarc_program::process::with_parent_death_signal(&mut cmd);
        let mut camera =
            cmd.spawn().map_err(|e| anyhow::anyhow!("cannot start {}: {e}", program.display()))?;
        let ended = (|| {
            let _token = session
                .liveliness()
                .declare_token(key(&self.cell, "camera"))
                .wait()
                .map_err(failed("the camera's token"))?;
            let parts = session
                .declare_publisher(key(&self.cell, "parts"))
                .wait()
                .map_err(failed("the parts' publisher"))?;
            let queryable = |what: &str| {
                session
                    .declare_queryable(key(&self.cell, what))
                    .complete(true)
                    .with(zenoh::handlers::FifoChannel::new(64))
                    .wait()
                    .map_err(failed(format!("the {what} queryable")))
            };
            let (belt_q, recent_q) = (queryable("belt")?, queryable("recent")?);
            let c = &self.settings.conveyor;
            let merge_mm = (4.0 * self.settings.camera.noise_mm).max(5.0);
            let window = [f64::NEG_INFINITY, self.settings.camera.field_mm[1] + FORGET_PAST_MM];
            let mut n = Numbering {
                queue: PartQueue::new(window, merge_mm, 4096),
                belt: Belt { mm_per_count: c.mm_per_count },
                motion: BeltMotion::new(c.speed_mm_s, &c.speed_steps, c.acceleration_mm_s2),
                epoch_mono_ns,
                realtime_offset_ns,
                recent: VecDeque::new(),
                seen: Seen::default(),
                last_counts: None,
            };
            let started = Instant::now();
            let until = (self.seconds > 0.0).then(|| Duration::from_secs_f64(self.seconds));
            while !qmarc_timer::stop::requested() && until.is_none_or(|u| started.elapsed() < u) {
                if let Some(status) = camera.try_wait()? {
                    anyhow::bail!("qmarc-camera ended ({status}): the cell has no camera");
                }
                while let Ok(Some(sample)) = detections.receive() {
                    if let Some(p) = n.detect(sample.payload()) {
                        parts.put(json(&p)).wait().map_err(failed("publishing a part"))?;
                    }
                }
                if let Some(counts) = n.last_counts {
                    n.queue.sweep(counts, &n.belt);
                }
                while let Ok(Some(q)) = belt_q.try_recv() {
                    let _ = q.reply(q.key_expr().clone(), json(belt)).wait();
                }
                while let Ok(Some(q)) = recent_q.try_recv() {
                    let list: Vec<WirePart> = n.recent.iter().copied().collect();
                    let _ = q.reply(q.key_expr().clone(), json(&list)).wait();
                }
                std::thread::sleep(POLL);
            }
            Ok(n.seen)
        })();
        qmarc_program::process::send(&camera, nix::sys::signal::Signal::SIGTERM);
        let _ = camera.wait();
        drop(node);
        ended
    }
}
