//! The `qmarc` binary before it takes the terminal: settings it cannot read are refused with
//! the file named and the terminal left alone. (The console itself is driven in tmux by the
//! workspace's end-to-end tests, `tests/console.rs`.)

use std::process::Command;

#[test]
fn a_missing_settings_file_is_named_and_the_terminal_untouched() {
    let out = Command::new(env!("CARGO_BIN_EXE_qmarc"))
        .args(["--config", "/nonexistent/qmarc.toml"])
        .output()
        .expect("run qmarc");
    assert_eq!(out.status.code(), Some(i32::from(qmarc_proto::exit::REFUSED)), "the exit table");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("/nonexistent/qmarc.toml: cannot read the settings file"), "{err}");
    // No escape sequence (alternate screen, raw mode) was written.
    assert!(!out.stdout.contains(&0x1b) && !out.stderr.contains(&0x1b), "{err}");
}

#[test]
fn a_console_without_a_terminal_says_so() {
    // Standard output is a pipe: the console refuses before touching any terminal.
    let config = concat!(env!("CARGO_MANIFEST_DIR"), "/../../config/qmarc.toml");
    let out = Command::new(env!("CARGO_BIN_EXE_qmarc"))
        .args(["--config", config])
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .stdin(std::process::Stdio::null())
        .output()
        .expect("run qmarc");
    assert_eq!(out.status.code(), Some(i32::from(qmarc_proto::exit::INTERNAL)));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("the console needs a terminal"), "{err}");
    assert!(!out.stdout.contains(&0x1b), "escape sequences written");
}
