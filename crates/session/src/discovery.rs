//! Which runs are alive: a run's processes are found by what their command lines say (the
//! starter's `--iox-prefix`, or the pid in its default prefix `qmarc_<pid>_`; the children's
//! `--settings=` run file), so that a second run is never started on a live run's files,
//! and a client that was told no prefix says which of several sessions it could mean
//! ([`serving_session`]); what dead runs left in `/dev/shm` is removed
//! ([`remove_stale_files`]).

use qmarc_proto::service::{IpcLocation, run_file};
use qmarc_telemetry::reader::location_of;
use std::path::{Path, PathBuf};
use std::time::SystemTime;

/// The programs a run is made of (a bridge, a scope or a `qmarc cmd` under the same prefix
/// is a client of the run, not the run).
const RUN_PROGRAMS: [&str; 3] = ["qmarc-starter", "qmarc-hwserver", "qmarc-controller"];

/// The subcommands with which `qmarc` runs a move itself, as the starter (`qmarc step …`).
const QMARC_MOVES: [&str; 9] =
    ["step", "run", "home", "jog", "check", "move", "serve", "tune", "trials"];

/// Prefix of the starter's default iceoryx2 prefixes (`qmarc_<pid>_`).
pub const PREFIX_STEM: &str = "qmarc_";

/// A run whose processes are alive.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct LiveRun {
    /// Its iceoryx2 prefix.
    pub prefix: String,
    /// The process that stands for it: its starter, else (a starter killed, its children
    /// still ending) one of its children.
    pub pid: u32,
    /// That process's command line.
    pub command: String,
    /// Where its data go (absolute), as its run file says; `None` before the file is written.
    pub out_dir: Option<PathBuf>,
    /// When its run file was written.
    pub started: Option<SystemTime>,
    /// Its run file says it serves (`qmarc-starter serve`).
    pub serving: bool,
    /// Its run file is the caller's (the same user's).
    pub own: bool,
}

impl std::fmt::Display for LiveRun {
    /// `pid 4242 (qmarc-starter --iox-prefix t4a_ serve), output folder /home/u/A, started
    /// 20:51:03 UTC (2 min 5 s ago)`.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "pid {} ({})", self.pid, self.command)?;
        if let Some(out) = &self.out_dir {
            write!(f, ", output folder {}", out.display())?;
        }
        if let Some(started) = self.started {
            write!(f, ", started {}", describe_time(started, SystemTime::now()))?;
        }
        Ok(())
    }
}

impl LiveRun {
    /// The short form: `pid 4242, output folder /home/u/A`.
    pub fn brief(&self) -> String {
        match &self.out_dir {
            Some(out) => format!("pid {}, output folder {}", self.pid, out.display()),
            None => format!("pid {}", self.pid),
        }
    }
}

/// `at` as `HH:MM:SS UTC (N min S s ago)` seen at `now`.
pub fn describe_time(at: SystemTime, now: SystemTime) -> String {
    let secs = at.duration_since(SystemTime::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let (h, m, s) = (secs / 3600 % 24, secs / 60 % 60, secs % 60);
    let ago = now.duration_since(at).map_or(0, |d| d.as_secs());
    let ago = match ago {
        0..60 => format!("{ago} s ago"),
        60..3600 => format!("{} min {} s ago", ago / 60, ago % 60),
        _ => format!("{} h {} min ago", ago / 3600, ago / 60 % 60),
    };
    format!("{h:02}:{m:02}:{s:02} UTC ({ago})")
}

/// One process: pid, arguments.
type Process = (u32, Vec<String>);

/// Every process but this one, with its arguments (a zombie has none, and is not listed).
fn processes() -> Vec<Process> {
    let me = std::process::id();
    let Ok(entries) = std::fs::read_dir("/proc") else { return Vec::new() };
    entries
        .flatten()
        .filter_map(|e| {
            let pid: u32 = e.file_name().to_str()?.parse().ok()?;
            let raw = std::fs::read(e.path().join("cmdline")).ok()?;
            let args: Vec<String> = raw
                .split(|&b| b == 0)
                .filter(|a| !a.is_empty())
                .map(|a| String::from_utf8_lossy(a).into_owned())
                .collect();
            (pid != me && !args.is_empty()).then_some((pid, args))
        })
        .collect()
}

/// Whether a process other than this one, alive, mentions `needle` in its command line (the
/// children of a starter carry its prefix in their arguments).
pub fn any_process_mentions(needle: &str) -> bool {
    mentions(&processes(), needle)
}

/// Whether one of `procs` mentions `needle` in its command line.
fn mentions(procs: &[Process], needle: &str) -> bool {
    procs.iter().any(|(_, args)| args.iter().any(|a| a.contains(needle)))
}

/// The program of `args` (its file name) if it is one a run is made of: a starter is
/// `qmarc-starter`, or `qmarc` running a move itself (`qmarc step …`; not `qmarc cmd` or
/// `qmarc scope`, which are clients).
fn run_program(args: &[String]) -> Option<&'static str> {
    let name = Path::new(args.first()?).file_name()?.to_str()?;
    let words = || args.iter().skip(1).map(String::as_str);
    if name == "qmarc" {
        let client = words().any(|w| w == "cmd" || w == "scope");
        return (!client && words().any(|w| QMARC_MOVES.contains(&w))).then_some("qmarc-starter");
    }
    RUN_PROGRAMS.into_iter().find(|p| *p == name)
}

/// The value of option `--name` in `args` (`--name=V` or `--name V`).
fn option<'a>(args: &'a [String], name: &str) -> Option<&'a str> {
    let flag = format!("--{name}");
    args.iter().enumerate().find_map(|(i, a)| match a.strip_prefix(&flag) {
        Some("") => args.get(i + 1).map(String::as_str),
        Some(v) => v.strip_prefix('='),
        None => None,
    })
}

/// The iceoryx2 prefix of the run process `pid` with arguments `args` belongs to.
fn prefix_of(pid: u32, args: &[String]) -> Option<String> {
    match run_program(args)? {
        "qmarc-starter" => Some(
            option(args, "iox-prefix")
                .map_or_else(|| format!("{PREFIX_STEM}{pid}_"), str::to_string),
        ),
        _ => {
            let settings = option(args, "settings")?;
            let name = Path::new(settings).file_name()?.to_str()?;
            let prefix = name.strip_suffix("run.json")?;
            (run_file(prefix) == Path::new(settings)).then(|| prefix.to_string())
        }
    }
}

/// The run with iceoryx2 prefix `prefix` if one of its processes is alive (other than this
/// one): what its starter (or a child of it) and its run file say.
pub fn live_run(prefix: &str) -> Option<LiveRun> {
    live_in(&processes(), prefix)
}

/// A live run whose files a run under `prefix` would touch: its prefix is `prefix`, or one
/// starts with the other (a run removes every file that starts with its own prefix).
pub fn live_run_overlapping(prefix: &str) -> Option<LiveRun> {
    let procs = processes();
    let mut prefixes: Vec<String> =
        procs.iter().filter_map(|(pid, args)| prefix_of(*pid, args)).collect();
    prefixes.sort();
    prefixes.dedup();
    prefixes
        .iter()
        .filter(|p| p.starts_with(prefix) || prefix.starts_with(p.as_str()))
        .find_map(|p| live_in(&procs, p))
}

fn live_in(procs: &[Process], prefix: &str) -> Option<LiveRun> {
    let mut mine: Vec<&Process> = procs
        .iter()
        .filter(|(pid, args)| prefix_of(*pid, args).as_deref() == Some(prefix))
        .collect();
    // The starter first.
    mine.sort_by_key(|(pid, args)| (run_program(args) != Some("qmarc-starter"), *pid));
    let (pid, args) = mine.first()?;
    let run = run_file(prefix);
    let spec = qmarc_config::RunSpec::read(&run).ok();
    let out_dir = spec.as_ref().map(|s| {
        let out = &s.settings.gather.out_dir;
        if out.is_absolute() {
            out.clone()
        } else {
            // Relative to the starter's working directory.
            std::fs::read_link(format!("/proc/{pid}/cwd")).map_or(out.clone(), |cwd| cwd.join(out))
        }
    });
    let meta = std::fs::metadata(&run).ok();
    Some(LiveRun {
        prefix: prefix.to_string(),
        pid: *pid,
        command: args.iter().map(|a| shell_word(a)).collect::<Vec<_>>().join(" "),
        out_dir,
        started: meta.as_ref().and_then(|m| m.modified().ok()),
        serving: spec.is_some_and(|s| s.mode.serving()),
        own: meta.is_none_or(|m| {
            use std::os::unix::fs::MetadataExt;
            m.uid() == nix::unistd::geteuid().as_raw()
        }),
    })
}

/// `word` as a shell would need it written (quoted where it holds a space or a quote).
fn shell_word(word: &str) -> String {
    let plain = word.bytes().all(|b| b.is_ascii_alphanumeric() || b"-_=./,:@%+".contains(&b));
    if plain && !word.is_empty() {
        word.to_string()
    } else {
        format!("'{}'", word.replace('\'', r"'\''"))
    }
}

/// Every live serving session (under the iceoryx2 root `root` only, if given), found by
/// their run files: the caller's own first, newest first within each.
pub fn serving_sessions(root: Option<&str>) -> Vec<LiveRun> {
    let procs = processes();
    qmarc_telemetry::reader::runs(root)
        .into_iter()
        .filter_map(|r| live_in(&procs, &r.location.prefix))
        .filter(|r| r.serving)
        .collect()
}

/// The run of `prefix` while it is a serving session (`qmarc-starter serve`): its run file
/// says so. A client makes no iceoryx2 node otherwise: a node under a prefix whose run has
/// ended would leave iceoryx2's files of that prefix behind.
pub fn serving(prefix: &str) -> Option<qmarc_config::RunSpec> {
    qmarc_config::RunSpec::read(&run_file(prefix)).ok().filter(|s| s.mode.serving())
}

/// Why a client has no session to address.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum SessionFindError {
    /// The prefix given is no serving session's.
    #[error(
        "no serving session under iceoryx2 prefix `{prefix}` (its run file {run} is not a \
         running `qmarc-starter serve`'s)"
    )]
    NotServing {
        /// The prefix given.
        prefix: String,
        /// Its run file.
        run: String,
    },
    /// No serving session runs.
    #[error("no serving session in /dev/shm: start `qmarc-starter serve`")]
    None,
    /// Several serving sessions run and no prefix says which.
    #[error(
        "{} serving sessions run; say which with --iox-prefix:{}",
        .0.len(),
        .0.iter().map(|r| format!("\n  --iox-prefix {}   {r}", r.prefix)).collect::<String>()
    )]
    Ambiguous(Vec<LiveRun>),
}

/// The serving session a client is for: `prefix`'s, else the only one that runs (under
/// `root`, if given), with its run and what it is; or why there is none — several running
/// without a prefix to choose are listed, never guessed at.
pub fn serving_session(
    prefix: Option<&str>,
    root: Option<&str>,
) -> Result<(IpcLocation, qmarc_config::RunSpec, Option<LiveRun>), SessionFindError> {
    if let Some(prefix) = prefix {
        let spec = serving(prefix).ok_or_else(|| SessionFindError::NotServing {
            prefix: prefix.to_string(),
            run: run_file(prefix).display().to_string(),
        })?;
        return Ok((location_of(prefix, root), spec, live_run(prefix)));
    }
    // The caller's own sessions decide; another user's only where the caller has none.
    let all = serving_sessions(root);
    let (mut own, others): (Vec<_>, Vec<_>) = all.into_iter().partition(|r| r.own);
    let mut live = if own.is_empty() { others } else { std::mem::take(&mut own) };
    if live.len() > 1 {
        return Err(SessionFindError::Ambiguous(live));
    }
    let run = live.pop().ok_or(SessionFindError::None)?;
    let spec = serving(&run.prefix).ok_or(SessionFindError::None)?;
    Ok((location_of(&run.prefix, root), spec, Some(run)))
}

/// The default iceoryx2 prefix of this starter: unique per run, so runs never meet and
/// leftovers can be traced to a dead starter.
pub fn default_prefix() -> String {
    format!("{PREFIX_STEM}{}_", std::process::id())
}

/// Removes what earlier starters under `root` left when they died without cleaning up: their
/// prefix `qmarc_<pid>_` names a starter that no longer exists *and* no process (an orphaned
/// child still shutting down) uses it. iceoryx2 first removes the resources of the prefix's
/// dead nodes itself (`Node::list`, `try_remove_stale_resources`); then every file left with
/// the prefix goes (its global management segment among them). Returns how many files were
/// removed.
pub fn remove_stale_files(root: &str) -> usize {
    let Ok(entries) = std::fs::read_dir(qmarc_proto::service::SHM_DIR) else {
        return 0;
    };
    // One look at the processes for every prefix found.
    let procs = processes();
    let mut stale: Vec<String> = entries
        .flatten()
        .filter_map(|e| {
            let name = e.file_name().to_string_lossy().into_owned();
            let pid: u32 = name.strip_prefix(PREFIX_STEM)?.split('_').next()?.parse().ok()?;
            Some((pid, format!("{PREFIX_STEM}{pid}_")))
        })
        .filter(|(pid, prefix)| {
            !std::path::Path::new(&format!("/proc/{pid}")).exists() && !mentions(&procs, prefix)
        })
        .map(|(_, prefix)| prefix)
        .collect();
    stale.sort();
    stale.dedup();
    stale
        .iter()
        .map(|p| {
            let location = IpcLocation::new(p, root);
            remove_dead_nodes(&location);
            location.remove_files()
        })
        .sum()
}

/// Removes what an earlier run with this run's own prefix (`--iox-prefix`) left when it
/// died, if no other process uses the prefix now (a run still going is refused later by
/// iceoryx2 itself, its services being in use). Returns how many files were removed.
pub fn remove_own_stale_files(location: &IpcLocation) -> usize {
    if any_process_mentions(&location.prefix) {
        return 0;
    }
    remove_dead_nodes(location);
    location.remove_files()
}

/// Lets iceoryx2 remove the resources of every dead node at `location`.
fn remove_dead_nodes(location: &IpcLocation) {
    use iceoryx2::node::NodeView;
    use iceoryx2::prelude::*;
    let Ok(cfg) = location.config() else { return };
    let _ = Node::<qmarc_proto::service::Link>::list(&cfg, |state| {
        // Without its details iceoryx2 would clean up with its global configuration (which
        // reads ./config/iceoryx2.toml): the files of such a node go by prefix below.
        if let NodeState::Dead(view) = state
            && view.details().is_some()
        {
            let _ = view.try_remove_stale_resources();
        }
        CallbackProgression::Continue
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    fn args(words: &str) -> Vec<String> {
        words.split_whitespace().map(str::to_string).collect()
    }

    #[test]
    fn a_runs_processes_are_found_by_their_prefix() {
        let procs = vec![
            (10, args("/x/qmarc-starter --iox-prefix t4a_ --out A serve")),
            (11, args("/x/qmarc-hwserver --settings=/dev/shm/t4a_run.json")),
            (12, args("/x/qmarc-controller --settings=/dev/shm/t4a_run.json")),
            (20, args("target/debug/qmarc-starter step")),
            (21, args("/x/qmarc-controller --settings /dev/shm/qmarc_20_run.json")),
            // Clients of a run are not the run; a prefix that only ends like another is not it.
            (30, args("/x/qmarc cmd --iox-prefix=t4a_ status")),
            (31, args("/x/qmarc-bridge --iox-prefix=t4a_")),
            (32, args("/x/qmarc-starter --iox-prefix=xt4a_ serve")),
        ];
        let run = live_in(&procs, "t4a_").expect("t4a_ is live");
        // A console's own move is a starter too; its `cmd` and `scope` are clients.
        let console = [
            (40, args("/x/qmarc --iox-prefix c1_ step")),
            (41, args("/x/qmarc cmd --iox-prefix c2_ move --to 1,2,3")),
        ];
        assert_eq!(live_in(&console, "c1_").map(|r| r.pid), Some(40));
        assert_eq!(live_in(&console, "c2_"), None);
        assert_eq!(
            (run.pid, run.command.as_str()),
            (10, "/x/qmarc-starter --iox-prefix t4a_ --out A serve")
        );
        assert_eq!(live_in(&procs, "qmarc_20_").map(|r| r.pid), Some(20));
        // Its starter gone, a child still ending stands for it.
        assert_eq!(live_in(&procs[1..], "t4a_").map(|r| r.pid), Some(11));
        assert_eq!(live_in(&procs[5..7], "t4a_"), None, "only clients");
        assert_eq!(live_in(&procs, "t4_"), None);
    }

    #[test]
    fn times_and_words_are_said_as_a_person_reads_them() {
        let at = SystemTime::UNIX_EPOCH
            + std::time::Duration::from_secs(86_400 * 365 + 20 * 3600 + 51 * 60 + 3);
        let later = |s| at + std::time::Duration::from_secs(s);
        assert_eq!(describe_time(at, later(125)), "20:51:03 UTC (2 min 5 s ago)");
        assert_eq!(describe_time(at, later(7)), "20:51:03 UTC (7 s ago)");
        assert_eq!(describe_time(at, later(3 * 3600 + 60)), "20:51:03 UTC (3 h 1 min ago)");
        assert_eq!(shell_word("--out=my dir"), "'--out=my dir'");
        assert_eq!(shell_word("-150,0,-600"), "-150,0,-600");
    }
}
