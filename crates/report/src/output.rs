//! The output folder of a move (`--out`): checked before anything is enabled, locked for the
//! run, and written so that no result is ever lost (docs/usage.md "The output folder").
//!
//! - Before the move the starter checks that the folder exists or can be created, that it
//!   can write there, and that its filesystem has room for the move's data ([`check`]), and
//!   takes an exclusive lock on it ([`OutLock`]): a second run on the same folder is refused,
//!   naming the run that holds it.
//! - Earlier results are never removed first. The controller writes the new files into a
//!   fresh folder inside (`.incoming-<pid>`), and only when every one is written puts them in
//!   place, `summary.json` last ([`write_set`]). A refused run writes nothing; a failed write
//!   leaves the last good results as they were.
//! - The folder never mixes two runs' files. Before a new set goes in, the set there is
//!   retired: a complete one (data and summary) is moved to `previous/` (replacing the one
//!   there), an incomplete one (a summary without data: a run whose controller died, or whose
//!   data a second Ctrl-C abandoned) is removed. So the last complete results are always in
//!   the folder or in `previous/`.
//! - If writing still fails after a move (a full disk), the data go to a rescue folder
//!   ([`rescue_dir`]) and the message says where.

use crate::summary::{Summary, Warning, WarningKind};
use nix::fcntl::{Flock, FlockArg};
use qmarc_controller::gather::Gather;
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

/// The lock file in an output folder; it holds the pid of the run that locked it.
pub const LOCK_FILE: &str = ".qmarc.lock";

/// Room kept free on the output filesystem beyond a move's data, bytes.
pub const SPARE_BYTES: u64 = 1 << 20;

/// The output folder cannot be used.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum OutDirError {
    /// It does not exist and cannot be created, or is not a folder.
    #[error("output folder {dir}: cannot create it: {reason}")]
    Create {
        /// The folder.
        dir: PathBuf,
        /// Why.
        reason: std::io::Error,
    },
    /// It names something that is not a folder.
    #[error("output folder {dir}: it is a file, not a folder: give a folder for --out")]
    NotAFolder {
        /// The path.
        dir: PathBuf,
    },
    /// A file cannot be written there.
    #[error("output folder {dir}: cannot write there: {reason}")]
    NotWritable {
        /// The folder.
        dir: PathBuf,
        /// Why.
        reason: std::io::Error,
    },
    /// Its filesystem has too little room.
    #[error(
        "output folder {dir}: its filesystem has {free} bytes free, the move's data need about \
         {need}: free some space, gather less (--gather-every) or give another --out"
    )]
    NoRoom {
        /// The folder.
        dir: PathBuf,
        /// Bytes free.
        free: u64,
        /// Bytes needed (with [`SPARE_BYTES`]).
        need: u64,
    },
    /// Another run holds its lock.
    #[error(
        "output folder {dir} is in use by another run (qmarc-starter pid {pid}): wait for it \
         or give another --out"
    )]
    Locked {
        /// The folder.
        dir: PathBuf,
        /// The other run's pid, 0 if unknown.
        pid: u32,
    },
}

/// An exclusive lock on an output folder, held while it lives (released when the process
/// ends, however it ends).
#[derive(Debug)]
pub struct OutLock {
    _lock: Flock<std::fs::File>,
}

/// Locks `dir` (which must exist) for this process, writing its pid into the lock file.
pub fn lock(dir: &Path) -> Result<OutLock, OutDirError> {
    let path = dir.join(LOCK_FILE);
    let not_writable = |reason| OutDirError::NotWritable { dir: dir.to_path_buf(), reason };
    let file = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .open(&path)
        .map_err(not_writable)?;
    match Flock::lock(file, FlockArg::LockExclusiveNonblock) {
        Ok(mut lock) => {
            let pid = std::process::id().to_string();
            lock.set_len(0)
                .and_then(|()| lock.rewind())
                .and_then(|()| lock.write_all(pid.as_bytes()))
                .map_err(not_writable)?;
            Ok(OutLock { _lock: lock })
        }
        Err((mut file, _)) => {
            let mut text = String::new();
            let _ = file.read_to_string(&mut text);
            Err(OutDirError::Locked {
                dir: dir.to_path_buf(),
                pid: text.trim().parse().unwrap_or(0),
            })
        }
    }
}

/// Checks before a move that `dir` exists (or is created), can be written (a probe file is
/// written and removed) and that its filesystem has room for `bytes` of data.
pub fn check(dir: &Path, bytes: u64) -> Result<(), OutDirError> {
    if dir.metadata().is_ok_and(|m| !m.is_dir()) {
        return Err(OutDirError::NotAFolder { dir: dir.to_path_buf() });
    }
    std::fs::create_dir_all(dir)
        .map_err(|reason| OutDirError::Create { dir: dir.to_path_buf(), reason })?;
    remove_dead_incoming(dir);
    let probe = dir.join(format!(".qmarc-probe-{}", std::process::id()));
    let written = std::fs::write(&probe, b"qmarc");
    let _ = std::fs::remove_file(&probe);
    written.map_err(|reason| OutDirError::NotWritable { dir: dir.to_path_buf(), reason })?;
    if let Ok(st) = nix::sys::statvfs::statvfs(dir) {
        let free = st.blocks_available().saturating_mul(st.fragment_size());
        let need = bytes.saturating_add(SPARE_BYTES);
        if free < need {
            return Err(OutDirError::NoRoom { dir: dir.to_path_buf(), free, need });
        }
    }
    Ok(())
}

/// Removes the `.incoming-<pid>` folders of `dir` whose process is gone (a controller killed
/// while it wrote its data): what they hold never became a result.
fn remove_dead_incoming(dir: &Path) {
    let Ok(entries) = std::fs::read_dir(dir) else { return };
    for e in entries.flatten() {
        let name = e.file_name();
        let Some(pid) = name.to_str().and_then(|n| n.strip_prefix(".incoming-")) else { continue };
        if pid.parse::<u32>().is_ok_and(|p| !Path::new(&format!("/proc/{p}")).exists()) {
            let _ = std::fs::remove_dir_all(e.path());
        }
    }
}

/// Bytes the data files of `rows` gathered rows of `n_motors` take at most: gather.csv and
/// gather.m hold the same numbers (about 24 characters each at most), summary.json a few KiB.
pub fn estimate_bytes(rows: u64, n_motors: usize) -> u64 {
    let per_row = 2 * 24 * (2 + 3 * n_motors as u64);
    rows.saturating_mul(per_row).saturating_add(64 << 10)
}

/// Where the data of a move go when its output folder cannot take them:
/// `<temp dir>/qmarc-rescue-<pid of the run>` (the run: the starter, the controller's parent).
pub fn rescue_dir(run_pid: u32) -> PathBuf {
    std::env::temp_dir().join(format!("qmarc-rescue-{run_pid}"))
}

/// One data file: its name and what writes it.
pub type FileWriter<'a> = (&'a str, &'a dyn Fn(&mut dyn Write) -> std::io::Result<()>);

/// Writing the data files failed (the rescue folder included).
#[derive(Debug, thiserror::Error)]
#[error("cannot write {file}: {reason}")]
pub struct WriteError {
    /// The file.
    pub file: PathBuf,
    /// Why.
    pub reason: std::io::Error,
}

/// Why [`StopAware`] stopped writing. Deliberately not `ErrorKind::Interrupted`: `write_all`
/// and `BufWriter` retry that kind, so the writing would spin until the process is killed.
#[derive(Debug, thiserror::Error)]
#[error("a stop signal arrived while the data were written")]
struct StoppedWriting;

/// A writer that fails ([`StoppedWriting`]) once a stop signal arrives after it was made:
/// the stop that ended a move does not cut its data short, a later one (Ctrl-C during the
/// writing) ends the writing at once.
struct StopAware<W> {
    inner: W,
    signals: u32,
}

impl<W: Write> Write for StopAware<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if qmarc_timer::stop::count() > self.signals {
            return Err(std::io::Error::other(StoppedWriting));
        }
        self.inner.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// True when `e` is a stop signal's end of the writing (the writer `write_set` uses watches
/// for one).
pub fn interrupted(e: &WriteError) -> bool {
    e.reason.get_ref().is_some_and(|r| r.is::<StoppedWriting>())
}

/// Writes `files` into `dir` as one set: each into `dir/.incoming-<pid>/`, then, when all are
/// written and flushed, renamed into `dir` in order (put `summary.json` last). Returns the
/// final paths. On failure the folder keeps what it had, and the incoming folder is removed.
/// A stop signal that arrives while it writes ends it (an `Interrupted` error).
pub fn write_set(dir: &Path, files: &[FileWriter<'_>]) -> Result<Vec<PathBuf>, WriteError> {
    let signals = qmarc_timer::stop::count();
    let incoming = dir.join(format!(".incoming-{}", std::process::id()));
    let fail = |file: PathBuf, reason| {
        let _ = std::fs::remove_dir_all(&incoming);
        WriteError { file, reason }
    };
    std::fs::create_dir_all(&incoming).map_err(|e| fail(incoming.clone(), e))?;
    for (name, write) in files {
        let path = incoming.join(name);
        let result = std::fs::File::create(&path).and_then(|f| {
            let mut w = std::io::BufWriter::new(StopAware { inner: f, signals });
            write(&mut w)?;
            w.flush()?;
            w.get_ref().inner.sync_data()
        });
        result.map_err(|e| fail(dir.join(name), e))?;
    }
    retire_current_set(dir).map_err(|e| fail(dir.join(PREVIOUS_DIR), e))?;
    let mut done = Vec::with_capacity(files.len());
    for (name, _) in files {
        let to = dir.join(name);
        std::fs::rename(incoming.join(name), &to).map_err(|e| fail(to.clone(), e))?;
        done.push(to);
    }
    let _ = std::fs::remove_dir(&incoming);
    Ok(done)
}

/// Files of a move's data, in the output directory, in the order they are put in place
/// (`summary.json` last: once it is there, the set is complete).
pub const OUTPUT_FILES: [&str; 3] = ["gather.csv", "gather.m", "summary.json"];

/// The PNG plots `qmarc-starter --plots` draws from a set (crate `qmarc-plots`): they belong
/// to the set beside them, so a new set retires them with it.
pub const PLOT_FILES: [&str; 6] =
    ["arms.png", "error.png", "velocity.png", "period.png", "effector-3d.png", "effector-xz.png"];

/// Files a set may have beside gather.csv: a conveyor session's `parts.csv`, the rows as
/// MCAP (`gather.mcap`, [`write_results`]'s `also`). They belong to the set, so a new set
/// retires them with it.
pub const EXTRA_FILES: [&str; 2] = ["parts.csv", "gather.mcap"];

/// The folder inside an output folder that keeps the last complete set a newer one replaced.
pub const PREVIOUS_DIR: &str = "previous";

/// Makes room for a new set in `dir`: a complete set there (data and summary) is moved into
/// `dir/previous/`, replacing the set that was there; the files of an incomplete one (a
/// summary without its data) are removed, so `previous/` keeps the last complete results.
fn retire_current_set(dir: &Path) -> std::io::Result<()> {
    let present: Vec<&str> = OUTPUT_FILES
        .into_iter()
        .chain(PLOT_FILES)
        .chain(EXTRA_FILES)
        .filter(|f| dir.join(f).exists())
        .collect();
    let complete = present.contains(&"gather.csv") && present.contains(&"summary.json");
    if complete {
        let previous = dir.join(PREVIOUS_DIR);
        match std::fs::remove_dir_all(&previous) {
            Err(e) if e.kind() != std::io::ErrorKind::NotFound => return Err(e),
            _ => {}
        }
        std::fs::create_dir(&previous)?;
        for f in &present {
            std::fs::rename(dir.join(f), previous.join(f))?;
        }
    } else {
        for f in &present {
            std::fs::remove_file(dir.join(f))?;
        }
    }
    Ok(())
}

/// Writes `summary` alone into `dir` as a set ([`write_set`]): the summary of a run that has
/// no data to write (its controller died), which must neither sit beside an earlier run's
/// data nor destroy them.
pub fn write_summary_set(dir: &Path, summary: &Summary) -> Result<PathBuf, WriteError> {
    let json = |w: &mut dyn Write| write_json(summary, w);
    let mut done = write_set(dir, &[("summary.json", &json)])?;
    Ok(done.remove(0))
}

/// Replaces `dir/summary.json` by `summary` in one step (written beside it, then renamed over
/// it), leaving the data files it describes in place: what the starter learnt after the
/// controller wrote it (a process that stopped responding).
pub fn amend_summary(dir: &Path, summary: &Summary) -> Result<PathBuf, WriteError> {
    let to = dir.join("summary.json");
    let tmp = dir.join(format!(".summary.json.{}", std::process::id()));
    let result = std::fs::File::create(&tmp).and_then(|f| {
        let mut w = std::io::BufWriter::new(f);
        write_json(summary, &mut w)?;
        w.into_inner().map_err(|e| e.into_error())?.sync_data()?;
        std::fs::rename(&tmp, &to)
    });
    result.map(|()| to.clone()).map_err(|reason| {
        let _ = std::fs::remove_file(&tmp);
        WriteError { file: to, reason }
    })
}

/// `summary` as `summary.json` holds it.
fn write_json(summary: &Summary, w: &mut dyn Write) -> std::io::Result<()> {
    serde_json::to_writer_pretty(&mut *w, summary).map_err(std::io::Error::other)?;
    writeln!(w)
}

/// Writes the move's data files and `summary.json` into `dir` as one set
/// ([`write_set`]): the previous results stay until all of them are written.
/// The stop that ended the move does not cut the writing short; a further stop signal while
/// the rows are written abandons the data files at once (the summary is still written, with a
/// warning, and the folder keeps the previous data files, if any: never a half-written set);
/// a failure writes everything to the rescue folder of the run whose starter is `run_pid`
/// instead ([`rescue_dir`]), with a warning, and says so on standard error.
///
/// `also`: more data files of the same rows (`gather.mcap`), written after gather.m and
/// abandoned with them.
pub fn write_results(
    dir: &Path,
    gather: &Gather,
    summary: &mut Summary,
    run_pid: u32,
    also: &[FileWriter<'_>],
) -> Result<(), WriteError> {
    write_results_with(dir, gather, summary, run_pid, &[], also)
}

/// [`write_results`] with `extra` files of the set ([`EXTRA_FILES`]: a name and its text),
/// written with the summary whether or not the data files are.
pub fn write_results_with(
    dir: &Path,
    gather: &Gather,
    summary: &mut Summary,
    run_pid: u32,
    extra: &[(&str, String)],
    also: &[FileWriter<'_>],
) -> Result<(), WriteError> {
    let csv = |w: &mut dyn Write| crate::files::write_csv(gather, w);
    let octave = |w: &mut dyn Write| crate::files::write_octave(gather, w);
    let texts: Vec<_> = extra
        .iter()
        .map(|(name, text)| (*name, move |w: &mut dyn Write| w.write_all(text.as_bytes())))
        .collect();
    let attempt = |dir: &Path, summary: &mut Summary, data: bool| {
        let names: &[&str] = if data { &OUTPUT_FILES } else { &OUTPUT_FILES[2..] };
        let also_names = also.iter().filter(|_| data).map(|(name, _)| dir.join(name));
        let extras = extra.iter().map(|(name, _)| dir.join(name));
        summary.files = names.iter().map(|f| dir.join(f)).chain(also_names).chain(extras).collect();
        let frozen = summary.clone();
        let json = move |w: &mut dyn Write| write_json(&frozen, w);
        let mut all: Vec<FileWriter<'_>> = Vec::new();
        if data {
            all.push(("gather.csv", &csv));
            all.push(("gather.m", &octave));
            all.extend(also.iter().copied());
        }
        all.extend(
            texts.iter().map(|(name, write)| {
                (*name, write as &dyn Fn(&mut dyn Write) -> std::io::Result<()>)
            }),
        );
        // The summary last: once it is there, the set is complete.
        all.push(("summary.json", &json));
        write_set(dir, &all)
    };
    let Err(e) = attempt(dir, summary, true) else { return Ok(()) };
    if interrupted(&e) {
        let mut files: Vec<&str> = vec!["gather.csv", "gather.m"];
        files.extend(also.iter().map(|(name, _)| *name));
        let last = files.pop().unwrap_or_default();
        summary.warnings.push(Warning::new(
            WarningKind::DataNotWritten,
            format!(
                "a stop signal arrived while the data were written: this move's {} and {last} \
                 were not written (the set they would have replaced, if any, is in {})",
                files.join(", "),
                dir.join(PREVIOUS_DIR).display()
            ),
        ));
        attempt(dir, summary, false)?;
        return Ok(());
    }
    let rescue = rescue_dir(run_pid);
    let warning = format!("{e}; the data of this move are in {} instead", rescue.display());
    let program = std::env::current_exe()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()));
    let _ = writeln!(std::io::stderr(), "{}: {warning}", program.as_deref().unwrap_or("qmarc"));
    summary.warnings.push(Warning::new(WarningKind::Rescued, warning));
    attempt(&rescue, summary, true)?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("qmarc-out-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    #[test]
    fn a_set_replaces_the_old_files_only_when_all_are_written() {
        let dir = scratch("set");
        let ok = |text: &'static str| move |w: &mut dyn Write| w.write_all(text.as_bytes());
        let (a, b) = (ok("a1"), ok("b1"));
        write_set(&dir, &[("a.txt", &a), ("b.txt", &b)]).unwrap();
        let failing =
            |_: &mut dyn Write| -> std::io::Result<()> { Err(std::io::Error::other("disk full")) };
        let a2 = ok("a2");
        let e = write_set(&dir, &[("a.txt", &a2), ("b.txt", &failing)]).unwrap_err();
        assert_eq!(
            e.to_string(),
            format!("cannot write {}: disk full", dir.join("b.txt").display())
        );
        assert_eq!(std::fs::read_to_string(dir.join("a.txt")).unwrap(), "a1", "kept as it was");
        let left: Vec<_> =
            std::fs::read_dir(&dir).unwrap().flatten().map(|e| e.file_name()).collect();
        assert_eq!(left.len(), 2, "no incoming folder left: {left:?}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// Issue 10, item 6: a run that has only a summary (its controller died) neither sits
    /// beside the previous run's data nor destroys them; the last complete set is kept in
    /// `previous/`, and a second incomplete run does not push it out.
    #[test]
    fn a_new_set_retires_the_old_one_whole() {
        let dir = scratch("retire");
        let text = |t: &'static str| move |w: &mut dyn Write| w.write_all(t.as_bytes());
        let (csv, m, json) = (text("data 1"), text("octave 1"), text("summary 1"));
        write_set(&dir, &[("gather.csv", &csv), ("gather.m", &m), ("summary.json", &json)])
            .unwrap();
        let lost = text("summary 2 (controller lost)");
        write_set(&dir, &[("summary.json", &lost)]).unwrap();
        let read = |p: &str| std::fs::read_to_string(dir.join(p)).ok();
        assert_eq!(read("summary.json").as_deref(), Some("summary 2 (controller lost)"));
        assert_eq!(read("gather.csv"), None, "no data of another run beside the summary");
        assert_eq!(read("previous/gather.csv").as_deref(), Some("data 1"));
        assert_eq!(read("previous/summary.json").as_deref(), Some("summary 1"));
        let lost_again = text("summary 3 (controller lost)");
        write_set(&dir, &[("summary.json", &lost_again)]).unwrap();
        assert_eq!(read("summary.json").as_deref(), Some("summary 3 (controller lost)"));
        assert_eq!(read("previous/summary.json").as_deref(), Some("summary 1"), "kept");
        let (csv4, m4, json4) = (text("data 4"), text("octave 4"), text("summary 4"));
        write_set(&dir, &[("gather.csv", &csv4), ("gather.m", &m4), ("summary.json", &json4)])
            .unwrap();
        assert_eq!(read("gather.csv").as_deref(), Some("data 4"));
        assert_eq!(
            read("previous/summary.json").as_deref(),
            Some("summary 1"),
            "an incomplete set never replaces the last complete one"
        );
        // Set 4's plots go with it: none is left beside set 5, whose plots they are not.
        std::fs::write(dir.join("error.png"), "plot 4").unwrap();
        let (csv5, m5, json5) = (text("data 5"), text("octave 5"), text("summary 5"));
        write_set(&dir, &[("gather.csv", &csv5), ("gather.m", &m5), ("summary.json", &json5)])
            .unwrap();
        assert_eq!(read("previous/gather.csv").as_deref(), Some("data 4"));
        assert_eq!(read("previous/error.png").as_deref(), Some("plot 4"));
        assert_eq!(read("error.png"), None);
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_dead_runs_incoming_folder_is_removed_a_live_ones_kept() {
        let dir = scratch("incoming");
        let dead = dir.join(".incoming-2147483646"); // above pid_max: never a live process
        let live = dir.join(format!(".incoming-{}", std::process::id()));
        for d in [&dead, &live] {
            std::fs::create_dir_all(d).unwrap();
        }
        check(&dir, 0).unwrap();
        assert!(!dead.exists() && live.exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_second_lock_is_refused_naming_the_first() {
        let dir = scratch("lock");
        std::fs::create_dir_all(&dir).unwrap();
        let held = lock(&dir).unwrap();
        // Another open file description of the same file: another run.
        let e = lock(&dir).unwrap_err();
        assert!(
            e.to_string().ends_with(&format!(
                "is in use by another run (qmarc-starter pid {}): wait for it or give another --out",
                std::process::id()
            )),
            "{e}"
        );
        drop(held);
        assert!(lock(&dir).is_ok(), "released");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn a_folder_that_cannot_be_made_or_filled_is_refused() {
        let e = check(Path::new("/proc/qmarc-out"), 0).unwrap_err();
        assert!(
            e.to_string().starts_with("output folder /proc/qmarc-out: cannot create it: "),
            "{e}"
        );
        // Issue 28, item 8: a file is called a file (before: "cannot create it: File exists").
        let e = check(Path::new("/etc/hostname"), 0).unwrap_err();
        assert_eq!(
            e.to_string(),
            "output folder /etc/hostname: it is a file, not a folder: give a folder for --out"
        );
        let dir = scratch("room");
        let e = check(&dir, u64::MAX / 2).unwrap_err();
        assert!(matches!(e, OutDirError::NoRoom { .. }), "{e}");
        check(&dir, 1000).unwrap();
        let _ = std::fs::remove_dir_all(&dir);
    }
}
