//! A serving session for a benchmark: `qmarc-starter serve` on the settings given, in real
//! time, under a prefix of its own; a client once its loop serves; quit and cleaned up after.

use anyhow::Context;
use qmarc_proto::service::{DEFAULT_ROOT, IpcLocation};
use qmarc_session::client::CommandClient;
use qmarc_session::wire::{CommandKind, CommandRequest};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

/// A running `qmarc-starter serve`.
pub struct Session {
    /// The starter (taken by a quit).
    child: Option<Child>,
    /// Where its services are.
    pub location: IpcLocation,
    scratch: PathBuf,
}

impl Session {
    /// Starts serving on the settings `config` (`name` tells the prefix and scratch folder).
    pub fn start(config: &Path, bin_dir: Option<&Path>, name: &str) -> anyhow::Result<Session> {
        let starter = qmarc_program::process::bin_dir(bin_dir)?.join("qmarc-starter");
        let pid = std::process::id();
        let prefix = format!("qmarc_bench{name}_{pid}_");
        let scratch = std::env::temp_dir().join(format!("qmarc-bench-{name}-{pid}"));
        let child = Command::new(&starter)
            .arg(format!("--config={}", config.display()))
            .arg(format!("--out={}", scratch.display()))
            .arg(format!("--iox-prefix={prefix}"))
            .arg("serve")
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .with_context(|| format!("cannot run {}", starter.display()))?;
        Ok(Session {
            child: Some(child),
            location: IpcLocation::new(&prefix, DEFAULT_ROOT),
            scratch,
        })
    }

    /// A client, once the session's loop serves (within 20 s).
    pub fn client(&self) -> anyhow::Result<CommandClient> {
        let started = Instant::now();
        let serving = qmarc_proto::state::Phase::Moving.wire();
        loop {
            let status = CommandClient::connect(&self.location)
                .and_then(|mut c| c.send(CommandRequest::of(CommandKind::Status)).map(|s| (c, s)));
            match status {
                Ok((c, s)) if s.robot.phase == serving => return Ok(c),
                _ if started.elapsed() < Duration::from_secs(20) => {
                    std::thread::sleep(Duration::from_millis(20))
                }
                Ok(_) => anyhow::bail!("the serving session did not start its loop"),
                Err(e) => return Err(e).context("the serving session did not start"),
            }
        }
    }

    /// Quits the session and waits for it; an error unless it ended cleanly.
    pub fn quit(self) -> anyhow::Result<()> {
        self.quit_with_summary().map(|_| ())
    }

    /// Quits the session and waits for it: its summary.json (the loop's timing), or an error
    /// unless it ended cleanly.
    pub fn quit_with_summary(mut self) -> anyhow::Result<qmarc_report::Summary> {
        let _ = CommandClient::connect(&self.location)
            .and_then(|mut c| c.send(CommandRequest::of(CommandKind::Quit)));
        let child = self.child.take().context("the session was quit already")?;
        let ended = child.wait_with_output();
        let summary = qmarc_report::Summary::read(&self.scratch).map_err(anyhow::Error::msg);
        let _ = std::fs::remove_dir_all(&self.scratch);
        let said = ended.as_ref().map_or(String::new(), |o| {
            String::from_utf8_lossy(&o.stderr).lines().last().unwrap_or_default().to_string()
        });
        anyhow::ensure!(
            ended.is_ok_and(|o| o.status.success()),
            "the serving session did not end cleanly: {said}"
        );
        summary.context("the serving session left no summary")
    }
}

impl Drop for Session {
    /// A session a benchmark leaves on an error is quit (killed if it will not), and its
    /// files go: no serving robot outlives its benchmark.
    fn drop(&mut self) {
        let Some(mut child) = self.child.take() else { return };
        let _ = CommandClient::connect(&self.location)
            .and_then(|mut c| c.send(CommandRequest::of(CommandKind::Quit)));
        let deadline = Instant::now() + Duration::from_secs(10);
        while child.try_wait().ok().flatten().is_none() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(20));
        }
        let _ = child.kill();
        let _ = child.wait();
        self.location.remove_files();
        let _ = std::fs::remove_dir_all(&self.scratch);
    }
}

/// The session's loop alone against with a companion, in interleaved rounds.
pub struct Rounds<'a> {
    /// The sessions' settings.
    pub config: &'a Path,
    /// Where the programs are.
    pub bin_dir: Option<&'a Path>,
    /// Rounds, each a session alone and one with the companion.
    pub rounds: u32,
    /// Each session's length, s.
    pub segment_s: f64,
    /// The sessions' names start with it.
    pub tag: &'a str,
    /// The companion's column head ("bridged").
    pub with: &'a str,
    /// The benchmark's name ("bridge").
    pub bench: &'a str,
    /// What runs beside the session in a round, as the banner says it.
    pub companion: &'a str,
}

impl Rounds<'_> {
    /// Runs the rounds, the order alternating round by round so that neither kind always
    /// meets the host first; `companion` starts what runs beside the session (dropped before
    /// the session quits). Prints each round's loop wake and output latency p99 (from each
    /// session's summary.json) and the medians of the per-round ratios with ÷ alone.
    pub fn run(
        &self,
        companion: &dyn Fn(&Session) -> anyhow::Result<Box<dyn std::any::Any>>,
    ) -> anyhow::Result<()> {
        let pinned =
            std::fs::read_to_string(self.config).is_ok_and(|t| t.contains("servo_cpu = 0"));
        println!(
            "qmarc-bench {}: {} interleaved rounds of {} s: a serving session alone, and with \
             {}{}",
            self.bench,
            self.rounds,
            self.segment_s,
            self.companion,
            if pinned { "; servo and hwserver on CPU 0, the rest off it" } else { "" }
        );
        println!(
            "  round   alone: wake p99  output p99    {:>7}: wake p99  output p99   (µs)",
            self.with
        );
        let (mut wake, mut output) = (Vec::new(), Vec::new());
        for r in 0..self.rounds {
            let mut figures = [(0.0, 0.0); 2];
            let order = if r % 2 == 0 { [false, true] } else { [true, false] };
            for with in order {
                let name = format!("{}{r}{}", self.tag, u8::from(with));
                let session = Session::start(self.config, self.bin_dir, &name)?;
                session.client()?;
                let beside = if with { Some(companion(&session)?) } else { None };
                std::thread::sleep(Duration::from_secs_f64(self.segment_s));
                drop(beside);
                let s = session.quit_with_summary()?;
                figures[usize::from(with)] =
                    (s.timing.wake_latency_us.p99, s.timing.output_latency_us.p99);
            }
            let [(w0, o0), (w1, o1)] = figures;
            println!("  {:>5}   {w0:>14.1}  {o0:>10.1}    {w1:>16.1}  {o1:>10.1}", r + 1);
            wake.push(w1 / w0);
            output.push(o1 / o0);
        }
        let (wake, output) = (crate::stats::median(&wake), crate::stats::median(&output));
        println!(
            "  median p99 ratio {} ÷ alone: wake {wake:.3}, output {output:.3} (goal ≤ 1.1)",
            self.with
        );
        Ok(())
    }
}

/// A copy of the settings `config` with the servo thread and the hwserver on CPU 0
/// (`timer.servo_cpu`, `timer.hwserver_cpu`), and this process (and what it starts after)
/// kept off it: a servo PC's deployment (`--pin`). `what` names the copy.
pub fn pinned_config(config: &Path, what: &str) -> anyhow::Result<PathBuf> {
    let text = std::fs::read_to_string(config)
        .with_context(|| format!("cannot read {}", config.display()))?;
    let mut doc: toml_edit::DocumentMut =
        text.parse().with_context(|| format!("{}", config.display()))?;
    doc["timer"]["servo_cpu"] = toml_edit::value(0);
    doc["timer"]["hwserver_cpu"] = toml_edit::value(0);
    let path = std::env::temp_dir().join(format!("qmarc-bench-{what}-{}.toml", std::process::id()));
    std::fs::write(&path, doc.to_string())?;
    qmarc_timer::cpus::keep_off(&[0])?;
    Ok(path)
}

/// The Python a benchmark's clients run under: `given` (`--python`), else `$QMARC_PYTHON`,
/// else `target/pyenv/bin/python3` (which scripts/test makes).
pub fn python(given: Option<&Path>) -> PathBuf {
    given
        .map(Path::to_path_buf)
        .or_else(|| std::env::var_os("QMARC_PYTHON").map(PathBuf::from))
        .unwrap_or_else(|| PathBuf::from("target/pyenv/bin/python3"))
}
