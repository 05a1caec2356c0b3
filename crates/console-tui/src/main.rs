//! `qmarc`: the console. `qmarc [--config FILE]` opens it; `qmarc home|step|run …` does the
//! same as `qmarc-starter home|step|run …` without it, for scripts (same options, same exit
//! codes); `qmarc scope …` shows or records a running move's live telemetry; `qmarc cmd …`
//! commands a serving controller (`qmarc-starter serve`).

use anyhow::Context;
use clap::{Args as _, CommandFactory, Parser};
use qmarc_console::app::{App, Quit};
use qmarc_console::form::Form;
use qmarc_console::ui;
use qmarc_starter::cli::MoveOptions;
use ratatui::crossterm::event::{self, Event, KeyEventKind};
use std::ffi::OsString;
use std::io::Write;
use std::os::unix::process::CommandExt;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::time::Duration;

/// Command line of `qmarc`.
#[derive(Debug, Parser)]
#[command(
    name = "qmarc",
    version,
    about = "QMARC console: set up, home, step, run and tune the robot",
    after_help = "Without the console: qmarc [qmarc-starter options] home|step|run [options] \
                  runs qmarc-starter with the same arguments; qmarc scope [--help] shows a \
                  running move's live telemetry; qmarc cmd [--help] commands a serving \
                  controller (qmarc-starter serve)."
)]
struct Args {
    /// Settings file (the one qmarc-starter reads).
    #[arg(long, default_value = "config/qmarc.toml")]
    config: PathBuf,
    /// qmarc-starter to run moves with (default: next to this program).
    #[arg(long)]
    starter: Option<PathBuf>,
    /// Passed to qmarc-starter: prefix of the runs' iceoryx2 files.
    #[arg(long)]
    iox_prefix: Option<String>,
    /// Passed to qmarc-starter: iceoryx2 root directory.
    #[arg(long)]
    iox_root: Option<String>,
    /// Passed to qmarc-starter: the hardware backend of the moves (`sim`, `s626`).
    #[arg(long)]
    backend: Option<String>,
    /// Passed to qmarc-starter: the Sensoray 626's comedi device.
    #[arg(long)]
    device: Option<PathBuf>,
}

fn starter_next_to_me() -> PathBuf {
    std::env::current_exe()
        .ok()
        .and_then(|e| e.parent().map(|d| d.join("qmarc-starter")))
        .unwrap_or_else(|| PathBuf::from("qmarc-starter"))
}

/// True when the console's terminal has hung up (its other end closed).
fn terminal_gone() -> bool {
    use nix::poll::{PollFd, PollFlags, PollTimeout, poll};
    let stdout = std::io::stdout();
    let mut fds = [PollFd::new(std::os::fd::AsFd::as_fd(&stdout), PollFlags::empty())];
    let gone = PollFlags::POLLHUP | PollFlags::POLLERR | PollFlags::POLLNVAL;
    matches!(poll(&mut fds, PollTimeout::ZERO), Ok(n) if n > 0)
        && fds[0].revents().is_some_and(|r| r.intersects(gone))
}

/// The settings file cannot be opened: nothing can be done (exit code "refused").
#[derive(Debug, thiserror::Error)]
#[error("{0}")]
struct Refused(String);

fn run_console(args: &Args) -> anyhow::Result<Option<Quit>> {
    let workdir = std::env::current_dir().context("no working directory")?;
    let form = Form::load_in(&args.config, &workdir).map_err(|e| anyhow::Error::new(Refused(e)))?;
    if !std::io::IsTerminal::is_terminal(&std::io::stdout()) {
        anyhow::bail!("the console needs a terminal; without one, use `qmarc home|step|run …`");
    }
    let mut app = App::new(form, args.starter.clone().unwrap_or_else(starter_next_to_me), workdir);
    // Every move's PNG plots, which the charts page names.
    app.starter_args.push("--plots".to_string());
    app.starter_args.extend(args.iox_prefix.iter().map(|p| format!("--iox-prefix={p}")));
    app.starter_args.extend(args.iox_root.iter().map(|r| format!("--iox-root={r}")));
    app.starter_args.extend(args.backend.iter().map(|b| format!("--backend={b}")));
    app.starter_args.extend(args.device.iter().map(|d| format!("--device={}", d.display())));
    if let Some(root) = &args.iox_root {
        app.iox_root = root.clone();
    }
    // SIGTERM, SIGHUP and a SIGINT from outside end the console like Cancel (aborting a move
    // first); Ctrl-C typed in the console arrives as a key.
    let stop = qmarc_timer::stop::install().context("signal handlers")?;
    let mut terminal = match ratatui::try_init() {
        Ok(t) => t,
        Err(e) => {
            // Raw mode may already be on.
            let _ = ratatui::try_restore();
            return Err(anyhow::Error::new(e).context("cannot set up the terminal"));
        }
    };
    let result = (|| -> anyhow::Result<()> {
        loop {
            // A terminal that went away (window closed, ssh dropped) ends the console like a
            // stop signal, whether or not SIGHUP reached this process.
            let gone = terminal_gone();
            if gone {
                stop.store(true, Ordering::Relaxed);
                std::thread::sleep(Duration::from_millis(50));
            } else {
                terminal.draw(|f| ui::draw(f, &app))?;
                if event::poll(Duration::from_millis(100))? {
                    match event::read()? {
                        Event::Key(k) if k.kind == KeyEventKind::Press => app.on_key(k),
                        _ => {} // a resize redraws on the next turn
                    }
                }
            }
            app.poll();
            if stop.load(Ordering::Relaxed) {
                app.abort();
                app.quit.get_or_insert(Quit::Cancelled);
            }
            if app.quit.is_some() && app.running.is_none() {
                return Ok(());
            }
        }
    })();
    // Whatever ended the loop (an error of the terminal included), a move still running is
    // stopped and waited for: motors disabled, data written.
    let still_running = app.abort_and_wait(Duration::from_secs(30));
    // Restoring a terminal that is gone fails; there is nothing left to restore then.
    let _ = ratatui::try_restore();
    if let Err(pid) = still_running {
        // Dropping the app kills it; its children stop on their parent-death signal.
        anyhow::bail!("qmarc-starter (pid {pid}) did not stop within 30 s of SIGTERM: killed");
    }
    result?;
    // Cancel: the file as it was when the console opened (moves save it before they start).
    if app.quit == Some(Quit::Cancelled) {
        app.form.restore_opened().map_err(anyhow::Error::msg)?;
    }
    Ok(app.quit)
}

/// `qmarc [options] home|step|run …`: the arguments for `qmarc-starter` (the console's own
/// `--starter` taken out, and returned), or `None` when no mode is given. The mode is the
/// first argument that is neither an option nor an option's value; which options take a
/// value comes from the command-line definitions themselves.
fn plain_subcommand(raw: &[OsString]) -> Option<(Option<PathBuf>, Vec<OsString>)> {
    let takes_value: Vec<String> = Args::command()
        .get_arguments()
        .chain(MoveOptions::augment_args(clap::Command::new("qmarc-starter")).get_arguments())
        .filter(|a| a.get_action().takes_values())
        .filter_map(|a| a.get_long().map(|l| format!("--{l}")))
        // qmarc-starter's own: where its two programs are.
        .chain(["--bin-dir".to_string()])
        .collect();
    let mut starter = None;
    let mut pass = Vec::new();
    let mut it = raw.iter();
    let mut mode = false;
    while let Some(a) = it.next() {
        let s = a.to_string_lossy();
        if mode {
            pass.push(a.clone());
        } else if s == "--starter" {
            starter = it.next().map(PathBuf::from);
        } else if let Some(v) = s.strip_prefix("--starter=") {
            starter = Some(PathBuf::from(v));
        } else if takes_value.iter().any(|o| *o == s) {
            pass.push(a.clone());
            pass.extend(it.next().cloned());
        } else {
            mode =
                matches!(s.as_ref(), "home" | "step" | "run" | "jog" | "check" | "move" | "serve");
            if !mode && !s.starts_with('-') {
                return None;
            }
            pass.push(a.clone());
        }
    }
    mode.then_some((starter, pass))
}

fn main() -> ExitCode {
    // `qmarc home|step|run|jog|check …`: the starter's command line, run in place of this
    // process.
    let raw: Vec<OsString> = std::env::args_os().skip(1).collect();
    // `qmarc scope …`: a running move's live telemetry.
    if raw.first().is_some_and(|a| a == "scope") {
        return qmarc_telemetry::scope::main(&raw[1..]);
    }
    // `qmarc cmd …`: a command to a serving controller.
    if raw.first().is_some_and(|a| a == "cmd") {
        return qmarc_console::cmd::main(&raw[1..]);
    }
    if let Some((starter, pass)) = plain_subcommand(&raw) {
        let starter = starter.unwrap_or_else(starter_next_to_me);
        // Named `qmarc` for the starter's usage lines (`qmarc step --help`).
        let err = std::process::Command::new(&starter).arg0("qmarc").args(&pass).exec();
        let _ = writeln!(std::io::stderr(), "qmarc: cannot run {}: {err}", starter.display());
        return ExitCode::from(1);
    }
    let args: Args = qmarc_program::cli::parse_or_exit();
    let outcome = run_console(&args)
        .map(|quit| {
            // Written without panicking: the terminal may be gone.
            let _ = match quit {
                Some(Quit::Saved) => writeln!(
                    std::io::stdout(),
                    "qmarc: settings saved to {}",
                    args.config.display()
                ),
                _ => writeln!(std::io::stdout(), "qmarc: left without saving"),
            };
            ExitCode::SUCCESS
        })
        .map_err(|e| {
            let code = if e.is::<Refused>() {
                qmarc_proto::exit::REFUSED
            } else {
                qmarc_proto::exit::INTERNAL
            };
            (code, e)
        });
    qmarc_program::cli::conclude("qmarc", outcome)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn split(args: &[&str]) -> Option<(Option<PathBuf>, Vec<String>)> {
        let raw: Vec<OsString> = args.iter().map(OsString::from).collect();
        plain_subcommand(&raw)
            .map(|(s, p)| (s, p.into_iter().map(|a| a.to_string_lossy().into_owned()).collect()))
    }

    #[test]
    fn the_mode_is_the_first_argument_that_is_no_option_value() {
        assert_eq!(split(&[]), None);
        assert_eq!(split(&["--config", "run.toml"]), None);
        // A settings file called `step` is a value, not the mode.
        assert_eq!(split(&["--config", "step"]), None);
        assert_eq!(split(&["--config=x.toml", "--iox-root", "/tmp/r/"]), None);
        let (starter, pass) =
            split(&["--config", "step", "--deterministic", "run", "--knots", "home"]).unwrap();
        assert_eq!(starter, None);
        assert_eq!(pass, ["--config", "step", "--deterministic", "run", "--knots", "home"]);
        // The console's --starter is taken out and used.
        let (starter, pass) = split(&["--starter", "/opt/s", "--out=o", "home"]).unwrap();
        assert_eq!(starter, Some(PathBuf::from("/opt/s")));
        assert_eq!(pass, ["--out=o", "home"]);
        let (starter, _) = split(&["--starter=/opt/t", "step", "--size", "-5"]).unwrap();
        assert_eq!(starter, Some(PathBuf::from("/opt/t")));
        // A stray word is left to the console's own parser (which reports it).
        assert_eq!(split(&["stepp"]), None);
    }
}
