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

fn signal_name(sig: i32) -> &'static str {
    match sig {
        libc::SIGKILL => "SIGKILL",
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        libc::SIGSEGV => "SIGSEGV",
        libc::SIGABRT => "SIGABRT",
        libc::SIGBUS => "SIGBUS",
        libc::SIGPIPE => "SIGPIPE",
        libc::SIGHUP => "SIGHUP",
        _ => "signal",
    }
}

/// "qmarc-hwserver exited with code 3", "… was killed by signal 9 (SIGKILL)".
pub fn describe_exit(name: &str, exit: Exit) -> String {
    match exit {
        Exit::Code(c) => format!("{name} exited with code {c}"),
        Exit::Signal(s) => format!("{name} was killed by signal {s} ({})", signal_name(s)),
    }
}

/// Spawns `program` with `args`. The child gets SIGTERM when the starter dies
/// (`PR_SET_PDEATHSIG`), and kills itself at once if the starter is already gone.
pub fn spawn(program: &Path, args: &[String]) -> std::io::Result<Child> {
    let parent = std::process::id() as libc::pid_t;
    let mut cmd = Command::new(program);
    cmd.args(args);
    // SAFETY: the closure runs between fork and exec and only makes async-signal-safe calls
    // (prctl, getppid, raise).
    unsafe {
        cmd.pre_exec(move || {
            libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM as libc::c_ulong, 0, 0, 0);
            if libc::getppid() != parent {
                libc::raise(libc::SIGTERM);
            }
            Ok(())
        });
    }
    cmd.spawn()
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
}

/// How long the survivors get once one child has ended, before SIGTERM and then SIGKILL.
#[derive(Debug, Clone, Copy)]
pub struct Grace {
    /// From the first exit to SIGTERM.
    pub term_after: Duration,
    /// From SIGTERM to SIGKILL.
    pub kill_after: Duration,
}

fn send(child: &Child, sig: i32) {
    // SAFETY: plain kill(2) on our own child's pid (not yet reaped, so not reused).
    unsafe { libc::kill(child.id() as libc::pid_t, sig) };
}

/// Waits until every child has ended. When one ends, the others get `grace.term_after` to
/// finish on their own (the controller notices a dead hwserver, the hwserver's watchdog a
/// dead controller), then SIGTERM, then SIGKILL. A stop request (`stop`) forwards SIGTERM to
/// all at once. Each child's end is reported through `report` as it happens.
pub fn wait_all(
    children: &mut [Supervised],
    stop: &AtomicBool,
    grace: Grace,
    mut report: impl FnMut(&Supervised),
) {
    let mut first_exit: Option<Instant> = None;
    let mut termed: Option<Instant> = None;
    let mut forwarded = false;
    loop {
        for s in children.iter_mut().filter(|s| s.exit.is_none()) {
            if let Ok(Some(status)) = s.child.try_wait() {
                s.exit = Some(Exit::from_status(status));
                first_exit.get_or_insert_with(Instant::now);
                report(s);
            }
        }
        let running: Vec<&Supervised> = children.iter().filter(|s| s.exit.is_none()).collect();
        if running.is_empty() {
            return;
        }
        if stop.load(Ordering::Relaxed) && !forwarded {
            forwarded = true;
            running.iter().for_each(|s| send(&s.child, libc::SIGTERM));
            termed.get_or_insert_with(Instant::now);
        }
        if let Some(t) = first_exit
            && termed.is_none()
            && t.elapsed() >= grace.term_after
        {
            running.iter().for_each(|s| send(&s.child, libc::SIGTERM));
            termed = Some(Instant::now());
        }
        if let Some(t) = termed
            && t.elapsed() >= grace.kill_after
        {
            running.iter().for_each(|s| send(&s.child, libc::SIGKILL));
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exits_are_described() {
        assert_eq!(describe_exit("a", Exit::Code(3)), "a exited with code 3");
        assert_eq!(describe_exit("b", Exit::Signal(15)), "b was killed by signal 15 (SIGTERM)");
        assert!(Exit::Code(0).success());
        assert!(!Exit::Signal(9).success());
    }

    #[test]
    fn survivors_are_terminated_after_the_grace_time() {
        let sh = Path::new("/bin/sh");
        let quick = spawn(sh, &["-c".into(), "exit 4".into()]).unwrap();
        let stubborn = spawn(sh, &["-c".into(), "trap '' TERM; exec sleep 30".into()]).unwrap();
        let mut kids = vec![
            Supervised { name: "quick", child: quick, exit: None },
            Supervised { name: "stubborn", child: stubborn, exit: None },
        ];
        let stop = AtomicBool::new(false);
        let grace =
            Grace { term_after: Duration::from_millis(50), kill_after: Duration::from_millis(50) };
        let mut seen = Vec::new();
        wait_all(&mut kids, &stop, grace, |s| seen.push(s.name));
        assert_eq!(seen, ["quick", "stubborn"]);
        assert_eq!(kids[0].exit, Some(Exit::Code(4)));
        assert_eq!(kids[1].exit, Some(Exit::Signal(libc::SIGKILL)), "TERM ignored, then KILL");
    }
}
