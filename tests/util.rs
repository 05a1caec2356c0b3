//! Helpers for the end-to-end tests: a [`TestRun`] gives each test its own iceoryx2 prefix,
//! root and output directory, runs the real binaries with a timeout, and checks on drop that
//! no process and no shared-memory file of the test is left.
//!
//! The binaries come from the same target directory as the test executable; `cargo test
//! --workspace` builds them (every binary crate has an integration test target).
#![deny(missing_docs)]

use qmarc_proto::service::IpcLocation;
use qmarc_report::Summary;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// The directory holding the workspace's binaries (`target/<profile>`).
pub fn bin_dir() -> PathBuf {
    let exe = std::env::current_exe().expect("test executable path");
    let dir = exe.parent().and_then(Path::parent).expect("target/<profile>/deps/..").to_path_buf();
    for b in ["qmarc-starter", "qmarc-controller", "qmarc-hwserver", "qmarc", "qmarc-camera"] {
        assert!(
            dir.join(b).is_file(),
            "{} is missing: run the tests with `scripts/test` (cargo test --workspace), which builds it",
            dir.join(b).display()
        );
    }
    dir
}

/// The workspace root.
pub fn workspace() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).parent().expect("workspace root").to_path_buf()
}

/// A file of the repository's `knots/`.
pub fn knots(name: &str) -> PathBuf {
    workspace().join("knots").join(name)
}

/// The Python with the tests' packages (tests/requirements.txt): `$QMARC_PYTHON`, else the
/// one `scripts/test` makes in `target/pyenv`.
pub fn python() -> PathBuf {
    let python = std::env::var_os("QMARC_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| workspace().join("target/pyenv/bin/python3"));
    assert!(
        python.exists(),
        "no Python with the tests' packages at {}: run scripts/test (it installs \
         tests/requirements.txt into target/pyenv) or set QMARC_PYTHON",
        python.display()
    );
    python
}

/// The shipped settings file.
pub fn shipped_config() -> PathBuf {
    workspace().join("config/qmarc.toml")
}

/// The shipped settings tuned for online moves (`config/tuned.toml`: the same robot, the
/// feed-forward tuned on the pick cycle).
pub fn tuned_config() -> PathBuf {
    workspace().join("config/tuned.toml")
}

/// The shipped settings for the Sensoray 626 (its counts, 1×).
pub fn s626_config() -> PathBuf {
    workspace().join("config/s626.toml")
}

/// The option that gives a run on the 626's path (the fake card) in real time the timing
/// bounds of `config/rehearse-without-rt.toml`: the card's shipped bounds (10 and 25
/// periods) are a PREEMPT_RT machine's, and this VM stalls for up to 100 ms under load —
/// not the backend's to survive; a rehearsal's explicit bounds, as docs/hardware.md says.
pub fn rehearsal_bounds() -> String {
    format!("--timing-overrides={}", workspace().join("config/rehearse-without-rt.toml").display())
}

/// The settings the end-to-end tests run with: the shipped file. Its simulated robot rides
/// out the multi-millisecond host stalls of a loaded VM without PREEMPT_RT (the backend's
/// timing defaults, `config::TimingDefaults`), which the tests meet running in parallel; the
/// watchdog and the overrun check are tested with their own bounds.
pub fn default_config() -> PathBuf {
    shipped_config()
}

/// `--config=<the shipped settings>`: a process test's settings flag.
pub fn config_arg() -> String {
    format!("--config={}", default_config().display())
}

/// What a process printed and how it ended.
#[derive(Debug)]
pub struct Finished {
    /// Exit code, `None` if a signal killed it.
    pub code: Option<i32>,
    /// Standard output.
    pub stdout: String,
    /// Standard error.
    pub stderr: String,
}

/// One test's isolated run: prefix, root and output directory of its own.
#[derive(Debug)]
pub struct TestRun {
    /// Unique iceoryx2 prefix.
    pub prefix: String,
    /// Private scratch directory (iceoryx2 root and outputs live under it).
    pub dir: PathBuf,
}

impl TestRun {
    /// A fresh run named after the test.
    pub fn new(test: &str) -> TestRun {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let nanos = std::time::SystemTime::now()
            .duration_since(std::time::UNIX_EPOCH)
            .map_or(0, |d| d.subsec_nanos());
        // Short enough that root + prefix fit iceoryx2's socket names (IpcLocation::checked).
        let short: String = test.chars().filter(char::is_ascii_alphanumeric).take(8).collect();
        let prefix = format!("qt{pid}_{n}_{nanos:x}_");
        let dir = std::env::temp_dir().join(format!("qmt-{pid}-{n}-{short}"));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(dir.join("iox")).expect("scratch dir");
        TestRun { prefix, dir }
    }

    /// The iceoryx2 root of this run.
    pub fn root(&self) -> String {
        format!("{}/iox/", self.dir.display())
    }

    /// Where this run's iceoryx2 files are.
    pub fn location(&self) -> IpcLocation {
        IpcLocation::new(&self.prefix, &self.root())
    }

    /// The output directory `name` inside the scratch directory.
    pub fn out(&self, name: &str) -> PathBuf {
        self.dir.join(name)
    }

    /// Arguments that isolate a starter run: prefix, root.
    pub fn isolation_args(&self) -> Vec<String> {
        vec![format!("--iox-prefix={}", self.prefix), format!("--iox-root={}", self.root())]
    }

    /// Runs `qmarc-starter` with the isolation arguments and `args`, from the workspace
    /// root, killing it after `timeout`.
    pub fn starter(&self, args: &[&str], timeout: Duration) -> Finished {
        let mut all = self.isolation_args();
        all.extend(args.iter().map(|s| s.to_string()));
        run_with_timeout(
            Command::new(bin_dir().join("qmarc-starter")).args(&all).current_dir(workspace()),
            timeout,
        )
    }

    /// `qmarc cmd` with the isolation arguments and `args` (a minute at most).
    pub fn cmd(&self, args: &[&str]) -> Finished {
        let mut c = Command::new(bin_dir().join("qmarc"));
        c.arg("cmd").args(self.isolation_args()).args(args);
        run_with_timeout(&mut c, Duration::from_secs(60))
    }

    /// A copy of the test settings in this run's directory with `edits` applied: each
    /// `(key, value)` replaces the value of every line `key = …` (every `[[motor]]` table's,
    /// for per-motor keys). A `section.key` that is not in the file is added to its
    /// `[section]`. Panics if a plain key is not in the file. The simulated robot keeps its
    /// homed frame in the run's own folder (`sim.state_file`), so runs never share it.
    pub fn config_with(&self, edits: &[(&str, &str)]) -> PathBuf {
        self.config_from(&default_config(), edits)
    }

    /// [`TestRun::config_with`] on the settings file `base` (`config/s626.toml`, say).
    pub fn config_from(&self, base: &Path, edits: &[(&str, &str)]) -> PathBuf {
        self.config_as("qmarc.toml", base, edits)
    }

    /// [`TestRun::config_from`] into the file `name` of this run's directory, for a test that
    /// keeps several settings files.
    pub fn config_as(&self, name: &str, base: &Path, edits: &[(&str, &str)]) -> PathBuf {
        let text = std::fs::read_to_string(base).expect("test settings");
        let mut doc: toml_edit::DocumentMut = text.parse().expect("the test settings parse");
        let state = format!("{:?}", self.dir.join("sim.state").display().to_string());
        let own_state = [("sim.state_file", state.as_str())];
        for (key, value) in own_state.iter().chain(edits) {
            let value: toml_edit::Value =
                value.parse().unwrap_or_else(|e| panic!("`{key} = {value}`: {e}"));
            let edited = match key.split_once('.') {
                Some((section, key)) => set_in(&mut doc[section], key, &value, true),
                None => doc.iter_mut().map(|(_, item)| set_in(item, key, &value, false)).sum(),
            };
            assert!(edited > 0, "no `{key}` in the settings");
        }
        let path = self.dir.join(name);
        std::fs::write(&path, doc.to_string()).expect("write settings");
        path
    }

    /// Runs `qmarc-starter` with the isolation arguments and `args` and asserts that it
    /// succeeded.
    pub fn starter_ok(&self, args: &[&str]) -> Finished {
        let r = self.starter(args, Duration::from_secs(120));
        assert_eq!(
            r.code,
            Some(0),
            "qmarc-starter {args:?}\nstdout:\n{}\nstderr:\n{}",
            r.stdout,
            r.stderr
        );
        r
    }

    /// Runs `qmarc-starter` with the shipped settings, output to `out` and `args` (global
    /// flags, then the mode and its flags), and asserts that it succeeded.
    pub fn step_ok(&self, out: &Path, args: &[&str]) -> Finished {
        let config = format!("--config={}", default_config().display());
        let out_arg = format!("--out={}", out.display());
        let mut all = vec![config.as_str(), out_arg.as_str()];
        all.extend_from_slice(args);
        let r = self.starter(&all, Duration::from_secs(60));
        assert_eq!(
            r.code,
            Some(0),
            "qmarc-starter {all:?}\nstdout:\n{}\nstderr:\n{}",
            r.stdout,
            r.stderr
        );
        r
    }

    /// Starts `qmarc-starter` with the isolation arguments and `args`, standard input piped (to
    /// feed a knot stream) and the output captured; finish it with [`wait_with_timeout`].
    pub fn spawn_starter(&self, args: &[&str]) -> std::process::Child {
        self.spawn_starter_on(None, args)
    }

    /// [`TestRun::spawn_starter`] on the second host `host` (a network namespace), or here.
    pub fn spawn_starter_on(
        &self,
        host: Option<&qmarc_program::net::Netns>,
        args: &[&str],
    ) -> std::process::Child {
        let starter = bin_dir().join("qmarc-starter");
        host.map_or_else(|| Command::new(&starter), |h| h.command(&starter))
            .args(self.isolation_args())
            .args(args)
            .current_dir(workspace())
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn qmarc-starter")
    }

    /// Processes whose command line mentions this run's prefix.
    pub fn processes(&self) -> Vec<(u32, String)> {
        processes_matching(&self.prefix)
    }

    /// Asserts nothing of this run is left: no process, no iceoryx2 file.
    pub fn assert_clean(&self) {
        let procs = self.processes();
        assert!(procs.is_empty(), "processes left behind: {procs:?}");
        let files = self.location().files();
        assert!(files.is_empty(), "iceoryx2 files left behind: {files:?}");
    }
}

impl Drop for TestRun {
    fn drop(&mut self) {
        for (pid, _) in self.processes() {
            send_signal(pid, nix::sys::signal::Signal::SIGKILL); // at worst it is already gone
        }
        self.location().remove_files();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Sends `sig` to process `pid` (found a moment ago; at worst it is gone and nothing happens).
pub fn send_signal(pid: u32, sig: nix::sys::signal::Signal) {
    let _ = nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid as i32), sig);
}

/// Waits until a move of the run with iceoryx2 prefix `prefix` is under way: its progress
/// page says it is homing, moving, holding or settling (or already past them: the caller's
/// own check then says what it finds). An observable start, where a fixed delay would guess
/// wrong on a loaded machine. Panics after `timeout`.
pub fn wait_until_moving(prefix: &str, timeout: Duration) {
    use qmarc_proto::state::Phase;
    wait_for_progress(prefix, timeout, "a move under way", |s| s.phase >= Phase::Homing.wire());
}

/// Waits until the progress page of the run with iceoryx2 prefix `prefix` (the controller's
/// phase and cycle) satisfies `done`; panics after `timeout`, naming `what`.
pub fn wait_for_progress(
    prefix: &str,
    timeout: Duration,
    what: &str,
    done: impl Fn(&qmarc_proto::progress::Snapshot) -> bool,
) -> qmarc_proto::progress::Snapshot {
    let start = Instant::now();
    loop {
        if let Some(s) = qmarc_proto::progress::Progress::snapshot(prefix)
            && done(&s)
        {
            return s;
        }
        assert!(start.elapsed() < timeout, "no {what} within {timeout:?}");
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// `/proc/<pid>/task/*/status` of every thread of `pid` (none if it is gone).
pub fn thread_statuses(pid: u32) -> Vec<String> {
    let tasks = std::fs::read_dir(format!("/proc/{pid}/task")).into_iter().flatten().flatten();
    tasks.filter_map(|t| std::fs::read_to_string(t.path().join("status")).ok()).collect()
}

/// The value of `key` in a `/proc` status text, trimmed.
pub fn status_field<'a>(status: &'a str, key: &str) -> Option<&'a str> {
    status.lines().find_map(|l| l.strip_prefix(key)?.strip_prefix(':')).map(str::trim)
}

/// A PVT path as knot-file lines, a knot every 50 ms: motor 1 moves `distance` counts in
/// `segments` segments, at rest at both ends (p = d·(3s² − 2s³), s = t/T); motors 2 and 3 stay.
pub fn smooth_step_pvt(distance: f64, segments: u32) -> String {
    let duration_s = f64::from(segments) / 20.0;
    (0..=segments)
        .map(|i| {
            let s = f64::from(i) / f64::from(segments);
            let p = (distance * (3.0 * s * s - 2.0 * s * s * s)).round();
            let v = distance / duration_s * (6.0 * s - 6.0 * s * s);
            format!("X {p} {v:.3} 50 Y 0 0 50 Z 0 0 50\n")
        })
        .collect()
}

/// A PVT stream that never runs dry while a test looks at the run: [`HeldStream::feed`]
/// writes a path, then keeps adding knots at rest where it ended, a second or more ahead of
/// the loop (the run's progress page), until [`HeldStream::end`] closes the stream. However
/// late a loaded machine runs the test, the stream neither starves nor ends before it says.
pub struct HeldStream {
    stop: std::sync::Arc<std::sync::atomic::AtomicBool>,
    thread: std::thread::JoinHandle<()>,
}

impl HeldStream {
    /// Writes the PVT knot lines `path` into `sink`, the stream of the run with iceoryx2
    /// prefix `prefix` and servo period `period_s`, then holds its last position.
    pub fn feed(
        mut sink: impl std::io::Write + Send + 'static,
        prefix: &str,
        period_s: f64,
        path: &str,
    ) -> HeldStream {
        use std::sync::atomic::AtomicBool;
        let last = path.lines().last().expect("a path").split_whitespace().collect::<Vec<_>>();
        // Per motor: label, position, velocity, time to the next knot (ms).
        let hold: String = last
            .chunks(4)
            .map(|m| format!("{} {} 0 20 ", m[0], m[1]))
            .collect::<String>()
            .trim_end()
            .to_string();
        let ms = |line: &str| line.split_whitespace().nth(3).map_or(0.0, |t| t.parse().unwrap());
        let mut lines = path.lines();
        let first = lines.next().expect("a path");
        // The path's time up to its last knot written, s.
        let mut written_s = 0.0;
        let mut next_ms = ms(first);
        sink.write_all(format!("{first}\n").as_bytes()).expect("the stream");
        for line in lines {
            written_s += next_ms / 1e3;
            next_ms = ms(line);
            sink.write_all(format!("{line}\n").as_bytes()).expect("the stream");
        }
        let _ = sink.flush();
        let stop = std::sync::Arc::new(AtomicBool::new(false));
        let prefix = prefix.to_string();
        let thread = std::thread::spawn({
            let stop = stop.clone();
            move || {
                while !stop.load(Ordering::Acquire) {
                    let cycle =
                        qmarc_proto::progress::Progress::snapshot(&prefix).map_or(0, |s| s.cycle);
                    while written_s < cycle as f64 * period_s + 1.0 {
                        written_s += next_ms / 1e3;
                        next_ms = 20.0;
                        if sink.write_all(format!("{hold}\n").as_bytes()).is_err() {
                            return;
                        }
                    }
                    let _ = sink.flush();
                    std::thread::sleep(Duration::from_millis(20));
                }
            }
        });
        HeldStream { stop, thread }
    }

    /// Closes the stream: the path ends at the last knot written.
    pub fn end(self) {
        self.stop.store(true, Ordering::Release);
        self.thread.join().expect("the feeder");
    }
}

/// Processes (pid, command line) whose command line contains `needle`, except this one.
pub fn processes_matching(needle: &str) -> Vec<(u32, String)> {
    let me = std::process::id();
    let Ok(entries) = std::fs::read_dir("/proc") else {
        return vec![];
    };
    entries
        .flatten()
        .filter_map(|e| {
            let pid: u32 = e.file_name().to_str()?.parse().ok()?;
            let raw = std::fs::read(e.path().join("cmdline")).ok()?;
            let cmd = String::from_utf8_lossy(&raw).replace('\0', " ");
            (pid != me && cmd.contains(needle)).then_some((pid, cmd))
        })
        .collect()
}

/// What the processes whose command line contains `needle` are doing, for a failure message:
/// pid, state and where each thread waits in the kernel.
pub fn describe_processes(needle: &str) -> String {
    let read = |p: std::path::PathBuf| std::fs::read_to_string(p).unwrap_or_default();
    processes_matching(needle)
        .into_iter()
        .map(|(pid, cmd)| {
            let threads: Vec<String> = std::fs::read_dir(format!("/proc/{pid}/task"))
                .into_iter()
                .flatten()
                .flatten()
                .map(|t| {
                    let stat = read(t.path().join("stat"));
                    let state = stat.rsplit_once(')').map_or("?", |(_, r)| r.trim()).chars().next();
                    format!(
                        "{} {} in {}",
                        read(t.path().join("comm")).trim(),
                        state.unwrap_or('?'),
                        read(t.path().join("wchan")).trim()
                    )
                })
                .collect();
            format!("{pid} {cmd}\n    {}", threads.join("\n    "))
        })
        .collect::<Vec<_>>()
        .join("\n")
}

/// Runs `cmd` to completion, capturing its output; kills it and panics after `timeout`.
pub fn run_with_timeout(cmd: &mut Command, timeout: Duration) -> Finished {
    let child = cmd.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().expect("spawn");
    wait_with_timeout(child, timeout)
}

/// Waits for `child` (spawned with piped stdout and stderr), capturing its output; kills it
/// and panics after `timeout`.
pub fn wait_with_timeout(mut child: std::process::Child, timeout: Duration) -> Finished {
    // A pipe the caller took to read itself reads here as empty.
    let read = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut s = String::new();
            if let Some(mut pipe) = pipe {
                let _ = pipe.read_to_string(&mut s);
            }
            s
        })
    };
    let out_reader = read(child.stdout.take().map(|p| Box::new(p) as Box<dyn Read + Send>));
    let err_reader = read(child.stderr.take().map(|p| Box::new(p) as Box<dyn Read + Send>));
    let started = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if started.elapsed() > timeout {
            let _ = child.kill();
            let _ = child.wait();
            panic!("timed out after {timeout:?}");
        }
        std::thread::sleep(Duration::from_millis(10));
    };
    Finished {
        code: status.code(),
        stdout: out_reader.join().unwrap_or_default(),
        stderr: err_reader.join().unwrap_or_default(),
    }
}

/// `summary.json` of an output directory.
pub fn read_summary(out: &Path) -> Summary {
    let text = std::fs::read_to_string(out.join("summary.json")).expect("summary.json");
    serde_json::from_str(&text).expect("summary.json parses")
}

/// Asserts that the move whose outputs are in `out` was aborted and that the hwserver
/// acknowledged disabling the motors (the message says so only when it did). Returns its
/// summary.
pub fn assert_aborted_with_motors_disabled(out: &Path) -> Summary {
    let s = read_summary(out);
    let fault = s.fault.as_ref().expect("the move was aborted");
    assert_eq!(fault.kind.name(), "aborted", "{fault:?}");
    assert!(fault.message.ends_with("all motors disabled"), "{fault:?}");
    s
}

/// The simulator's event log: `(t_ns, event, motor)` rows.
pub fn read_sim_events(path: &Path) -> Vec<(u64, String, usize)> {
    let text = std::fs::read_to_string(path).expect("simulator event log");
    text.lines()
        .skip(1)
        .map(|l| {
            let f: Vec<&str> = l.split(',').collect();
            (f[0].parse().expect("t_ns"), f[1].to_string(), f[2].parse().expect("motor"))
        })
        .collect()
}

/// `gather.csv` of an output directory: the header and the rows as numbers.
pub fn read_gather(out: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    let text = std::fs::read_to_string(out.join("gather.csv")).expect("gather.csv");
    let mut lines = text.lines();
    let header: Vec<String> =
        lines.next().expect("header").split(',').map(str::to_string).collect();
    let rows = lines
        .map(|l| {
            l.split(',')
                .map(|v| v.parse::<f64>().unwrap_or_else(|_| panic!("number: {v}")))
                .collect()
        })
        .collect();
    (header, rows)
}

/// Sets `key = value` in the table `item`, or in each table of the array of tables `item`
/// (`[[motor]]`): where the key is already, or everywhere when `insert`. The number of tables
/// edited.
fn set_in(item: &mut toml_edit::Item, key: &str, value: &toml_edit::Value, insert: bool) -> usize {
    let set = |t: &mut toml_edit::Table| {
        let there = t.contains_key(key);
        if there || insert {
            t[key] = toml_edit::value(value.clone());
        }
        usize::from(there || insert)
    };
    match item {
        toml_edit::Item::Table(t) => set(t),
        toml_edit::Item::ArrayOfTables(a) => a.iter_mut().map(set).sum(),
        toml_edit::Item::None => panic!("no table for `{key}` in the settings"),
        _ => 0,
    }
}
