//! qmarc-cell's own tests: its command line.

use std::process::Command;

fn cell() -> Command {
    Command::new(env!("CARGO_BIN_EXE_qmarc-cell"))
}

#[test]
fn a_bad_cell_name_is_a_usage_error() {
    let out = cell().args(["camera", "--cell", "a/b"]).output().unwrap();
    assert_eq!(out.status.code(), Some(64));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("--cell: must be 1‥31 letters, digits, `-` or `_`"), "{err}");
}
