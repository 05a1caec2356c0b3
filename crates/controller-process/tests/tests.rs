//! Integration tests of the `qmarc-controller` process: run by hand from the run file the
//! starter prints (`--print-settings`), as a developer debugging it would, and refusing a
//! file that is not a run file. (The starter runs it in every end-to-end test of `tests/`.)

use qmarc_proto::exit;
use qmarc_tests::{TestRun, bin_dir, read_summary, wait_with_timeout, workspace};
use std::process::{Command, Stdio};
use std::time::Duration;

/// Starts `bin` (a workspace binary) with `--settings FILE`, output captured.
fn spawn_with_settings(bin: &str, settings: &std::path::Path) -> std::process::Child {
    Command::new(bin_dir().join(bin))
        .arg(format!("--settings={}", settings.display()))
        .current_dir(workspace())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("spawn {bin}: {e}"))
}

#[test]
fn the_children_run_by_hand_from_the_printed_settings() {
    let t = TestRun::new("byhand");
    let config = t.config_with(&[]);
    let out = t.out("out");
    let printed = t.starter(
        &[
            &format!("--config={}", config.display()),
            &format!("--out={}", out.display()),
            "--deterministic",
            "--print-settings",
            "step",
            "--duration=0.2",
        ],
        Duration::from_secs(30),
    );
    assert_eq!(printed.code, Some(0), "--print-settings: {}", printed.stderr);
    assert!(!out.join("summary.json").exists(), "--print-settings ran a move");
    let run = t.dir.join("run.json");
    std::fs::write(&run, &printed.stdout).expect("write the run file");

    let hwserver = spawn_with_settings("qmarc-hwserver", &run);
    let controller = spawn_with_settings("qmarc-controller", &run);
    let c = wait_with_timeout(controller, Duration::from_secs(60));
    let h = wait_with_timeout(hwserver, Duration::from_secs(30));
    assert_eq!(c.code, Some(i32::from(exit::OK)), "controller: {}", c.stderr);
    assert_eq!(h.code, Some(i32::from(exit::OK)), "hwserver: {}", h.stderr);
    let summary = read_summary(&out);
    assert!(summary.fault.is_none(), "{:?}", summary.fault);
    assert_eq!(summary.cycles, 501, "0.2 s at 400 µs, plus sample 0");
    // Run by hand, nobody removes the run's iceoryx2 files but the processes themselves (and
    // iceoryx2's deliberate 16-byte management segment): the starter does that for a run.
    t.location().remove_files();
    assert!(t.processes().is_empty(), "processes left behind: {:?}", t.processes());
}

#[test]
fn a_file_that_is_not_a_run_file_is_a_usage_error_naming_it() {
    let t = TestRun::new("badrun");
    for (name, text) in
        [("garbage.json", "step --size 1000\n"), ("old.json", "{\"mode\": \"step\"}")]
    {
        let file = t.dir.join(name);
        std::fs::write(&file, text).expect("write");
        for bin in ["qmarc-controller", "qmarc-hwserver"] {
            let r = wait_with_timeout(spawn_with_settings(bin, &file), Duration::from_secs(10));
            assert_eq!(r.code, Some(i32::from(exit::USAGE)), "{bin} {name}: {}", r.stderr);
            assert!(
                r.stderr.contains(&file.display().to_string())
                    && r.stderr.contains("not a QMARC run file"),
                "{bin} {name}: {}",
                r.stderr
            );
            assert_eq!(r.stderr.trim().lines().count(), 1, "one line: {}", r.stderr);
        }
    }
    assert!(t.processes().is_empty());
}
