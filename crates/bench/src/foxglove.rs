//! `qmarc-bench foxglove`: what the live view (issue 45, `serve --foxglove`) costs the servo
//! loop and what its viewers receive, each figure measured in one run on this machine:
//!
//! - **The loop with the live view.** Interleaved rounds of a serving session alone and of
//!   one with `qmarc-foxglove live` and two viewers subscribed to every channel
//!   (`examples/foxglove_client.py`, Python over the Foxglove WebSocket protocol on
//!   loopback), the same length each; the loop's wake and output latency p99 from each
//!   session's summary.json, and the median of the per-round ratios viewed ÷ alone (the goal:
//!   ≤ 1.1).
//! - **What a viewer receives.** One viewer for `--stream-s`: each channel's messages over
//!   that time, as the viewer counts them.

use crate::session::{Rounds, Session};
use anyhow::Context;
use std::path::PathBuf;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// Options of `foxglove`.
#[derive(Debug, Clone, clap::Args)]
pub struct FoxgloveArgs {
    /// Interleaved rounds (each a session alone and one with the live view and two viewers).
    #[arg(long, default_value_t = 5)]
    pub rounds: u32,
    /// Length of each session of the rounds, s.
    #[arg(long, default_value_t = 10.0)]
    pub segment_s: f64,
    /// How long one viewer counts what it receives, s.
    #[arg(long, default_value_t = 20.0)]
    pub stream_s: f64,
    /// Settings file of the sessions.
    #[arg(long, default_value = "config/qmarc.toml")]
    pub config: PathBuf,
    /// Directory holding qmarc-starter and qmarc-foxglove (default: next to this program).
    #[arg(long)]
    pub bin_dir: Option<PathBuf>,
    /// The Python with websockets, protobuf and rosbags (default: $QMARC_PYTHON, else
    /// target/pyenv/bin/python3, which scripts/test makes).
    #[arg(long)]
    pub python: Option<PathBuf>,
    /// The viewer.
    #[arg(long, default_value = "examples/foxglove_client.py")]
    pub client: PathBuf,
    /// The servo thread and the hwserver on CPU 0 (`timer.servo_cpu`, `timer.hwserver_cpu`),
    /// everything else — the live view, its viewers, the starter — off it: a servo PC's
    /// deployment.
    #[arg(long)]
    pub pin: bool,
}

/// A live view on a session and its viewers; killed on drop.
struct Viewed {
    children: Vec<Child>,
    port: u16,
}

impl Drop for Viewed {
    fn drop(&mut self) {
        for c in self.children.iter_mut().rev() {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

impl FoxgloveArgs {
    /// A viewer of the live view at `port`, for `seconds`.
    fn viewer(&self, port: u16, seconds: f64) -> Command {
        let mut c = Command::new(crate::session::python(self.python.as_deref()));
        c.arg(&self.client)
            .arg(format!("--url=ws://127.0.0.1:{port}"))
            .arg(format!("--seconds={seconds}"));
        c
    }

    /// `qmarc-foxglove live` on `session` at a free loopback port, once it accepts.
    fn live(&self, session: &Session) -> anyhow::Result<Viewed> {
        let port = qmarc_program::net::free_loopback_port();
        let bin = qmarc_program::process::bin_dir(self.bin_dir.as_deref())?.join("qmarc-foxglove");
        let child = Command::new(&bin)
            .arg("live")
            .arg(format!("--iox-prefix={}", session.location.prefix))
            .arg(format!("--addr=127.0.0.1:{port}"))
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .with_context(|| format!("cannot run {}", bin.display()))?;
        let viewed = Viewed { children: vec![child], port };
        let started = Instant::now();
        while std::net::TcpStream::connect(("127.0.0.1", port)).is_err() {
            anyhow::ensure!(
                started.elapsed() < Duration::from_secs(20),
                "the live view never listened"
            );
            std::thread::sleep(Duration::from_millis(20));
        }
        Ok(viewed)
    }
}

/// The live view and two viewers of every channel beside `session`, for a round.
fn beside(a: &FoxgloveArgs, session: &Session) -> anyhow::Result<Box<dyn std::any::Any>> {
    let mut v = a.live(session)?;
    for _ in 0..2 {
        let viewer = a
            .viewer(v.port, a.segment_s + 60.0)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()?;
        v.children.push(viewer);
    }
    Ok(Box::new(v))
}

/// Runs `foxglove`.
pub fn run(a: &FoxgloveArgs) -> anyhow::Result<()> {
    if a.pin {
        let config = crate::session::pinned_config(&a.config, "foxglove")?;
        let result = run(&FoxgloveArgs { config: config.clone(), pin: false, ..a.clone() });
        let _ = std::fs::remove_file(&config);
        return result;
    }
    anyhow::ensure!(a.rounds >= 1, "--rounds must be ≥ 1");
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
        tag: "fx",
        with: "viewed",
        bench: "foxglove",
        companion: "qmarc-foxglove live and 2 Python viewers of every channel (loopback)",
    };
    rounds.run(&|session| beside(a, session))?;
    stream(a)
}

/// One viewer for `--stream-s`: what it received of each channel, a second.
fn stream(a: &FoxgloveArgs) -> anyhow::Result<()> {
    let session = Session::start(&a.config, a.bin_dir.as_deref(), "fxstream")?;
    session.client()?;
    let v = a.live(&session)?;
    let started = Instant::now();
    let out = a.viewer(v.port, a.stream_s).output()?;
    let elapsed = started.elapsed().as_secs_f64();
    let found: serde_json::Value = serde_json::from_slice(&out.stdout)
        .with_context(|| format!("the viewer said: {}", String::from_utf8_lossy(&out.stderr)))?;
    println!(
        "one viewer for {} s ({elapsed:.1} s with its connecting), messages a second received:",
        a.stream_s
    );
    for (topic, n) in found["counts"].as_object().into_iter().flatten() {
        let n = n.as_f64().unwrap_or(0.0);
        println!("  {topic:<16} {:>8.1} /s  ({n} messages)", n / a.stream_s);
    }
    drop(v);
    session.quit_with_summary().map(|_| ())
}
