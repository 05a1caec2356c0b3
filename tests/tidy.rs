//! Repository rules that `cargo test` enforces: every Rust source file opens with a `//!`
//! comment that says what it is.

use qmarc_tests::workspace;
use std::path::{Path, PathBuf};

fn rust_files(dir: &Path, out: &mut Vec<PathBuf>) {
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let p = e.path();
        let name = e.file_name();
        if name == "target" || name.to_string_lossy().starts_with('.') {
            continue;
        }
        if p.is_dir() {
            rust_files(&p, out);
        } else if p.extension().is_some_and(|x| x == "rs") {
            out.push(p);
        }
    }
}

#[test]
fn every_rust_file_starts_with_a_module_doc_comment() {
    let mut files = Vec::new();
    rust_files(&workspace(), &mut files);
    assert!(files.len() > 20, "found the sources");
    let missing: Vec<_> = files
        .iter()
        .filter(|f| !std::fs::read_to_string(f).unwrap().trim_start().starts_with("//!"))
        .collect();
    assert!(missing.is_empty(), "files without a leading //! comment: {missing:?}");
}

#[test]
fn the_state_diagram_in_architecture_md_names_every_phase_of_the_code() {
    let servo =
        std::fs::read_to_string(workspace().join("crates/controller/src/servo.rs")).unwrap();
    let body =
        servo.split("pub enum Phase {").nth(1).expect("enum Phase").split("\n}").next().unwrap();
    let variants: Vec<&str> = body
        .lines()
        .map(str::trim)
        .filter(|l| !l.starts_with("///") && !l.is_empty())
        .map(|l| l.trim_end_matches(','))
        .collect();
    assert!(variants.len() >= 6, "{variants:?}");
    let arch = std::fs::read_to_string(workspace().join("ARCHITECTURE.md")).unwrap();
    let diagram =
        arch.split("Controller states: `servo::Phase`").nth(1).expect("the state section");
    let diagram =
        diagram.split("```text").nth(1).and_then(|d| d.split("```").next()).expect("a diagram");
    for v in variants {
        assert!(diagram.contains(v), "ARCHITECTURE.md's state diagram lacks `{v}`");
    }
}
