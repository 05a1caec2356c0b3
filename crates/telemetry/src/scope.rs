//! `qmarc scope [--every N] [--csv FILE] [--duration S] [--iox-prefix P] [--iox-root R]`:
//! attaches to a running move's telemetry (the run of `--iox-prefix`, or the newest run
//! found), prints a compact live line per motor or records every sample into a CSV file, and
//! detaches when the move ends, after `--duration` seconds or on Ctrl-C. Started before a
//! move, it says that none runs and waits for one.
//!
//! Exit codes: 0 it recorded a move, 1 no move ran within `--duration` (nothing recorded) or
//! the telemetry failed, 130 Ctrl-C before a move, 64 bad options.

use crate::reader::{End, FoundRun, TelemetryReader, is_last, location_of, runs};
use anyhow::Context;
use clap::Parser;
use qmarc_proto::exit;
use qmarc_proto::service::IpcLocation;
use qmarc_proto::state::FaultKind;
use qmarc_proto::state::Phase;
use qmarc_proto::telemetry::{TelemetryOpenError, TelemetrySample};
use std::ffi::OsString;
use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::{Duration, Instant};

/// Options of `qmarc scope`.
#[derive(Debug, Clone, PartialEq, Parser)]
#[command(
    name = "qmarc scope",
    about = "Live telemetry of a running move: a line per motor, or every sample into a CSV file"
)]
pub struct ScopeArgs {
    /// Keep every N-th sample received (the move publishes every `telemetry.every`-th cycle).
    #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..))]
    pub every: u32,
    /// Record the samples into FILE (CSV: the columns of gather.csv and the timing) instead
    /// of printing them.
    #[arg(long)]
    pub csv: Option<PathBuf>,
    /// Detach after S seconds (waiting for a move included); default: when the move ends.
    #[arg(long)]
    pub duration: Option<f64>,
    /// The run's iceoryx2 prefix (default: your newest run found in /dev/shm, else the
    /// newest of another user's).
    #[arg(long)]
    pub iox_prefix: Option<String>,
    /// The run's iceoryx2 root (default: the one its run file names).
    #[arg(long)]
    pub iox_root: Option<String>,
}

/// How long the scope sleeps between looks.
const POLL: Duration = Duration::from_millis(10);

/// `qmarc scope ARGS…`; the exit code: 0 when it detached (the move ended, or the duration
/// passed), 1 on an error, 130 on Ctrl-C, 64 on bad options.
pub fn main(args: &[OsString]) -> ExitCode {
    let all = std::iter::once(OsString::from("qmarc scope")).chain(args.iter().cloned());
    let args = match ScopeArgs::try_parse_from(all) {
        Ok(a) => a,
        Err(e) => {
            let _ = e.print();
            return ExitCode::from(if e.use_stderr() { exit::USAGE } else { exit::OK });
        }
    };
    match run(&args) {
        Ok(code) => ExitCode::from(code),
        Err(e) => {
            eprintln!("qmarc scope: error: {e:#}");
            ExitCode::from(exit::INTERNAL)
        }
    }
}

/// Where the samples go.
enum Sink {
    /// A live block of lines on standard output, redrawn in place on a terminal.
    Live { terminal: bool, shown: usize, last: Option<Instant>, every: Duration },
    /// Every sample into a CSV file.
    Csv { file: std::io::BufWriter<std::fs::File>, path: PathBuf, header: bool },
}

/// Runs the scope; the exit code.
pub fn run(args: &ScopeArgs) -> anyhow::Result<u8> {
    if args.duration.is_some_and(|d| !(d.is_finite() && d > 0.0)) {
        anyhow::bail!("--duration must be a number of seconds > 0");
    }
    if let Some(root) = &args.iox_root
        && !std::path::Path::new(root).is_dir()
    {
        anyhow::bail!(
            "--iox-root {root}: no such folder (a run's iceoryx2 root exists while it runs: \
             `qmarc-starter --iox-root` names it)"
        );
    }
    let stop = qmarc_timer::stop::install().context("signal handlers")?;
    let start = Instant::now();
    let deadline = args.duration.map(|d| start + Duration::from_secs_f64(d));
    let over = || deadline.is_some_and(|d| Instant::now() >= d);
    let stopped = || stop.load(std::sync::atomic::Ordering::Relaxed);
    let mut said = false;
    let (mut reader, location, whose) = loop {
        if stopped() {
            return Ok(exit::INTERRUPTED);
        }
        if let Some(found) = attach(args)? {
            break found;
        }
        if over() {
            // Nothing recorded: not a success (a script waiting for a move learns it did not
            // come).
            println!("qmarc scope: no move ran within {} s", args.duration.unwrap_or(0.0));
            return Ok(exit::INTERNAL);
        }
        if !said {
            let which = args.iox_prefix.as_ref().map_or(String::new(), |p| format!(" under {p}"));
            println!("qmarc scope: no move is running{which}; waiting for one (Ctrl-C leaves)");
            said = true;
        }
        // Soon after the move's telemetry appears: before its first sample, mostly.
        std::thread::sleep(POLL / 2);
    };
    if said {
        // It waited for this move: what went by before it attached is lost, and said so.
        reader.count_from_start();
    }
    println!("qmarc scope: attached to the move of {} ({}){whose}", location.prefix, location.root);
    let mut sink = match &args.csv {
        Some(path) => Sink::Csv {
            file: std::io::BufWriter::new(
                std::fs::File::create(path)
                    .with_context(|| format!("cannot create {}", path.display()))?,
            ),
            path: path.clone(),
            header: false,
        },
        None => {
            let terminal = std::io::IsTerminal::is_terminal(&std::io::stdout());
            let every = Duration::from_millis(if terminal { 100 } else { 1000 });
            Sink::Live { terminal, shown: 0, last: None, every }
        }
    };
    let mut kept = 0u64;
    let why = loop {
        while let Some(s) = reader.receive().map_err(anyhow::Error::msg)? {
            let last = is_last(&s);
            if (reader.received() - 1).is_multiple_of(u64::from(args.every)) || last {
                sink.take(&s, last)?;
                kept += 1;
            }
        }
        match reader.end() {
            Some(End::Last(s)) => break ended(&s),
            Some(End::Gone) => {
                break "the move's controller went away without saying how it ended".to_string();
            }
            None => {}
        }
        if stopped() {
            break "stopped (Ctrl-C)".to_string();
        }
        if over() {
            break format!("{} s passed", args.duration.unwrap_or(0.0));
        }
        std::thread::sleep(POLL);
    };
    let (received, lost) = (reader.received(), reader.lost());
    let lost = match reader.lost_before_first() {
        0 => format!("{lost}"),
        n => format!("{lost} ({n} before it attached)"),
    };
    drop(reader);
    let written = match sink {
        Sink::Csv { mut file, path, .. } => {
            file.flush().with_context(|| format!("cannot write {}", path.display()))?;
            format!(", {kept} written to {}", path.display())
        }
        Sink::Live { .. } => String::new(),
    };
    println!("qmarc scope: detached: {why}; {received} samples received, {lost} lost{written}");
    Ok(if stopped() { exit::INTERRUPTED } else { exit::OK })
}

/// The reader of the move `args` name (or of the caller's newest run found, else another
/// user's), if one runs now, and whose it is in words (empty when named by `--iox-prefix`).
fn attach(args: &ScopeArgs) -> anyhow::Result<Option<(TelemetryReader, IpcLocation, String)>> {
    let me = nix::unistd::geteuid().as_raw();
    let candidates = match &args.iox_prefix {
        Some(p) => vec![FoundRun { location: location_of(p, args.iox_root.as_deref()), uid: me }],
        None => runs(args.iox_root.as_deref()),
    };
    let found = candidates.len();
    for FoundRun { location, uid } in candidates {
        let whose = match (&args.iox_prefix, uid == me) {
            (Some(_), _) => String::new(),
            (None, true) => format!(": your newest running move of the {found} runs found"),
            (None, false) => {
                format!(": user {uid}'s — none of yours runs (--iox-prefix names a run)")
            }
        };
        match TelemetryReader::open_run(&location) {
            Ok(r) => return Ok(Some((r, location, whose))),
            Err(TelemetryOpenError::NoMove) => {}
            Err(TelemetryOpenError::Failed(e)) if args.iox_prefix.is_some() => {
                return Err(anyhow::Error::msg(e.to_string()));
            }
            // A run found by looking may be one that is ending: the next one, then.
            Err(TelemetryOpenError::Failed(_)) => {}
        }
    }
    Ok(None)
}

/// How the move of its last sample `s` ended.
fn ended(s: &TelemetrySample) -> String {
    match FaultKind::from_wire(s.fault) {
        Some(kind) => format!("the move ended with the fault {}", kind.name()),
        None => "the move is done".to_string(),
    }
}

/// The phase's name in a sample.
fn phase_name(code: u32) -> &'static str {
    Phase::from_wire(code).map_or("?", Phase::name)
}

impl Sink {
    /// Takes a sample: a CSV row, or (at most every `every`, and always the last) the live
    /// lines.
    fn take(&mut self, s: &TelemetrySample, last: bool) -> anyhow::Result<()> {
        match self {
            Sink::Csv { file, path, header } => {
                let n = s.n_motors as usize;
                if !*header {
                    writeln!(file, "{}", csv_header(n))?;
                    *header = true;
                }
                writeln!(file, "{}", csv_row(s, n))
                    .with_context(|| format!("cannot write {}", path.display()))
            }
            Sink::Live { terminal, shown, last: at, every } => {
                if !last && at.is_some_and(|t| t.elapsed() < *every) {
                    return Ok(());
                }
                *at = Some(Instant::now());
                let lines = live_lines(s);
                std::io::stdout().lock().write_all(block(&lines, *terminal, *shown).as_bytes())?;
                *shown = lines.len();
                Ok(())
            }
        }
    }
}

/// The text that shows `lines`: on a terminal, back over the `shown` lines of the block before
/// and each line cleared to its end (redrawn in place); elsewhere (a pipe, a file) the lines
/// alone, no escape codes.
pub fn block(lines: &[String], terminal: bool, shown: usize) -> String {
    let mut text = String::new();
    if terminal && shown > 0 {
        text.push_str(&format!("\x1b[{shown}A"));
    }
    for l in lines {
        text.push_str(l);
        if terminal {
            text.push_str("\x1b[K");
        }
        text.push('\n');
    }
    text
}

/// The live block of `s`: the cycle's line, then a line per motor.
pub fn live_lines(s: &TelemetrySample) -> Vec<String> {
    let us = |ns: u32| f64::from(ns) / 1e3;
    let mut lines = vec![format!(
        "t {:9.4} s  cycle {:>8}  {:<12} period {:7.1} µs  wake {:6.1} µs  tick→DAC {:6.1} µs",
        s.time_ns as f64 / 1e9,
        s.cycle,
        phase_name(s.phase),
        us(s.period_ns),
        us(s.wake_latency_ns),
        us(s.output_latency_ns),
    )];
    for m in 0..(s.n_motors as usize).min(s.cmd.len()) {
        lines.push(format!(
            "  M{}  cmd {:11.1}  act {:11.1}  error {:8.1}  dac {:6}",
            m + 1,
            s.cmd[m],
            s.act[m],
            s.following_error[m],
            s.dac[m]
        ));
    }
    lines
}

/// The CSV header for `n` motors.
pub fn csv_header(n: usize) -> String {
    let mut h = String::from(
        "seq,cycle,time_s,phase,fault,status,wake_latency_us,output_latency_us,period_us",
    );
    for m in 1..=n {
        h.push_str(&format!(",cmd{m},act{m},dac{m},fe{m}"));
    }
    h
}

/// The CSV row of `s` (cmd, act and dac written as gather.csv writes them).
pub fn csv_row(s: &TelemetrySample, n: usize) -> String {
    let fault = FaultKind::from_wire(s.fault).map_or("", FaultKind::name);
    let mut r = format!(
        "{},{},{},{},{fault},{},{},{},{}",
        s.seq,
        s.cycle,
        s.time_ns as f64 / 1e9,
        phase_name(s.phase),
        s.status,
        f64::from(s.wake_latency_ns) / 1e3,
        f64::from(s.output_latency_ns) / 1e3,
        f64::from(s.period_ns) / 1e3
    );
    for m in 0..n.min(s.cmd.len()) {
        r.push_str(&format!(",{},{},{},{}", s.cmd[m], s.act[m], s.dac[m], s.following_error[m]));
    }
    r
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reader::{SeqCount, own_first};

    /// Issue 28, item 10: a scope that waited for the move counts the samples before its
    /// first as lost (before: "0 lost" after missing the whole step transient); one that
    /// attached to a move under way counts only gaps.
    #[test]
    fn samples_before_the_first_are_lost_when_counting_from_the_start() {
        let mut waited = SeqCount { from_start: true, ..SeqCount::default() };
        let mut late = SeqCount::default();
        for seq in [21, 22, 25] {
            waited.see(seq);
            late.see(seq);
        }
        assert_eq!((waited.received, waited.lost, waited.before_first), (3, 2, 21));
        assert_eq!((late.received, late.lost, late.before_first), (3, 2, 0));
        let mut from_zero = SeqCount { from_start: true, ..SeqCount::default() };
        from_zero.see(0);
        assert_eq!(from_zero.before_first, 0);
    }

    /// Issue 28, item 10: the caller's own runs first (newest first), then others'.
    #[test]
    fn the_callers_own_runs_come_first() {
        let t = |s| std::time::UNIX_EPOCH + Duration::from_secs(s);
        let run = |p: &str, uid| FoundRun { location: IpcLocation::new(p, "/tmp/iceoryx2"), uid };
        let found = vec![
            (t(30), run("theirs_new_", 1000)),
            (t(10), run("mine_old_", 0)),
            (t(20), run("mine_new_", 0)),
        ];
        let order: Vec<String> =
            own_first(found, 0).into_iter().map(|r| r.location.prefix).collect();
        assert_eq!(order, ["mine_new_", "mine_old_", "theirs_new_"]);
    }

    /// Issue 28, item 10: piped or redirected, the live lines hold no escape codes; on a
    /// terminal they are redrawn in place.
    #[test]
    fn no_escape_codes_unless_on_a_terminal() {
        let lines = vec!["a".to_string(), "b".to_string()];
        assert_eq!(block(&lines, false, 2), "a\nb\n");
        assert_eq!(block(&lines, true, 2), "\x1b[2Aa\x1b[K\nb\x1b[K\n");
        assert_eq!(block(&lines, true, 0), "a\x1b[K\nb\x1b[K\n");
    }

    /// Issue 28, item 10: an `--iox-root` that does not exist is refused, naming it (before:
    /// ignored, the scope waiting for a move that could never come).
    #[test]
    fn a_root_that_does_not_exist_is_refused() {
        let args =
            ScopeArgs::try_parse_from(["qmarc scope", "--iox-root", "/nonexistent/iox"]).unwrap();
        let e = run(&args).unwrap_err().to_string();
        assert!(e.starts_with("--iox-root /nonexistent/iox: no such folder"), "{e}");
    }
}
