//! `gather.mcap`: a move's data as an MCAP file (profile `ros2`, uncompressed, as rosbag2's
//! MCAP storage writes one) on the [`crate::channels`]: every gathered row, the joint states,
//! the effector, the Deltabot drawn at [`crate::publish::SCENE_PERIOD_NS`] of loop time and the log (the move
//! began, its phases, each part picked or missed, its warnings, its fault, its end).
//!
//! A row's log time is its loop tick on the system clock: tick 0's ([`Recording::started_wall_ns`])
//! plus its `time_s`. Written after the move, from what the loop gathered: never from the loop.

use crate::channels::Channels;
use crate::publish::RowPublisher;
use crate::scene::{BeltLook, PartAt};
use foxglove::messages::log::Level;
use foxglove::{Context, FoxgloveError, McapWriteOptions};
use qmarc_config::Settings;
use qmarc_controller::gather::{Gather, GatherRow};
use qmarc_controller::record::MoveRecord;
use qmarc_report::files::columns;
use qmarc_report::output::{WriteError, write_results_with};
use qmarc_report::summary::Summary;
use std::io::{Cursor, Write};
use std::path::Path;
use std::sync::{Mutex, OnceLock};

/// The name `gather.mcap` has in an output folder.
pub const FILE: &str = "gather.mcap";

/// A part of a conveyor session, as `parts.csv` lists it.
#[derive(Debug, Clone, PartialEq)]
pub struct Part {
    /// Its id.
    pub id: u32,
    /// Along the belt when seen, mm.
    pub belt_mm: f64,
    /// Across the belt, mm.
    pub across_mm: f64,
    /// The belt encoder then, counts.
    pub latched_counts: i64,
    /// `picked`, `missed` or `pending`.
    pub state: String,
    /// The cycle the gripper was told to close on it.
    pub grip_cycle: Option<u64>,
    /// The cycle the gripper was told to open at the place.
    pub place_cycle: Option<u64>,
    /// The effector against it at the grip, mm.
    pub error_mm: Option<f64>,
}

/// What `gather.mcap` is written from.
pub struct Recording<'a> {
    /// The run's settings (the robot, the belt, counts per radian).
    pub settings: &'a Settings,
    /// The gathered rows, in order.
    pub gather: &'a Gather,
    /// The move's summary (mode, warnings, fault).
    pub summary: &'a Summary,
    /// Tick 0 on the system clock, ns since the Unix epoch.
    pub started_wall_ns: u64,
    /// The path's first sample (after the approach).
    pub path_from: u64,
    /// The settle's first sample, if it began.
    pub settle_from: Option<u64>,
    /// A conveyor session's parts.
    pub parts: &'a [Part],
}

/// One line of the log, due at a cycle.
struct Event {
    cycle: u64,
    level: Level,
    message: String,
}

impl<'a> Recording<'a> {
    /// The recording of the move that left `record`, summed up in `summary`.
    pub fn of(
        settings: &'a Settings,
        record: &'a MoveRecord,
        summary: &'a Summary,
        parts: &'a [Part],
    ) -> Recording<'a> {
        Recording {
            settings,
            gather: &record.gather,
            summary,
            started_wall_ns: record.started_wall_ns,
            path_from: record.path_from,
            settle_from: record.settle_from,
            parts,
        }
    }

    /// The log time of row `r`, ns since the Unix epoch.
    pub fn log_ns(&self, r: &GatherRow) -> u64 {
        self.started_wall_ns.saturating_add((r.time_s * 1e9).round().max(0.0) as u64)
    }

    /// The file's bytes.
    pub fn to_bytes(&self) -> Result<Vec<u8>, FoxgloveError> {
        self.to_bytes_until(&|| false)
    }

    /// The file's bytes, unless `stopped` says so first (checked every few hundred rows): then
    /// an error.
    pub fn to_bytes_until(&self, stopped: &dyn Fn() -> bool) -> Result<Vec<u8>, FoxgloveError> {
        let ctx = Context::new();
        // As rosbag2's MCAP storage writes one by default: uncompressed chunks.
        let options = McapWriteOptions::new().profile("ros2").compression(None);
        // About 32 bytes a column a row: the JSON rows dominate.
        let guess = self.gather.rows().len() * 32 * columns(self.gather).len();
        let writer =
            ctx.mcap_writer_with_options(options).create(Cursor::new(Vec::with_capacity(guess)))?;
        let channels = Channels::new(&ctx, &columns(self.gather))?;
        let whole = self.log_all(&channels, stopped);
        drop(channels);
        let bytes = writer.close()?.into_inner();
        if !whole {
            return Err(FoxgloveError::Unspecified(
                "a stop signal arrived while it was written".into(),
            ));
        }
        Ok(bytes)
    }

    /// Writes the move's set into `dir` as `write_results_with` does (`extra`: the set's
    /// texts, `parts.csv`), with gather.mcap when `gather.mcap` is on: encoded on a thread of
    /// its own while gather.csv and gather.m are written, put in the set after them. A
    /// failure to encode it fails the set as a failure to write it does (the rescue folder).
    pub fn write_results(
        &self,
        dir: &Path,
        summary: &mut Summary,
        run_pid: u32,
        extra: &[(&str, String)],
    ) -> Result<(), WriteError> {
        if !self.settings.gather.mcap {
            return write_results_with(dir, self.gather, summary, run_pid, extra, &[]);
        }
        // The thread encodes a copy of the rows (the loop's may be in its shared page, which
        // is not shared between threads).
        let rows = self.gather.clone();
        let (settings, summary_then, parts) = (self.settings, self.summary, self.parts);
        let (started_wall_ns, path_from, settle_from) =
            (self.started_wall_ns, self.path_from, self.settle_from);
        // A stop signal after this (Ctrl-C while the files are written) ends the encoding too.
        let signals = qmarc_timer::stop::count();
        let stopped = move || qmarc_timer::stop::count() > signals;
        std::thread::scope(|scope| {
            let encoding = Mutex::new(Some(scope.spawn(move || {
                let r = Recording {
                    settings,
                    gather: &rows,
                    summary: summary_then,
                    started_wall_ns,
                    path_from,
                    settle_from,
                    parts,
                };
                r.to_bytes_until(&stopped)
            })));
            let encoded: OnceLock<Result<Vec<u8>, String>> = OnceLock::new();
            let write = |w: &mut dyn Write| {
                let bytes = encoded.get_or_init(|| {
                    let handle = encoding.lock().ok().and_then(|mut h| h.take());
                    match handle.map(|h| h.join()) {
                        Some(Ok(Ok(bytes))) => Ok(bytes),
                        Some(Ok(Err(e))) => Err(e.to_string()),
                        _ => Err("its encoding thread panicked".to_string()),
                    }
                });
                match bytes {
                    Ok(b) => w.write_all(b),
                    Err(e) => Err(std::io::Error::other(format!("cannot encode it: {e}"))),
                }
            };
            write_results_with(dir, self.gather, summary, run_pid, extra, &[(FILE, &write)])
        })
    }

    /// Every message, in time order: a `/qmarc/gather` message per row; the joint states
    /// and the effector at the live view's rate (every `telemetry.every` cycles); the scene
    /// every [`crate::publish::SCENE_PERIOD_NS`] of loop time; the log's lines at their cycles. False if
    /// `stopped` ended it first.
    fn log_all(&self, ch: &Channels, stopped: &dyn Fn() -> bool) -> bool {
        let rows = self.gather.rows();
        let belt = (self.gather.fields().conv).then(|| BeltLook::of(self.settings));
        let every = u64::from(self.settings.telemetry.every.max(1));
        let mut publisher =
            RowPublisher::new(self.settings, self.gather.fields(), self.gather.n_motors());
        let mut events = self.events();
        events.sort_by_key(|e| e.cycle);
        let mut events = events.into_iter().peekable();
        let mut next_sample = 0u64;
        for (k, r) in rows.iter().enumerate() {
            if k % 512 == 0 && stopped() {
                return false;
            }
            let ns = self.log_ns(r);
            let final_row = k + 1 == rows.len();
            while let Some(e) = events.next_if(|e| e.cycle <= r.cycle || final_row) {
                ch.say(ns, e.level, &e.message);
            }
            publisher.gather(ch, r, ns);
            if r.cycle < next_sample && !final_row {
                continue;
            }
            next_sample = r.cycle + every;
            publisher.sample(ch, r, ns);
            if publisher.scene_due(ns - self.started_wall_ns, final_row) {
                let parts = belt.as_ref().map(|b| (b, self.parts_at(b, r)));
                let belt = parts.as_ref().map(|(b, p)| (*b, p.as_slice()));
                publisher.scene(ch, r, ns, belt);
            }
        }
        true
    }

    /// Where each part is in row `r`: on the belt from where the camera saw it until the
    /// gripper closes on it, then held until the place; a missed one until it leaves the
    /// drawn stretch.
    fn parts_at(&self, b: &BeltLook, r: &GatherRow) -> Vec<PartAt> {
        let mut out = Vec::new();
        for p in self.parts {
            let moved = (r.conv - p.latched_counts) as f64 * b.conveyor.mm_per_count;
            let along_mm = p.belt_mm + moved;
            let gripped = p.grip_cycle.is_some_and(|c| r.cycle >= c);
            let placed = p.place_cycle.is_some_and(|c| r.cycle >= c);
            if placed || moved < 0.0 {
                continue;
            }
            if gripped {
                out.push(PartAt::Held);
            } else if along_mm <= b.along_mm[1] {
                out.push(PartAt::Belt { along_mm, across_mm: p.across_mm });
            }
        }
        out
    }

    /// The log's lines: the move began, its phases, its parts, its fault, its warnings, its
    /// end.
    fn events(&self) -> Vec<Event> {
        let s = self.summary;
        let first = self.gather.rows().first().map_or(0, |r| r.cycle);
        let last = self.gather.rows().last().map_or(0, |r| r.cycle);
        let info = |cycle, message: String| Event { cycle, level: Level::Info, message };
        let what = match s.trajectory.as_str() {
            t if t.is_empty() || t == s.mode.to_string() => s.mode.to_string(),
            t => format!("{} ({t})", s.mode),
        };
        let mut ev = vec![info(
            first,
            format!(
                "{what} began: {} motors, period {} µs, a row every {} cycles",
                s.n_motors, s.period_us, s.gather_every
            ),
        )];
        if self.path_from > 0 {
            ev.push(info(first, "approach to the path's start".into()));
            ev.push(info(self.path_from, "path".into()));
        }
        if let Some(c) = self.settle_from {
            ev.push(info(c, "settle".into()));
        }
        for p in self.parts {
            let error = p.error_mm.map_or(String::new(), |e| format!(", {e:.2} mm off"));
            match (p.state.as_str(), p.grip_cycle) {
                ("picked", Some(c)) => ev.push(info(c, format!("part {} picked{error}", p.id))),
                ("missed", _) => ev.push(Event {
                    cycle: last,
                    level: Level::Warning,
                    message: format!("part {} missed", p.id),
                }),
                _ => {}
            }
        }
        if let Some(f) = &s.fault {
            ev.push(Event {
                cycle: f.cycle,
                level: Level::Error,
                message: format!("fault {}: {}", f.kind.name(), f.message),
            });
        }
        for w in &s.warnings {
            ev.push(Event { cycle: last, level: Level::Warning, message: w.message.clone() });
        }
        let end = if s.ok { "ended: ok" } else { "ended: not ok" };
        ev.push(info(last, format!("{} {end}, {} cycles", s.mode, s.cycles)));
        ev
    }
}
