//! `qmarc-bench bridge`: what the ROS 2 bridge (issue 31) costs the servo loop and what it
//! delivers, each figure measured in one run on this machine:
//!
//! - **The loop with the bridge.** Interleaved rounds of a serving session alone and of one
//!   with `qmarc-bridge` and two ROS 2 subscribers of its joint states (`ros2_client.py`,
//!   Python processes over Zenoh on loopback), the same length each; the loop's wake and
//!   output latency p99 from each session's summary.json, and the median over rounds of the
//!   ratio with ÷ without (the goal: ≤ 1.1). The order alternates round by round, so neither
//!   kind always meets the host first.
//! - **Joint states.** One subscriber for `--stream-s` at the bridge's 250 Hz: the samples lost
//!   (gaps in the attachment's sequence numbers), and the latency from the servo sample (the
//!   joint state's stamp: the loop's tick, on the system clock) to the Python callback.
//! - **A target.** `--targets` targets published on `qmarc/target` 100 ms apart, alternating
//!   between two points: from the publisher's send to the loop's first command of the new
//!   move (the command service's `taken_ns`), on one clock (the send time moved from the
//!   system clock to `CLOCK_MONOTONIC` by their offset, read here).

use crate::session::{Rounds, Session};
use crate::stats::percentiles_us;
use anyhow::Context;
use qmarc_session::client::CommandClient;
use qmarc_session::wire::{CommandKind, CommandRequest};
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Options of `bridge`.
#[derive(Debug, Clone, clap::Args)]
pub struct BridgeArgs {
    /// Interleaved rounds (each a session alone and one with the bridge and two subscribers).
    #[arg(long, default_value_t = 5)]
    pub rounds: u32,
    /// Length of each session of the rounds, s.
    #[arg(long, default_value_t = 10.0)]
    pub segment_s: f64,
    /// How long one subscriber takes joint states, s.
    #[arg(long, default_value_t = 60.0)]
    pub stream_s: f64,
    /// Targets published.
    #[arg(long, default_value_t = 100)]
    pub targets: u32,
    /// Settings file of the sessions.
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Directory holding qmarc-starter and qmarc-bridge (default: next to this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// The Python with eclipse-zenoh and rosbags (default: $QMARC_PYTHON, else
    /// target/pyenv/bin/python3, which scripts/test makes).
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// The ROS 2 client.
    #[arg(long, default_value = "examples/ros2_client.py")]
    pub client: PathBuf,
    /// The servo thread and the hwserver on CPU 0 (`timer.servo_cpu`, `timer.hwserver_cpu`),
    /// everything else — the bridge, its subscribers, the starter — off it: a servo PC's
    /// deployment (docs/ros2.md).
    #[arg(long)]
    pub pin: bool,
}

/// The bridge's joint-state rate, Hz (its default `--rate`).
const RATE_HZ: f64 = 250.0;

/// A bridge on a session and its ROS 2 subscribers; killed on drop.
struct Bridged {
    children: Vec<Child>,
    endpoint: String,
    config: PathBuf,
}

impl Drop for Bridged {
    fn drop(&mut self) {
        for c in &mut self.children {
            let _ = c.kill();
            let _ = c.wait();
        }
        let _ = std::fs::remove_file(&self.config);
    }
}

impl BridgeArgs {
    /// The ROS 2 client with `args`, connected to `endpoint`.
    fn client(&self, endpoint: &str, args: &[String]) -> Command {
        let mut c = Command::new(crate::session::python(self.python.as_deref()));
        c.arg(&self.client).arg(format!("--connect={endpoint}")).args(args);
        c
    }

    /// A bridge on `session`, listening on a free loopback port, once its node is up.
    fn bridge(&self, session: &Session) -> anyhow::Result<Bridged> {
        let port = qmarc_program::net::free_loopback_port();
        let endpoint = format!("tcp/127.0.0.1:{port}");
        let config = std::env::temp_dir().join(format!("qmarc-bench-zenoh-{port}.json5"));
        std::fs::write(
            &config,
            format!(
                "{{ mode: \"peer\", listen: {{ endpoints: [\"{endpoint}\"] }}, \
                 scouting: {{ multicast: {{ enabled: false }}, gossip: {{ enabled: false }} }} }}"
            ),
        )?;
        let bin = qmarc_program::process::bin_dir(self.bin_dir.as_deref())?.join("qmarc-bridge");
        let child = Command::new(&bin)
            .arg(format!("--iox-prefix={}", session.location.prefix))
            .arg(format!("--zenoh-config={}", config.display()))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot run {}", bin.display()))?;
        let bridged = Bridged { children: vec![child], endpoint, config };
        // Up once a client sees a joint state through it.
        let probe =
            self.client(&bridged.endpoint, &["joint-states".into(), "1".into()]).output()?;
        anyhow::ensure!(
            probe.status.success(),
            "no joint state through the bridge: {}",
            String::from_utf8_lossy(&probe.stderr)
        );
        Ok(bridged)
    }
}

/// The bridge and two subscribers of its joint states beside `session`, for a round.
fn beside(a: &BridgeArgs, session: &Session) -> anyhow::Result<Box<dyn std::any::Any>> {
    let mut b = a.bridge(session)?;
    for _ in 0..2 {
        let args = [
            "joint-states".into(),
            "100000000".into(),
            format!("--timeout={}", a.segment_s + 60.0),
        ];
        let sub =
            a.client(&b.endpoint, &args).stdout(Stdio::null()).stderr(Stdio::null()).spawn()?;
        b.children.push(sub);
    }
    Ok(Box::new(b))
}

/// Runs `bridge`.
pub fn run(a: &BridgeArgs) -> anyhow::Result<()> {
    if a.pin {
        let config = crate::session::pinned_config(&a.config, "bridge")?;
        let result = run(&BridgeArgs { config: config.clone(), pin: false, ..a.clone() });
        let _ = std::fs::remove_file(&config);
        return result;
    }
    anyhow::ensure!(a.rounds >= 1 && a.targets >= 1, "--rounds and --targets must be ≥ 1");
    anyhow::ensure!(
        a.client.is_file(),
        "{}: no such client (run from the workspace)",
        a.client.display()
    );
    let rounds = Rounds {
        config: &a.config,
        bin_dir: a.bin_dir.as_deref(),
        rounds: a.rounds,
        segment_s: a.segment_s,
        tag: "br",
        with: "bridged",
        bench: "bridge",
        companion: "qmarc-bridge and 2 Python subscribers of joint_states over Zenoh (loopback)",
    };
    rounds.run(&|session| beside(a, session))?;
    stream_and_targets(a)
}

/// Joint states for `--stream-s`, then `--targets` targets, through one bridge.
fn stream_and_targets(a: &BridgeArgs) -> anyhow::Result<()> {
    let session = Session::start(&a.config, a.bin_dir.as_deref(), "brstream")?;
    let mut client = session.client()?;
    let b = a.bridge(&session)?;
    let n = (RATE_HZ * a.stream_s).round() as u64;
    let args = ["joint-states".into(), n.to_string(), format!("--timeout={}", a.stream_s + 30.0)];
    let out = a.client(&b.endpoint, &args).output()?;
    let lines: Vec<serde_json::Value> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str(l).ok())
        .collect();
    let num = |v: &serde_json::Value, k: &str| v[k].as_i64().unwrap_or(0);
    let seqs: Vec<i64> = lines.iter().map(|l| num(l, "seq")).collect();
    let span = seqs.iter().max().zip(seqs.iter().min()).map_or(0, |(hi, lo)| hi - lo + 1);
    let mut latency: Vec<u64> =
        lines.iter().map(|l| (num(l, "received_ns") - num(l, "stamp_ns")).max(0) as u64).collect();
    let l = percentiles_us(&mut latency);
    // The rate as the subscriber sees it: messages received over the time between the first
    // and the last (issue 42: a rate read from the setting hid 196 Hz of 250).
    let received: Vec<i64> = lines.iter().map(|l| num(l, "received_ns")).collect();
    let elapsed_s = received
        .iter()
        .max()
        .zip(received.iter().min())
        .map_or(0.0, |(hi, lo)| (hi - lo) as f64 * 1e-9);
    let rate = if elapsed_s > 0.0 { (received.len() - 1) as f64 / elapsed_s } else { 0.0 };
    println!(
        "joint_states for {} s at --rate {RATE_HZ} Hz: {} received of {n} ({} lost: gaps in the \
         sequence), {rate:.2} Hz received ({} messages over {elapsed_s:.3} s, first to last); \
         servo sample → Python subscriber p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        a.stream_s,
        lines.len(),
        span - lines.len() as i64,
        received.len(),
        l.p50 / 1e3,
        l.p99 / 1e3,
        l.max / 1e3
    );
    let mut took = targets(a, &b, &mut client)?;
    let t = percentiles_us(&mut took);
    println!(
        "published target → the loop's first command of its move ({} targets, 100 ms apart): \
         p50 {:.2} ms, p99 {:.2} ms, max {:.2} ms",
        took.len(),
        t.p50 / 1e3,
        t.p99 / 1e3,
        t.max / 1e3
    );
    drop(b);
    session.quit_with_summary().map(|_| ())
}

/// Publishes the targets and measures each, ns.
fn targets(a: &BridgeArgs, b: &Bridged, client: &mut CommandClient) -> anyhow::Result<Vec<u64>> {
    let args: Vec<String> = ["targets".to_string(), a.targets.to_string(), "0.1".into()]
        .into_iter()
        .chain(["0.02", "-0.01", "-0.64", "-0.03", "0.02", "-0.65"].map(String::from))
        .collect();
    let publisher =
        a.client(&b.endpoint, &args).stdout(Stdio::piped()).stderr(Stdio::null()).spawn()?;
    let mut taken = Vec::new();
    let start = client.send(CommandRequest::of(CommandKind::Status))?.orders.accepted;
    let mut last = start;
    let deadline = Instant::now() + Duration::from_secs_f64(f64::from(a.targets) * 0.1 + 30.0);
    while taken.len() < a.targets as usize && Instant::now() < deadline {
        let s = client.send(CommandRequest::of(CommandKind::Status))?;
        if s.orders.accepted > last && s.orders.taken >= s.orders.accepted {
            taken.push(s.timing.taken_ns);
            last = s.orders.accepted;
        }
        std::thread::sleep(Duration::from_micros(200));
    }
    let out = publisher.wait_with_output()?;
    let offset = realtime_minus_monotonic();
    let sent: Vec<i64> = String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter_map(|v| v["published_ns"].as_i64())
        .collect();
    anyhow::ensure!(
        sent.len() == taken.len(),
        "{} targets sent, {} taken",
        sent.len(),
        taken.len()
    );
    Ok(sent.iter().zip(&taken).map(|(s, t)| (*t as i64 - (s - offset)).max(0) as u64).collect())
}

/// The system clock less `CLOCK_MONOTONIC`, ns (the smallest of a few paired reads).
fn realtime_minus_monotonic() -> i64 {
    (0..5)
        .map(|_| {
            let mono = qmarc_timer::clock::monotonic_now_ns() as i64;
            let real = std::time::SystemTime::now()
                .duration_since(std::time::UNIX_EPOCH)
                .map_or(0, |d| d.as_nanos() as i64);
            real - mono
        })
        .min()
        .unwrap_or(0)
}
