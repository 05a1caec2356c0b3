//! Children of a QMARC program: spawned so that none outlives its parent
//! ([`with_parent_death_signal`]), signalled ([`send`]), stopped ([`terminate`]), found
//! beside the program ([`bin_dir`]).

use std::os::unix::process::CommandExt;
use std::process::{Child, Command};

/// The directory holding the QMARC binaries: `explicit` (`--bin-dir`), else the one this
/// program is in (where `cargo build` puts them all).
pub fn bin_dir(explicit: Option<&std::path::Path>) -> std::io::Result<std::path::PathBuf> {
    if let Some(d) = explicit {
        return Ok(d.to_path_buf());
    }
    let me = std::env::current_exe()?;
    me.parent().map(std::path::Path::to_path_buf).ok_or_else(|| {
        std::io::Error::new(std::io::ErrorKind::NotFound, "no directory for this program")
    })
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

/// Sends `sig` to `child` (not yet reaped, so its pid cannot have been reused).
pub fn send(child: &Child, sig: nix::sys::signal::Signal) {
    let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(child.id() as i32), sig);
}

/// Stops `child` as its user would — SIGTERM, so that it ends what it started and removes
/// its files — and SIGKILLs it if it has not ended within `grace`; reaps it. Its exit status
/// (`None` if it could not be had). A child that has ended already is only reaped.
pub fn terminate(
    child: &mut Child,
    grace: std::time::Duration,
) -> Option<std::process::ExitStatus> {
    if let Ok(Some(status)) = child.try_wait() {
        return Some(status);
    }
    send(child, nix::sys::signal::Signal::SIGTERM);
    let since = std::time::Instant::now();
    while since.elapsed() < grace {
        if let Ok(Some(status)) = child.try_wait() {
            return Some(status);
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    let _ = child.kill();
    child.wait().ok()
}
