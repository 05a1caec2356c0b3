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
