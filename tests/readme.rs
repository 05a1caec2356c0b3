//! README's commands, run as written (issue 43): every line of its `sh` blocks, from a scratch
//! folder laid out as a fresh clone after `cargo build --release`, so the README cannot drift
//! from what the programs do.
//!
//! How a block runs: as one bash script (`set -euo pipefail`), its working directory the
//! scratch folder, its background jobs (`serve &`) waited for at its end, each of which must
//! succeed. In the folder, `target/release/` holds the binaries this `cargo test` built (a
//! nested release build would take minutes): `qmarc-starter`, `qmarc` and `qmarc-bridge` are
//! two-line shims that run the real program with the command's own arguments followed by the
//! test's own `--iox-prefix` and `--iox-root` (global options of each), so that the test's
//! runs and sessions are its own; the other binaries are links. `config/` holds the shipped
//! settings with the simulated robot's `sim.state_file` moved into the folder (the shipped one
//! is in /dev/shm, shared by every run of the machine); `knots/` and `examples/` link to the
//! repository's. The console (`./target/release/qmarc` alone) runs in an 80×24 tmux pane and
//! is left with F12, as a user leaves it.
//!
//! What is not run is listed here, with why: [`SKIPPED`] lines and [`STANDING_IN`] parts of
//! lines; an entry the README no longer needs fails the test.

use qmarc_tests::{TestRun, bin_dir, s626_config, shipped_config, workspace};
use std::os::unix::process::CommandExt;
use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// README lines the test does not run, found by a part of the line, and why.
const SKIPPED: &[(&str, &str)] = &[
    (
        "scripts/test",
        "it installs packages and runs `cargo test --workspace`, this test among them",
    ),
    (
        "--device /dev/comedi0",
        "it needs a Sensoray 626 card; the same backend runs on the fake driver in the next line \
         and in tests/hardware.rs",
    ),
];

/// Parts of README lines the test leaves out, and why; the rest of the line runs.
const STANDING_IN: &[(&str, &str)] = &[(
    "cargo build --release && ",
    "the binaries `cargo test --workspace` built stand in for the release build",
)];

/// The console's command line: a terminal program, run in tmux and left with F12.
const CONSOLE: &str = "./target/release/qmarc";

/// How long one block may take (a loaded machine, debug binaries, the tuning's search).
const BLOCK_TIMEOUT: Duration = Duration::from_secs(600);

/// The `sh` blocks of README.md, each as its logical lines (a line ending in `\` joined with
/// the next), with their line numbers.
fn sh_blocks(readme: &str) -> Vec<Vec<(usize, String)>> {
    let mut blocks = Vec::new();
    let mut block: Option<Vec<(usize, String)>> = None;
    let mut pending = String::new();
    for (idx, line) in readme.lines().enumerate() {
        match &mut block {
            None if line.trim_end() == "```sh" => block = Some(Vec::new()),
            None => {}
            Some(b) if line.trim_end() == "```" => {
                assert!(pending.is_empty(), "README:{}: a block ends in `\\`", idx + 1);
                blocks.push(std::mem::take(b));
                block = None;
            }
            Some(b) => match line.strip_suffix('\\') {
                Some(part) => pending.push_str(part),
                None => {
                    b.push((idx + 1, format!("{pending}{line}")));
                    pending.clear();
                }
            },
        }
    }
    assert!(block.is_none(), "README ends inside an `sh` block");
    blocks
}

/// The command part of a line: without its `#` comment (README's comments follow two spaces
/// or more) and surrounding blanks.
fn command(line: &str) -> &str {
    line.split("  #").next().unwrap_or_default().trim()
}

/// The scratch folder of a fresh clone after its release build (see the module's doc).
fn lay_out_clone(run: &TestRun) {
    let bins = bin_dir();
    let release = run.dir.join("target/release");
    std::fs::create_dir_all(&release).expect("target/release");
    let isolation = run.isolation_args().join(" ");
    for name in ["qmarc-starter", "qmarc", "qmarc-bridge"] {
        let real = bins.join(name);
        assert!(
            real.is_file(),
            "{} is missing: run the tests with `scripts/test` (cargo test --workspace), which builds it",
            real.display()
        );
        let shim = format!("#!/bin/sh\nexec '{}' \"$@\" {isolation}\n", real.display());
        let path = release.join(name);
        std::fs::write(&path, shim).expect("a shim");
        let mode = std::os::unix::fs::PermissionsExt::from_mode(0o755);
        std::fs::set_permissions(&path, mode).expect("an executable shim");
    }
    for name in
        ["qmarc-hwserver", "qmarc-controller", "qmarc-bench", "qmarc-camera", "qmarc-foxglove"]
    {
        std::os::unix::fs::symlink(bins.join(name), release.join(name)).expect("a link");
    }
    for dir in ["knots", "examples"] {
        std::os::unix::fs::symlink(workspace().join(dir), run.dir.join(dir)).expect("a link");
    }
    std::fs::create_dir_all(run.dir.join("config")).expect("config/");
    run.config_as("config/qmarc.toml", &shipped_config(), &[]);
    run.config_as("config/s626.toml", &s626_config(), &[]);
    run.config_as("config/tuned.toml", &qmarc_tests::tuned_config(), &[]);
    let rehearsal = "config/rehearse-without-rt.toml";
    std::fs::copy(workspace().join(rehearsal), run.dir.join(rehearsal)).expect(rehearsal);
}

/// What a block's script printed and how it ended.
struct Ran {
    code: Option<i32>,
    output: String,
}

/// Runs `script` with bash in `dir`, its own process group killed after [`BLOCK_TIMEOUT`].
fn bash(dir: &Path, script: &str) -> Ran {
    let log = dir.join("block.log");
    let file = std::fs::File::create(&log).expect("the block's log");
    let mut child = Command::new("bash")
        .arg("-c")
        .arg(script)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(file.try_clone().expect("the log"))
        .stderr(file)
        .process_group(0)
        .spawn()
        .expect("bash");
    let started = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().expect("wait") {
            break s;
        }
        if started.elapsed() > BLOCK_TIMEOUT {
            let group = nix::unistd::Pid::from_raw(-(child.id() as i32));
            let _ = nix::sys::signal::kill(group, nix::sys::signal::Signal::SIGKILL);
            let _ = child.wait();
            let output = std::fs::read_to_string(&log).unwrap_or_default();
            panic!("timed out after {BLOCK_TIMEOUT:?}:\n{script}\noutput:\n{output}");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    Ran { code: status.code(), output: std::fs::read_to_string(&log).unwrap_or_default() }
}

/// Runs the console's `line` in an 80×24 tmux pane in `dir`: waits for its setup page, leaves
/// it with F12 (without saving) and returns how it ended.
fn console(dir: &Path, line: &str) -> Ran {
    let socket = dir.join("tmux.sock");
    let tmux = |args: &[&str]| {
        let out = Command::new("tmux").arg("-S").arg(&socket).args(args).output();
        out.unwrap_or_else(|e| panic!("cannot run tmux (scripts/test installs it): {e}"))
    };
    let shell = format!("{line}; echo \"[readme: exited $?]\"");
    let d = dir.to_str().expect("a UTF-8 path");
    let started = tmux(&[
        "-f",
        "/dev/null",
        "new-session",
        "-d",
        "-x",
        "80",
        "-y",
        "24",
        "-c",
        d,
        &shell,
        ";",
        "set-option",
        "-g",
        "remain-on-exit",
        "on",
    ]);
    assert!(started.status.success(), "tmux: {}", String::from_utf8_lossy(&started.stderr));
    let screen = || String::from_utf8_lossy(&tmux(&["capture-pane", "-p"]).stdout).into_owned();
    let wait_for = |what: &str, done: &dyn Fn(&str) -> bool| {
        let start = Instant::now();
        loop {
            let s = screen();
            if done(&s) {
                return s;
            }
            if start.elapsed() > Duration::from_secs(120) {
                tmux(&["kill-server"]);
                panic!("no {what} within 120 s; the screen:\n{s}");
            }
            std::thread::sleep(Duration::from_millis(100));
        }
    };
    wait_for("setup page", &|s| {
        s.contains("Cancel (leave without saving)") || s.contains("[readme: exited")
    });
    tmux(&["send-keys", "F12"]);
    let end = wait_for("end of the console", &|s| s.contains("[readme: exited "));
    tmux(&["kill-server"]);
    let code = end.split("[readme: exited ").nth(1).and_then(|r| r.split(']').next());
    Ran { code: code.and_then(|c| c.parse().ok()), output: end }
}

/// Every command of README's `sh` blocks runs as written and succeeds; what cannot run is
/// listed in [`SKIPPED`] and [`STANDING_IN`], each entry still needed.
#[test]
fn readme_commands_run_as_written() {
    let readme = std::fs::read_to_string(workspace().join("README.md")).expect("README.md");
    let blocks = sh_blocks(&readme);
    assert!(blocks.len() > 5, "README's `sh` blocks: {}", blocks.len());
    let run = TestRun::new("readme");
    lay_out_clone(&run);
    let mut skips_used = vec![false; SKIPPED.len()];
    let mut stand_ins_used = vec![false; STANDING_IN.len()];
    for (block_idx, block) in blocks.iter().enumerate() {
        let mut script = String::from("set -euo pipefail\n");
        let mut commands = 0;
        for (number, line) in block {
            if let Some(i) = SKIPPED.iter().position(|(part, _)| command(line).contains(part)) {
                eprintln!("README:{number}: skipped `{}`: {}", command(line), SKIPPED[i].1);
                skips_used[i] = true;
                continue;
            }
            let mut line = line.clone();
            for (i, (part, why)) in STANDING_IN.iter().enumerate() {
                if line.contains(part) {
                    eprintln!("README:{number}: `{}` left out: {why}", part.trim());
                    line = line.replace(part, "");
                    stand_ins_used[i] = true;
                }
            }
            if command(&line) == CONSOLE {
                assert_eq!(block.len(), 1, "README:{number}: the console is a block of its own");
                eprintln!("README:{number}: `{CONSOLE}` in tmux, left with F12");
                let r = console(&run.dir, CONSOLE);
                assert_eq!(r.code, Some(0), "README:{number}: the console:\n{}", r.output);
                continue;
            }
            if !command(&line).is_empty() {
                commands += 1;
            }
            script.push_str(&line);
            script.push('\n');
        }
        if commands == 0 {
            continue;
        }
        script.push_str("for job in $(jobs -p); do wait \"$job\"; done\n");
        let first = block.first().map_or(0, |(n, _)| *n);
        eprintln!("README:{first}: running block {block_idx}");
        let started = Instant::now();
        let r = bash(&run.dir, &script);
        eprintln!(
            "README:{first}: block {block_idx} took {:.1} s",
            started.elapsed().as_secs_f64()
        );
        assert_eq!(r.code, Some(0), "README:{first}: the block\n{script}\nfailed:\n{}", r.output);
        if block_idx == 0 {
            assert!(r.output.contains("QMARC step: ok"), "README's first command:\n{}", r.output);
        }
    }
    for (used, (part, _)) in skips_used.iter().zip(SKIPPED) {
        assert!(used, "SKIPPED names `{part}`, which no README command has: remove it");
    }
    for (used, (part, _)) in stand_ins_used.iter().zip(STANDING_IN) {
        assert!(used, "STANDING_IN names `{part}`, which no README command has: remove it");
    }
    run.assert_clean();
}
