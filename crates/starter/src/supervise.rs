//! Spawning and supervising the two children.

use qmarc_program::process::{send, with_parent_death_signal};
use std::path::Path;
use std::process::{Child, Command};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How a child ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Exit {
    /// It exited with this code.
    Code(i32),
    /// A signal killed it.
    Signal(i32),
}

impl Exit {
    /// True for exit code 0.
    pub fn success(self) -> bool {
        self == Exit::Code(0)
    }
}

/// A child that job control stopped (SIGSTOP, SIGTSTP, …) for longer than the run can wait:
/// the starter ended the run for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Unresponsive {
    /// The signal that stopped it.
    pub signal: i32,
    /// How long it had been stopped when the starter ended the run.
    pub stopped_for: Duration,
}

impl Unresponsive {
    /// "qmarc-controller stopped responding: it was stopped by SIGSTOP for 0.10 s".
    pub fn describe(&self, name: &str) -> String {
        format!(
            "{name} stopped responding: it was stopped by {} for {:.2} s",
            qmarc_timer::stop::signal_name(self.signal),
            self.stopped_for.as_secs_f64()
        )
    }
}

/// "qmarc-hwserver exited with code 2 (fault)", "… was killed by SIGKILL".
pub fn describe_exit(name: &str, exit: Exit) -> String {
    match exit {
        Exit::Code(c) => {
            format!("{name} exited with code {c} ({})", qmarc_proto::exit::describe(c))
        }
        Exit::Signal(s) => {
            format!("{name} was killed by {}", qmarc_timer::stop::signal_name(s))
        }
    }
}

/// Spawns `program` with `args`. The child gets SIGTERM when the starter dies
/// (`PR_SET_PDEATHSIG`), and ends itself at once if the starter is already gone.
pub fn spawn(program: &Path, args: &[String]) -> std::io::Result<Child> {
    spawn_logged(program, args, None)
}

/// [`spawn`], the child's standard error going to `log` (appended) instead of ours: the
/// messages of a trial's processes, kept apart from the trials' progress bar and table.
pub fn spawn_logged(
    program: &Path,
    args: &[String],
    log: Option<&std::fs::File>,
) -> std::io::Result<Child> {
    command_logged(program, args, log)?.spawn()
}

/// The command [`spawn_logged`] spawns, for a caller that sets more of it first.
pub fn command_logged(
    program: &Path,
    args: &[String],
    log: Option<&std::fs::File>,
) -> std::io::Result<Command> {
    let mut cmd = Command::new(program);
    cmd.args(args);
    if let Some(log) = log {
        cmd.stderr(log.try_clone()?);
    }
    with_parent_death_signal(&mut cmd);
    Ok(cmd)
}

/// A child under supervision.
#[derive(Debug)]
pub struct Supervised {
    /// Its name for messages.
    pub name: &'static str,
    /// The process.
    pub child: Child,
    /// How it ended, once it has.
    pub exit: Option<Exit>,
    /// Once the other child has ended, how long this one may take to finish on its own
    /// before SIGTERM.
    pub term_after: Duration,
    /// After SIGTERM, how long before SIGKILL.
    pub kill_after: Duration,
    /// Since when, and by which signal, it is stopped (job control), if it is.
    stopped: Option<(Instant, i32)>,
    /// Set when it stayed stopped too long and the starter ended the run for it.
    pub unresponsive: Option<Unresponsive>,
}

impl Supervised {
    /// `child`, named `name`, with its grace times.
    pub fn new(
        name: &'static str,
        child: Child,
        term_after: Duration,
        kill_after: Duration,
    ) -> Supervised {
        Supervised {
            name,
            child,
            exit: None,
            term_after,
            kill_after,
            stopped: None,
            unresponsive: None,
        }
    }

    fn pid(&self) -> nix::unistd::Pid {
        nix::unistd::Pid::from_raw(self.child.id() as i32)
    }

    /// Reaps it if it has ended, and notes whether job control stopped or continued it
    /// (`waitpid` with `WUNTRACED | WCONTINUED`: a stopped child is seen at once).
    /// Returns true when it has just ended.
    fn poll(&mut self) -> bool {
        use nix::sys::wait::{WaitPidFlag, WaitStatus, waitpid};
        let flags = WaitPidFlag::WNOHANG | WaitPidFlag::WUNTRACED | WaitPidFlag::WCONTINUED;
        loop {
            match waitpid(self.pid(), Some(flags)) {
                Ok(WaitStatus::Exited(_, code)) => self.exit = Some(Exit::Code(code)),
                Ok(WaitStatus::Signaled(_, sig, _)) => self.exit = Some(Exit::Signal(sig as i32)),
                Ok(WaitStatus::Stopped(_, sig)) => {
                    self.stopped.get_or_insert((Instant::now(), sig as i32));
                    continue;
                }
                Ok(WaitStatus::Continued(_)) => {
                    self.stopped = None;
                    continue;
                }
                Err(nix::errno::Errno::EINTR) => continue,
                // Reaped elsewhere (cannot happen: the starter alone waits for its children).
                Err(_) => self.exit = Some(Exit::Code(-1)),
                Ok(_) => {}
            }
            return self.exit.is_some();
        }
    }
}

/// Ends a child that stays stopped: SIGTERM, then SIGCONT, so that it wakes to its stop
/// request (the controller writes what it gathered; the hwserver disables the motors).
fn wake_to_end(child: &Child) {
    send(child, nix::sys::signal::Signal::SIGTERM);
    send(child, nix::sys::signal::Signal::SIGCONT);
}

/// Waits until every child has ended. When one ends, each other gets its `term_after` to
/// finish on its own (the controller notices a dead hwserver and writes its data, the
/// hwserver's watchdog notices a dead controller), then SIGTERM, then after its `kill_after`
/// SIGKILL. A child that job control stopped for `stall_limit` (the time the other would
/// wait for it: the hwserver's watchdog, the controller's response timeout) stopped
/// responding: it is told to end and continued, so it keeps what it can and cleans up, and
/// `report` names it at once (its `unresponsive` set, its `exit` not yet); a shorter stop is
/// ridden out. A stopped child that is told to end is continued too. A stop request (`stop`)
/// forwards its signal (SIGINT from Ctrl-C stays SIGINT, so the summaries name what the
/// user did) to all at once, in reverse order of
/// `children` (the controller before the hwserver: its signal is pending by the time the
/// hwserver shuts down, so it reports an abort, not a hwserver fault). Each child's end is
/// reported through `report` as it happens; `tick` runs every few ms meanwhile.
pub fn wait_all(
    children: &mut [Supervised],
    stop: &AtomicBool,
    stall_limit: Duration,
    mut report: impl FnMut(&Supervised),
    mut tick: impl FnMut(),
) {
    use nix::sys::signal::Signal;
    let mut first_exit: Option<Instant> = None;
    let mut termed: Vec<Option<Instant>> = vec![None; children.len()];
    let mut forwarded = false;
    loop {
        for s in children.iter_mut().filter(|s| s.exit.is_none()) {
            if s.poll() {
                first_exit.get_or_insert_with(Instant::now);
                report(s);
            }
        }
        if children.iter().all(|s| s.exit.is_some()) {
            return;
        }
        let forward = stop.load(Ordering::Relaxed) && !forwarded;
        forwarded |= forward;
        let alive = children.iter_mut().zip(termed.iter_mut()).filter(|(s, _)| s.exit.is_none());
        for (s, termed) in alive.rev() {
            if termed.is_none() && forward {
                send(&s.child, forwarded_signal());
                *termed = Some(Instant::now());
            }
            if let Some((since, signal)) = s.stopped
                && s.unresponsive.is_none()
                && since.elapsed() >= stall_limit
            {
                s.unresponsive = Some(Unresponsive { signal, stopped_for: since.elapsed() });
                report(s);
                wake_to_end(&s.child);
                termed.get_or_insert_with(Instant::now);
            } else if s.stopped.is_some() && termed.is_some() {
                // Told to end while stopped (a forwarded stop, a SIGTERM): it must run to end.
                send(&s.child, Signal::SIGCONT);
            }
            if termed.is_none() && first_exit.is_some_and(|t| t.elapsed() >= s.term_after) {
                send(&s.child, Signal::SIGTERM);
                *termed = Some(Instant::now());
            }
            if termed.is_some_and(|t| t.elapsed() >= s.kill_after) {
                send(&s.child, Signal::SIGKILL);
            }
        }
        tick();
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// The stop signal this process received (SIGTERM when it is not known): the one it forwards.
pub fn forwarded_signal() -> nix::sys::signal::Signal {
    qmarc_timer::stop::signal()
        .and_then(|s| nix::sys::signal::Signal::try_from(s).ok())
        .unwrap_or(nix::sys::signal::Signal::SIGTERM)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exits_are_described() {
        assert_eq!(describe_exit("a", Exit::Code(3)), "a exited with code 3 (refused)");
        assert_eq!(describe_exit("b", Exit::Signal(15)), "b was killed by SIGTERM");
        assert!(Exit::Code(0).success());
        assert!(!Exit::Signal(9).success());
    }

    #[test]
    fn survivors_are_terminated_after_the_grace_time() {
        let sh = Path::new("/bin/sh");
        let quick = spawn(sh, &["-c".into(), "exit 4".into()]).unwrap();
        // It says when it ignores SIGTERM: the test goes on only then (a shell that had not
        // run its `trap` yet would die of the SIGTERM).
        let ready = std::env::temp_dir().join(format!("qmarc-stubborn-{}", std::process::id()));
        let script = format!("trap '' TERM; : > {}; exec sleep 30", ready.display());
        let stubborn = spawn(sh, &["-c".into(), script]).unwrap();
        let waiting = Instant::now();
        while !ready.exists() {
            assert!(waiting.elapsed() < Duration::from_secs(60), "the shell did not start");
            std::thread::sleep(Duration::from_millis(5));
        }
        let _ = std::fs::remove_file(&ready);
        let ms = Duration::from_millis;
        let mut kids = vec![
            Supervised::new("quick", quick, ms(50), ms(50)),
            Supervised::new("stubborn", stubborn, ms(50), ms(50)),
        ];
        let stop = AtomicBool::new(false);
        let mut seen = Vec::new();
        wait_all(&mut kids, &stop, ms(1000), |s| seen.push(s.name), || {});
        assert_eq!(seen, ["quick", "stubborn"]);
        assert_eq!(kids[0].exit, Some(Exit::Code(4)));
        assert_eq!(
            kids[1].exit,
            Some(Exit::Signal(nix::sys::signal::Signal::SIGKILL as i32)),
            "TERM ignored, then KILL"
        );
    }

    /// A child stopped longer than the limit is reported at once, told to end and continued
    /// (its SIGTERM is delivered: it does not wait for SIGKILL), and its partner, which never
    /// ended, is not waited for.
    #[test]
    fn a_child_stopped_too_long_is_ended_and_named() {
        let sh = Path::new("/bin/sh");
        let stops = spawn(sh, &["-c".into(), "kill -STOP $$; exit 0".into()]).unwrap();
        let ms = Duration::from_millis;
        let mut kids = vec![Supervised::new("stops", stops, ms(60_000), ms(60_000))];
        let stop = AtomicBool::new(false);
        let mut seen = Vec::new();
        let start = Instant::now();
        wait_all(&mut kids, &stop, ms(100), |s| seen.push((s.name, s.exit, s.unresponsive)), || {});
        assert!(start.elapsed() < ms(30_000), "waited for the grace times: {:?}", start.elapsed());
        let u = kids[0].unresponsive.expect("named unresponsive");
        assert_eq!(u.signal, nix::sys::signal::Signal::SIGSTOP as i32);
        assert!(u.stopped_for >= ms(100), "{:?}", u.stopped_for);
        assert_eq!(
            seen,
            [("stops", None, Some(u)), ("stops", Some(Exit::Signal(15)), Some(u))],
            "named when it stopped responding, then when it ended by the SIGTERM"
        );
        assert!(
            u.describe("x").starts_with("x stopped responding: it was stopped by SIGSTOP for ")
        );
    }

    /// A stop shorter than the limit is ridden out: the child goes on and ends by itself.
    #[test]
    fn a_short_stop_is_ridden_out() {
        let sh = Path::new("/bin/sh");
        let child = spawn(sh, &["-c".into(), "sleep 0.3; exit 5".into()]).unwrap();
        let pid = child.id();
        let ms = Duration::from_millis;
        let mut kids = vec![Supervised::new("short", child, ms(60_000), ms(60_000))];
        let stop = AtomicBool::new(false);
        let kill = |sig| nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), sig);
        kill(nix::sys::signal::Signal::SIGSTOP).unwrap();
        let mut polls = 0;
        wait_all(
            &mut kids,
            &stop,
            ms(60_000),
            |_| {},
            || {
                polls += 1;
                if polls == 10 {
                    kill(nix::sys::signal::Signal::SIGCONT).unwrap();
                }
            },
        );
        assert_eq!(kids[0].exit, Some(Exit::Code(5)));
        assert_eq!(kids[0].unresponsive, None);
    }
}
