//! The live view (`qmarc-foxglove live`, `qmarc-starter serve --foxglove`): a serving
//! session's telemetry on the [`crate::channels`], served by the foxglove SDK's WebSocket
//! server behind the [`crate::proxy::Relay`] that speaks `foxglove.websocket.v1`.
//!
//! A process of its own beside the session, as the ROS 2 bridge is: it reads the telemetry
//! service every client reads (the loop never waits for a reader: a full queue loses samples,
//! never a cycle), so a slow or vanished viewer can never slow the servo loop. Each sample
//! (every `telemetry.every` cycles) becomes a `/qmarc/gather` row of the telemetry's columns
//! (`cycle`, `time_s`, `cmdM`, `actM`, `dacM`, `grip`), the joint states and the effector;
//! the scene every 20 ms of loop time; the log says the phases, a fault, the end.

use crate::channels::Channels;
use crate::publish::RowPublisher;
use foxglove::Context;
use foxglove::messages::log::Level;
use qmarc_config::{GatherFields, RunSpec};
use qmarc_controller::gather::GatherRow;
use qmarc_proto::progress::Progress;
use qmarc_proto::service::IpcLocation;
use qmarc_proto::state::{FaultKind, Phase};
use qmarc_proto::telemetry::TelemetrySample;
use qmarc_proto::{Gripper, MAX_MOTORS};
use qmarc_telemetry::reader::TelemetryReader;
use qmarc_timer::clock::realtime_now_ns;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// The address `--foxglove` serves at when given none: Foxglove's own default.
pub const DEFAULT_ADDR: &str = "127.0.0.1:8765";
/// Messages the SDK queues per viewer before it drops the oldest: a second of every channel
/// at the default telemetry rate.
const BACKLOG: usize = 4096;
/// How long a session that is starting may take to publish its telemetry.
const ATTACH_WAIT: Duration = Duration::from_secs(30);
/// How often the telemetry is read.
const POLL: Duration = Duration::from_millis(2);
/// The most samples one turn takes (a second's worth at the default telemetry rate).
const TURN_SAMPLES: usize = 625;

/// The viewers' address cannot be served.
#[derive(Debug, thiserror::Error)]
#[error(
    "cannot serve the live view at {addr}: {reason} (give another address: --foxglove HOST:PORT)"
)]
pub struct AddressTaken {
    /// The address.
    pub addr: String,
    /// Why.
    pub reason: std::io::Error,
}

/// What to serve.
pub struct LiveOptions {
    /// The serving session.
    pub location: IpcLocation,
    /// Its run (settings, mode).
    pub spec: RunSpec,
    /// Where the viewers connect: `host:port`.
    pub addr: String,
}

/// Serves the live view until the session ends or `stop` is set. The address is taken, and
/// the server started, before anything is read: a taken address is an error at once.
pub fn run(opts: &LiveOptions, stop: &AtomicBool) -> anyhow::Result<()> {
    let ctx = Context::new();
    let server = ctx
        .websocket_server()
        .name(format!("qmarc {}", opts.location.prefix))
        .bind("127.0.0.1", 0)
        .message_backlog_size(BACKLOG)
        .start_blocking()
        .map_err(|e| anyhow::anyhow!("the WebSocket server: {e}"))?;
    let relay = match crate::proxy::Relay::start(&opts.addr, server.port()) {
        Ok(r) => r,
        Err(reason) => {
            server.stop().wait_blocking();
            return Err(AddressTaken { addr: opts.addr.clone(), reason }.into());
        }
    };
    eprintln!(
        "qmarc-foxglove: the live view of {} at ws://{} (Foxglove: Open connection → Foxglove WebSocket)",
        opts.location.prefix,
        relay.addr()
    );
    let result = serve(opts, &ctx, stop);
    drop(relay);
    server.stop().wait_blocking();
    result
}

/// The session's telemetry onto the channels of `ctx`.
fn serve(
    opts: &LiveOptions,
    ctx: &std::sync::Arc<Context>,
    stop: &AtomicBool,
) -> anyhow::Result<()> {
    let s = &opts.spec.settings;
    let fields =
        GatherFields { time: true, cmd: true, act: true, dac: true, grip: false, conv: false };
    let Some(mut reader) = attach(&opts.location, stop)? else { return Ok(()) };
    let progress = Progress::open(&Progress::path(&opts.location.prefix)).ok();
    let mut view: Option<(Channels, RowPublisher)> = None;
    let mut watch = crate::watch::Watch::new(&opts.location);
    let mut belt = at_belt(opts);
    let robot = s.robot();
    let (mut phase, mut fault) = (u32::MAX, 0);
    while !stop.load(Ordering::Relaxed) {
        // A turn's samples at most: the session's status and its end are looked at between
        // turns, however fast the samples come.
        for _ in 0..TURN_SAMPLES {
            let Some(sample) = reader.receive().map_err(|e| anyhow::anyhow!(e))? else { break };
            // The channels once the first sample says whether a gripper is wired.
            let (ch, publisher) = match &mut view {
                Some(v) => v,
                None => {
                    let grip = Gripper(sample.gripper).code() >= 0;
                    let fields = GatherFields { grip, ..fields };
                    let n = s.n_motors;
                    let ch = Channels::new(ctx, &qmarc_report::files::columns_of(fields, n))?;
                    let said = format!("live view of {}: {} motors", opts.spec.mode, n);
                    ch.say(realtime_now_ns(), Level::Info, &said);
                    view.insert((ch, RowPublisher::new(s, fields, n)))
                }
            };
            let ns = stamp(progress.as_ref(), &sample);
            let row = row_of(&sample);
            publisher.gather(ch, &row, ns);
            publisher.sample(ch, &row, ns);
            if publisher.scene_due(sample.time_ns, false) {
                // A conveyor session's belt and its parts.
                let effector = robot
                    .as_ref()
                    .and_then(|r| r.mm_of(&[row.act[0], row.act[1], row.act[2]]).ok());
                let parts = belt.as_mut().map(|b| {
                    b.receive();
                    b.parts(effector, row.grip)
                });
                let drawn = belt.as_ref().zip(parts.as_deref()).map(|(b, p)| (&b.look, p));
                publisher.scene(ch, &row, ns, drawn);
            }
            if sample.phase != phase {
                phase = sample.phase;
                let name = Phase::from_wire(phase).map_or("unknown", Phase::name_serving);
                ch.say(ns, Level::Info, &format!("phase: {name}"));
            }
            if sample.fault != 0 && sample.fault != fault {
                fault = sample.fault;
                let kind = FaultKind::from_wire(fault - 1).map_or("unknown", FaultKind::name);
                ch.say(ns, Level::Error, &format!("fault {kind}"));
            }
        }
        if let Some((ch, _)) = &view
            && let (Some(c), Some(b)) = (watch.poll(ch, realtime_now_ns()), belt.as_mut())
        {
            b.status(c);
        }
        if reader.end().is_some() {
            if let Some((ch, _)) = &view {
                ch.say(realtime_now_ns(), Level::Info, "the session ended");
            }
            return Ok(());
        }
        std::thread::sleep(POLL);
    }
    Ok(())
}

/// A conveyor session's belt, read from its camera (none for another session, or when the
/// camera's service cannot be read: said, and the robot is drawn alone).
fn at_belt(opts: &LiveOptions) -> Option<crate::belt::LiveBelt> {
    if opts.spec.mode != qmarc_config::Mode::Conveyor {
        return None;
    }
    crate::belt::LiveBelt::open(&opts.location, &opts.spec.settings)
        .map_err(|e| eprintln!("qmarc-foxglove: the belt's parts will not be drawn: {e}"))
        .ok()
}

/// The session's telemetry, once it publishes (`serve --foxglove` starts the view with it);
/// `None` if a stop signal came first.
fn attach(location: &IpcLocation, stop: &AtomicBool) -> anyhow::Result<Option<TelemetryReader>> {
    let since = Instant::now();
    loop {
        match TelemetryReader::open_run(location) {
            Ok(r) => return Ok(Some(r)),
            Err(e) if since.elapsed() > ATTACH_WAIT => {
                anyhow::bail!("the session's telemetry: {e:?}")
            }
            _ if stop.load(Ordering::Relaxed) => return Ok(None),
            _ => std::thread::sleep(Duration::from_millis(50)),
        }
    }
}

/// A telemetry sample as a gathered row (no belt counts).
fn row_of(s: &TelemetrySample) -> GatherRow {
    let mut dac = [0; MAX_MOTORS];
    dac.copy_from_slice(&s.dac);
    GatherRow {
        cycle: s.cycle,
        time_s: s.time_ns as f64 / 1e9,
        cmd: s.cmd,
        act: s.act,
        dac,
        grip: Gripper(s.gripper).code(),
        conv: 0,
    }
}

/// When the loop took sample `s`, on the system clock: its tick from the session's tick 0
/// (its progress page) where the session runs in real time, which a sample less than a second
/// old says; else (lock-step: simulated time) now.
fn stamp(progress: Option<&Progress>, s: &TelemetrySample) -> u64 {
    let now = realtime_now_ns();
    let Some(t0) = progress.map(|p| p.read().t0_ns).filter(|&t| t != 0) else { return now };
    let taken = t0.saturating_add(s.time_ns);
    match qmarc_timer::clock::monotonic_now_ns().checked_sub(taken) {
        Some(age) if age < 1_000_000_000 => now - age,
        _ => now,
    }
}
