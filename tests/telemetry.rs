//! Issue 16, live telemetry: `qmarc scope` records a move's samples (they are gather.csv's
//! rows), started before or during the move; a reader that never reads changes nothing of
//! the move, and one killed with SIGKILL leaves nothing behind.

use qmarc_tests::{TestRun, bin_dir, read_gather, read_summary, send_signal, wait_with_timeout};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::Duration;

/// `qmarc scope --iox-prefix … --iox-root … ARGS…` of `run`, its output piped.
fn scope(run: &TestRun, args: &[&str]) -> Child {
    Command::new(bin_dir().join("qmarc"))
        .args([
            "scope",
            &format!("--iox-prefix={}", run.prefix),
            &format!("--iox-root={}", run.root()),
        ])
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn qmarc scope")
}

/// [`scope`], with its standard output's lines as they come (the receiver) and all of them
/// once it ends (the thread's result).
fn scope_lines(
    run: &TestRun,
    args: &[&str],
) -> (Child, std::sync::mpsc::Receiver<String>, std::thread::JoinHandle<String>) {
    let mut child = scope(run, args);
    let (said, lines) = std::sync::mpsc::channel();
    let stdout = child.stdout.take().expect("stdout");
    let printed = std::thread::spawn(move || {
        use std::io::BufRead;
        let mut all = String::new();
        for line in std::io::BufReader::new(stdout).lines().map_while(Result::ok) {
            all.push_str(&line);
            all.push('\n');
            let _ = said.send(line);
        }
        all
    });
    (child, lines, printed)
}

/// Waits (a minute at most) for a line containing `text` among `lines`.
fn wait_for_line(lines: &std::sync::mpsc::Receiver<String>, text: &str) {
    let deadline = std::time::Instant::now() + Duration::from_secs(60);
    while !lines
        .recv_timeout(deadline.saturating_duration_since(std::time::Instant::now()))
        .unwrap_or_else(|_| panic!("no line saying {text:?}"))
        .contains(text)
    {}
}

/// The rows of a scope's CSV file: header, rows.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).expect("scope CSV");
    let mut lines = text.lines();
    let header = lines.next().expect("a header").split(',').map(str::to_string).collect();
    (header, lines.map(|l| l.split(',').map(str::to_string).collect()).collect())
}

/// Every row of the scope's CSV at `csv` is the gather.csv row of its cycle (in `out`): the
/// same command, actual position and DAC value for every motor, and the same time.
fn assert_rows_are_gathered(csv: &Path, out: &Path) -> usize {
    let (header, rows) = read_csv(csv);
    let text = std::fs::read_to_string(out.join("gather.csv")).expect("gather.csv");
    let gathered: std::collections::HashMap<&str, Vec<&str>> = text
        .lines()
        .skip(1)
        .map(|l| {
            let cols: Vec<&str> = l.split(',').collect();
            (cols[0], cols)
        })
        .collect();
    let col = |name: &str| header.iter().position(|h| h == name).expect(name);
    let mut matched = 0;
    for r in &rows {
        if r[col("phase")] != "moving" && r[col("phase")] != "settling at the end of the path" {
            continue; // the end sample comes after the last cycle
        }
        let g = gathered.get(r[col("cycle")].as_str()).unwrap_or_else(|| {
            panic!("cycle {} of the scope is not in gather.csv", r[col("cycle")])
        });
        assert_eq!(g[1], r[col("time_s")], "time of cycle {}", g[0]);
        for m in 0..3 {
            for (k, name) in ["cmd", "act", "dac"].iter().enumerate() {
                let field = format!("{name}{}", m + 1);
                assert_eq!(g[1 + 3 * m + k + 1], r[col(&field)], "{field} of cycle {}", g[0]);
            }
        }
        matched += 1;
    }
    matched
}

#[test]
fn scope_records_a_move_started_before_or_during_it_and_its_samples_are_gathered_rows() {
    let run = TestRun::new("scope");
    let config = run.config_with(&[("duration_s", "6.0")]);
    let (before_csv, during_csv) = (run.out("before.csv"), run.out("during.csv"));
    // Started before the move: it says no move runs, then waits — the move starts once it
    // said so (issue 48: a fixed delay guessed at when it had started).
    let (before, before_lines, before_printed) =
        scope_lines(&run, &["--csv", before_csv.to_str().unwrap()]);
    wait_for_line(&before_lines, "no move is running under");
    let out = run.out("out");
    let starter = run.spawn_starter(&[
        &format!("--config={}", config.display()),
        &format!("--out={}", out.display()),
        "step",
    ]);
    // Half a second into the move (its progress page says so), a second scope.
    qmarc_tests::wait_for_progress(
        &run.prefix,
        Duration::from_secs(60),
        "0.5 s of the move",
        |s| s.cycle > 1_250,
    );
    let during = scope(&run, &["--csv", during_csv.to_str().unwrap(), "--every", "2"]);
    let moved = wait_with_timeout(starter, Duration::from_secs(120));
    assert_eq!(moved.code, Some(0), "{}{}", moved.stdout, moved.stderr);
    let before = wait_with_timeout(before, Duration::from_secs(30));
    let before =
        qmarc_tests::Finished { stdout: before_printed.join().unwrap() + &before.stdout, ..before };
    let during = wait_with_timeout(during, Duration::from_secs(30));
    for (name, s, csv) in [("before", before, &before_csv), ("during", during, &during_csv)] {
        assert_eq!(s.code, Some(0), "scope {name}: {}{}", s.stdout, s.stderr);
        assert!(s.stdout.contains("detached: the move is done"), "scope {name}: {}", s.stdout);
        let matched = assert_rows_are_gathered(csv, &out);
        // 6 s at 2.5 kHz, a sample every 4th cycle (every 8th for `--every 2`).
        println!("scope {name}: {matched} samples, each a gather.csv row\n{}", s.stdout);
        assert!(matched > 100, "scope {name}: only {matched} samples");
        if name == "before" {
            // Waiting when the move began, it attached in its first half (6 s: 3750 samples).
            let (_, rows) = read_csv(csv);
            let first: u64 = rows[0][0].parse().unwrap();
            assert!(first < 1_800, "scope {name} missed the move's first half: from {first}");
        }
    }
    // The one started during the move saw it from its middle on, every 2nd sample.
    let (_, rows) = read_csv(&during_csv);
    let seqs: Vec<u64> = rows.iter().map(|r| r[0].parse().unwrap()).collect();
    assert!(seqs[0] > 0, "the scope started during the move saw its first sample");
    assert!(seqs.windows(2).filter(|w| w[1] - w[0] == 2).count() > seqs.len() / 2, "--every 2");
    run.assert_clean();
}

/// Moves without a reader and with one stopped by SIGSTOP (a reader that never reads), then
/// killed with SIGKILL in the middle of the move: the move goes on to its end, gathers every
/// row, and nothing of the reader is left. The timing figures of the two moves are printed
/// beside each other (a VM's noise decides them, so they are compared by eye, not asserted).
#[test]
fn a_reader_that_never_reads_or_is_killed_changes_nothing_of_the_move() {
    let run = TestRun::new("deafscope");
    let config = run.config_with(&[("duration_s", "2.0")]);
    let c = format!("--config={}", config.display());
    let alone = run.out("alone");
    run.starter_ok(&[&c, &format!("--out={}", alone.display()), "step"]);

    let out = run.out("deaf");
    // Its lines as they come: it is stopped once it says it attached.
    let (mut reader, lines, printed) = scope_lines(&run, &[]);
    let starter = run.spawn_starter(&[&c, &format!("--out={}", out.display()), "step"]);
    qmarc_tests::wait_until_moving(&run.prefix, Duration::from_secs(60));
    // Attached (it polls every 50 ms; a loaded machine takes longer), then stopped: its queue
    // fills and overflows.
    wait_for_line(&lines, "attached to the move");
    send_signal(reader.id(), nix::sys::signal::Signal::SIGSTOP);
    std::thread::sleep(Duration::from_millis(900));
    send_signal(reader.id(), nix::sys::signal::Signal::SIGKILL);
    let killed = reader.wait().expect("wait");
    assert_eq!(killed.code(), None, "killed by a signal");
    let printed = printed.join().unwrap();
    assert!(printed.contains("attached to the move"), "{printed}");
    let moved = wait_with_timeout(starter, Duration::from_secs(120));
    assert_eq!(moved.code, Some(0), "{}{}", moved.stdout, moved.stderr);

    for dir in [&alone, &out] {
        let summary = read_summary(dir);
        assert!(summary.fault.is_none(), "{}: {:?}", dir.display(), summary.fault);
        let (_, rows) = read_gather(dir);
        // Every cycle gathered: the only sample indices without a row are the missed
        // periods' and the one where the path ended (that cycle writes nothing; the settle
        // follows).
        let cycles: Vec<u64> = rows.iter().map(|r| r[0] as u64).collect();
        let missing: u64 = cycles.windows(2).map(|w| w[1] - w[0] - 1).sum();
        assert_eq!(missing, summary.timing.missed_periods + 1, "{}", dir.display());
        let t = &summary.timing;
        println!(
            "{:<6} wake p50 {:6.1} p99 {:6.1} µs · tick→DAC p50 {:6.1} p99 {:6.1} µs · missed {} \
             · off > 40 µs {} · {} rows",
            dir.file_name().unwrap().to_string_lossy(),
            t.wake_latency_us.p50,
            t.wake_latency_us.p99,
            t.output_latency_us.p50,
            t.output_latency_us.p99,
            t.missed_periods,
            t.outside_40us,
            rows.len()
        );
    }
    run.assert_clean();
}

/// `qmarc scope --duration S` where no move runs: it says so, waits the S seconds, says no
/// move ran, exits 0 and leaves no file of its waiting (it looks every 50 ms with a node of
/// its own) under the run's prefix.
#[test]
fn a_scope_with_a_duration_and_no_move_says_so_and_leaves_nothing() {
    let run = TestRun::new("idlescope");
    let started = std::time::Instant::now();
    let idle = wait_with_timeout(scope(&run, &["--duration", "0.6"]), Duration::from_secs(30));
    let waited = started.elapsed();
    // Issue 42: nothing recorded is no success.
    assert_eq!(idle.code, Some(1), "{}{}", idle.stdout, idle.stderr);
    let prefix = &run.prefix;
    assert!(
        idle.stdout.contains(&format!("no move is running under {prefix}; waiting for one")),
        "{}",
        idle.stdout
    );
    assert!(idle.stdout.contains("no move ran within 0.6 s"), "{}", idle.stdout);
    assert!(waited >= Duration::from_millis(600), "it left after {waited:?}");
    run.assert_clean();
}
