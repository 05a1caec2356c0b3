//! Spawning and supervising the two children.

use std::os::unix::process::{CommandExt, ExitStatusExt};
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

    fn from_status(s: std::process::ExitStatus) -> Exit {
        match (s.code(), s.signal()) {
            (Some(c), _) => Exit::Code(c),
            (None, Some(sig)) => Exit::Signal(sig),
            (None, None) => Exit::Code(-1),
        }
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
    let mut cmd = Command::new(program);
    cmd.args(args);
    if let Some(log) = log {
        cmd.stderr(log.try_clone()?);
    }
    with_parent_death_signal(&mut cmd);
    cmd.spawn()
}

/// Makes the child of `cmd` receive SIGTERM when the process that spawns it dies, and end
/// itself at once if that process is already gone when it starts (the race the prctl alone
/// leaves). Used for every child a QMARC program starts: no child outlives its parent.
pub fn with_parent_death_signal(cmd: &mut Command) -> &mut Command {
    use nix::sys::prctl;
    use nix::sys::signal::{Signal, raise};
    let parent = nix::unistd::getpid();
    // SAFETY: the closure runs between fork and exec and only makes async-signal-safe calls
    // (sigaction, prctl, getppid, raise).
    unsafe {
        cmd.pre_exec(move || {
            // Until exec the child runs with its parent's signal handlers: a stop signal that
            // arrived now would set the parent's flag in the child's copy of memory and be
            // lost, leaving a child whose parent is gone. With the default action it ends it.
            for sig in [Signal::SIGTERM, Signal::SIGINT, Signal::SIGHUP] {
                nix::sys::signal::signal(sig, nix::sys::signal::SigHandler::SigDfl)?;
            }
            prctl::set_pdeathsig(Signal::SIGTERM)?;
            if nix::unistd::getppid() != parent {
                raise(Signal::SIGTERM)?;
            }
            Ok(())
        })
    }
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
}

impl Supervised {
    /// `child`, named `name`, with its grace times.
    pub fn new(
        name: &'static str,
        child: Child,
        term_after: Duration,
        kill_after: Duration,
    ) -> Supervised {
        Supervised { name, child, exit: None, term_after, kill_after }
    }
}

/// Sends `sig` to `child` (not yet reaped, so its pid cannot have been reused).
pub fn send(child: &Child, sig: nix::sys::signal::Signal) {
    let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(child.id() as i32), sig);
}

/// Waits until every child has ended. When one ends, each other gets its `term_after` to
/// finish on its own (the controller notices a dead hwserver and writes its data, the
/// hwserver's watchdog notices a dead controller), then SIGTERM, then after its `kill_after`
/// SIGKILL. A stop request (`stop`) forwards its signal (SIGINT from Ctrl-C stays SIGINT, so
/// the summaries name what the user did) to all at once, in reverse order of
/// `children` (the controller before the hwserver: its signal is pending by the time the
/// hwserver shuts down, so it reports an abort, not a hwserver fault). Each child's end is
/// reported through `report` as it happens; `tick` runs every few ms meanwhile.
pub fn wait_all(
    children: &mut [Supervised],
    stop: &AtomicBool,
    mut report: impl FnMut(&Supervised),
    mut tick: impl FnMut(),
) {
    use nix::sys::signal::Signal;
    let mut first_exit: Option<Instant> = None;
    let mut termed: Vec<Option<Instant>> = vec![None; children.len()];
    let mut forwarded = false;
    loop {
        for s in children.iter_mut().filter(|s| s.exit.is_none()) {
            if let Ok(Some(status)) = s.child.try_wait() {
                s.exit = Some(Exit::from_status(status));
                first_exit.get_or_insert_with(Instant::now);
                report(s);
            }
        }
        if children.iter().all(|s| s.exit.is_some()) {
            return;
        }
        let forward = stop.load(Ordering::Relaxed) && !forwarded;
        forwarded |= forward;
        let alive = children.iter().zip(termed.iter_mut()).filter(|(s, _)| s.exit.is_none());
        for (s, termed) in alive.rev() {
            if termed.is_none() && forward {
                send(&s.child, forwarded_signal());
                *termed = Some(Instant::now());
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

/// The stop signal this process received (SIGTERM when it is not known).
fn forwarded_signal() -> nix::sys::signal::Signal {
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
        let stubborn = spawn(sh, &["-c".into(), "trap '' TERM; exec sleep 30".into()]).unwrap();
        let ms = Duration::from_millis;
        let mut kids = vec![
            Supervised::new("quick", quick, ms(50), ms(50)),
            Supervised::new("stubborn", stubborn, ms(50), ms(50)),
        ];
        let stop = AtomicBool::new(false);
        let mut seen = Vec::new();
        wait_all(&mut kids, &stop, |s| seen.push(s.name), || {});
        assert_eq!(seen, ["quick", "stubborn"]);
        assert_eq!(kids[0].exit, Some(Exit::Code(4)));
        assert_eq!(
            kids[1].exit,
            Some(Exit::Signal(nix::sys::signal::Signal::SIGKILL as i32)),
            "TERM ignored, then KILL"
        );
    }
}
