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
    let servo = std::fs::read_to_string(workspace().join("crates/proto/src/state.rs")).unwrap();
    let body =
        servo.split("pub enum Phase {").nth(1).expect("enum Phase").split("\n}").next().unwrap();
    let variants: Vec<&str> = body
        .lines()
        .map(str::trim)
        .filter(|l| !l.starts_with("///") && !l.is_empty())
        .map(|l| l.split([' ', ',']).next().unwrap())
        .collect();
    assert!(variants.len() >= 6, "{variants:?}");
    let arch = std::fs::read_to_string(workspace().join("ARCHITECTURE.md")).unwrap();
    let diagram =
        arch.split("Controller states: `proto::state::Phase`").nth(1).expect("the state section");
    let diagram =
        diagram.split("```text").nth(1).and_then(|d| d.split("```").next()).expect("a diagram");
    for v in variants {
        assert!(diagram.contains(v), "ARCHITECTURE.md's state diagram lacks `{v}`");
    }
}

/// The workspace's crates, lowest floor first (ARCHITECTURE.md's code map): a crate may
/// depend only on crates of lower floors. `config` knows nothing of the plug-ins (the
/// registries inject the names it accepts) and of the hardware only which backends there are,
/// `controller` is the loop and knows
/// no plug-in and no hardware, the hardware server knows no controller, and the processes
/// (`controller-process`, `starter`, the console) sit on top.
const LAYERS: &[&str] = &[
    "proto",
    "ros2msg",
    "kinematics",
    "conveyor",
    "comedi",
    "timer",
    "config",
    "program",
    "vision",
    "controller",
    "knots",
    "hwserver",
    "camera",
    "telemetry",
    "plugins",
    "session",
    "report",
    "foxglove",
    "bridge",
    "cell",
    "waypoints",
    "plots",
    "controller-process",
    "tune",
    "starter",
    "console-tui",
    "bench",
];

/// The `qmarc-*` crates in the `[<table>]` table (`dependencies`, `dev-dependencies`) of the
/// manifest `dir/Cargo.toml`.
fn qmarc_crates_in(dir: &Path, table: &str) -> Vec<String> {
    let manifest = dir.join("Cargo.toml");
    let text = std::fs::read_to_string(&manifest)
        .unwrap_or_else(|e| panic!("{}: {e}", manifest.display()));
    let table =
        text.split(&format!("\n[{table}]\n")).nth(1).map_or("", |t| t.split("\n[").next().unwrap());
    table
        .lines()
        .filter_map(|l| l.trim().strip_prefix("qmarc-"))
        .map(|l| l.split(['.', ' ', '=']).next().unwrap().to_string())
        .collect()
}

/// The `qmarc-*` crates in the `[dependencies]` table of `crates/<name>/Cargo.toml`.
fn our_dependencies(name: &str) -> Vec<String> {
    qmarc_crates_in(&workspace().join("crates").join(name), "dependencies")
}

/// The `qmarc-*` crates in the `[dev-dependencies]` table of `crates/<name>/Cargo.toml`.
fn our_dev_dependencies(name: &str) -> Vec<String> {
    qmarc_crates_in(&workspace().join("crates").join(name), "dev-dependencies")
}

#[test]
fn crates_depend_only_on_lower_layers() {
    let mut listed: Vec<String> = std::fs::read_dir(workspace().join("crates"))
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    listed.sort();
    let mut layers: Vec<String> = LAYERS.iter().map(|s| s.to_string()).collect();
    layers.sort();
    assert_eq!(listed, layers, "every crate has its place in LAYERS");
    let layer = |dep: &str| {
        let dep = if dep == "console" { "console-tui" } else { dep };
        LAYERS.iter().position(|l| *l == dep).unwrap_or_else(|| panic!("unknown crate {dep}"))
    };
    // `qmarc-tests` (tests/util.rs: the end-to-end helpers) is only ever a dev-dependency;
    // a crate may use it when everything it stands on is below that crate.
    let helpers = qmarc_crates_in(&workspace().join("tests"), "dependencies");
    for (i, name) in LAYERS.iter().enumerate() {
        for dep in our_dependencies(name) {
            assert!(layer(&dep) < i, "crates/{name} depends on qmarc-{dep}, a layer above it");
        }
        for dep in our_dev_dependencies(name) {
            let below = |d: &str| layer(d) < i;
            let ok = if dep == "tests" { helpers.iter().all(|d| below(d)) } else { below(&dep) };
            assert!(ok, "crates/{name} dev-depends on qmarc-{dep}, a layer above it");
        }
    }
    for (name, not) in
        [("controller", "hwserver"), ("hwserver", "controller"), ("telemetry", "controller")]
    {
        let all = [our_dependencies(name), our_dev_dependencies(name)].concat();
        assert!(!all.contains(&not.to_string()), "crates/{name} depends on qmarc-{not}");
    }
    assert!(
        !our_dependencies("console-tui").contains(&"controller".to_string()),
        "the console reads the wire's words from proto, not from the loop's crate"
    );
    assert_eq!(
        our_dependencies("config"),
        ["proto", "kinematics"],
        "config knows no registry or backend"
    );
}

/// Every crate that builds a binary has an integration test target, so `cargo test
/// --workspace` (README's command) builds the binary the end-to-end tests run.
#[test]
fn every_binary_crate_has_an_integration_test_target() {
    for name in LAYERS {
        let dir = workspace().join("crates").join(name);
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
        let has_bin = manifest.contains("[[bin]]") || dir.join("src/main.rs").is_file();
        if has_bin {
            assert!(
                manifest.contains("[[test]]") && dir.join("tests/tests.rs").is_file(),
                "crates/{name} builds a binary but has no tests/tests.rs target"
            );
        }
    }
}

/// Source lines that are code: string literals and `//` comments blanked, so braces in
/// them do not count.
fn code_of(line: &str) -> String {
    let mut out = String::new();
    let mut chars = line.chars().peekable();
    let mut in_str = false;
    while let Some(c) = chars.next() {
        match (in_str, c) {
            (true, '\\') => {
                chars.next();
            }
            (true, '"') => in_str = false,
            (true, _) => {}
            (false, '"') => in_str = true,
            (false, '/') if chars.peek() == Some(&'/') => break,
            (false, '\'') => {
                // A char literal ('{', '\'', '\u{feff}') or a lifetime ('a): skip a literal.
                let rest: String = chars.clone().take(12).collect();
                if let Some(escaped) = rest.strip_prefix('\\') {
                    let len = escaped.chars().skip(1).position(|c| c == '\'').map_or(0, |p| p + 3);
                    for _ in 0..len {
                        chars.next();
                    }
                } else if rest.chars().nth(1) == Some('\'') {
                    chars.nth(1);
                }
            }
            (false, c) => out.push(c),
        }
    }
    out
}

/// `(line, name, length)` of every function body in `text` longer than `limit` lines.
fn long_functions(text: &str, limit: usize) -> Vec<(usize, String, usize)> {
    let lines: Vec<String> = text.lines().map(code_of).collect();
    let mut found = Vec::new();
    for (i, l) in lines.iter().enumerate() {
        let Some(at) = l.find("fn ") else { continue };
        if at > 0 && l.as_bytes()[at - 1].is_ascii_alphanumeric() {
            continue;
        }
        let name: String =
            l[at + 3..].chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        let (mut depth, mut opened) = (0i32, false);
        for (j, body) in lines.iter().enumerate().skip(i) {
            if !opened && !body.contains('{') && body.trim_end().ends_with(';') {
                break; // a declaration without a body
            }
            for c in body.chars() {
                match c {
                    '{' => {
                        depth += 1;
                        opened = true;
                    }
                    '}' => depth -= 1,
                    _ => {}
                }
            }
            if opened && depth <= 0 {
                if j - i + 1 > limit {
                    found.push((i + 1, name.clone(), j - i + 1));
                }
                break;
            }
        }
    }
    found
}

#[test]
fn the_function_length_check_finds_bodies() {
    let text = "fn short() {\n    let s = \"}}}\";\n}\nfn long() {\n    1\n    2\n    3\n}\n";
    assert_eq!(long_functions(text, 3), [(4, "long".to_string(), 5)]);
    assert_eq!(long_functions("fn decl();\nfn f() { '{' }\n", 0).len(), 1);
    let escapes = "fn f() {\n    g('\\u{feff}', '\\'', '}');\n}\nfn h() {\n}\n";
    assert_eq!(long_functions(escapes, 2), [(1, "f".to_string(), 3)]);
}

/// No source file over 600 lines (tests, in `tests.rs` files, excepted), and no function
/// over 80 lines in the crates the servo loop runs in: each stays readable in one sitting.
#[test]
fn files_and_loop_functions_stay_short() {
    // The loop's crates, and the process crates' steps (a move's preparation, launch and
    // conclusion; its report): functions a reader must take in whole.
    const SHORT_FUNCTIONS: &[&str] = &[
        "proto",
        "comedi",
        "timer",
        "controller",
        "hwserver",
        "plugins",
        "report",
        "controller-process",
        "starter",
    ];
    let mut problems = Vec::new();
    for name in LAYERS {
        let mut files = Vec::new();
        rust_files(&workspace().join("crates").join(name).join("src"), &mut files);
        for f in files.iter().filter(|f| !f.ends_with("tests.rs")) {
            let text = std::fs::read_to_string(f).unwrap();
            let shown = f.strip_prefix(workspace()).unwrap().display().to_string();
            if text.lines().count() > 600 {
                problems.push(format!("{shown}: {} lines", text.lines().count()));
            }
            if SHORT_FUNCTIONS.contains(name) {
                for (line, func, len) in long_functions(&text, 80) {
                    problems.push(format!("{shown}:{line}: fn {func} has {len} lines"));
                }
            }
        }
    }
    assert!(
        problems.is_empty(),
        "too long (move tests to a tests.rs, split):\n{}",
        problems.join("\n")
    );
}

/// ARCHITECTURE.md's code map is true: its table names every crate once, on the floor its
/// dependencies put it (one above the highest it stands on), with exactly the crates it
/// depends on (`proto`, `config` and `timer` left out, as the table says).
#[test]
fn the_code_maps_table_is_the_manifests() {
    let arch = std::fs::read_to_string(workspace().join("ARCHITECTURE.md")).unwrap();
    let map = arch.split("## Code map").nth(1).expect("a code map");
    let table = map.split("```text").nth(1).and_then(|t| t.split("```").next()).expect("a table");
    let common = ["proto", "config", "timer"];
    let mut floors = std::collections::BTreeMap::new();
    let mut rows = Vec::new();
    let row = |l: &&str| l.trim_start().starts_with(|c: char| c.is_ascii_digit());
    for line in table.lines().filter(row) {
        let mut words = line.split_whitespace();
        let floor: usize = words.next().unwrap().parse().expect("a floor");
        let name = words.next().unwrap().to_string();
        let on: Vec<String> = words
            .take_while(|w| LAYERS.contains(w) || *w == "—")
            .filter(|w| *w != "—")
            .map(str::to_string)
            .collect();
        floors.insert(name.clone(), floor);
        rows.push((name, on));
    }
    let mut named: Vec<&str> = rows.iter().map(|(n, _)| n.as_str()).collect();
    named.sort();
    let mut crates = LAYERS.to_vec();
    crates.sort();
    assert_eq!(named, crates, "the table names every crate once");
    for (name, on) in &rows {
        let deps: Vec<String> = our_dependencies(name)
            .into_iter()
            .map(|d| if d == "console" { "console-tui".to_string() } else { d })
            .collect();
        let mut expected: Vec<&String> =
            deps.iter().filter(|d| !common.contains(&d.as_str())).collect();
        let mut listed: Vec<&String> = on.iter().collect();
        expected.sort();
        listed.sort();
        assert_eq!(listed, expected, "{name}: the crates it stands on");
        let floor = deps.iter().map(|d| floors[d.as_str()] + 1).max().unwrap_or(0);
        assert_eq!(floors[name.as_str()], floor, "{name}: its floor");
        // Crates on one floor know nothing of each other, in their tests neither.
        for dev in our_dev_dependencies(name).iter().filter(|d| *d != "tests") {
            assert!(floors[dev.as_str()] < floor, "{name} dev-depends on {dev}, not below it");
        }
    }
}

/// The top-level modules of the crate at `src` that each one names (`crate::other…`) outside
/// its tests: module → the modules it uses. A module is `src/<name>.rs` with its folder
/// `src/<name>/`; `lib.rs` and `main.rs` (the root, which declares and re-exports) are none.
fn module_uses(
    src: &Path,
) -> std::collections::BTreeMap<String, std::collections::BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(src, &mut files);
    let module_of = |p: &Path| {
        let rel = p.strip_prefix(src).unwrap();
        let first = rel.components().next()?.as_os_str().to_string_lossy().into_owned();
        let name = first.trim_end_matches(".rs").to_string();
        (name != "lib" && name != "main" && name != "bin").then_some(name)
    };
    let modules: std::collections::BTreeSet<String> =
        files.iter().filter_map(|p| module_of(p)).collect();
    let mut uses: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> =
        modules.iter().map(|m| (m.clone(), Default::default())).collect();
    for file in &files {
        let Some(module) = module_of(file) else { continue };
        if file.file_name().is_some_and(|n| n == "tests.rs") {
            continue;
        }
        let text = std::fs::read_to_string(file).unwrap();
        // The code outside its tests, without comments (a doc link is no dependency).
        let code: String = text
            .split("#[cfg(test)]")
            .next()
            .unwrap_or("")
            .lines()
            .map(code_of)
            .collect::<Vec<_>>()
            .join("\n");
        for (at, _) in code.match_indices("crate::") {
            let rest = &code[at + "crate::".len()..];
            let name: String =
                rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            // `use crate::{a, b}` names several.
            let named: Vec<String> = if let Some(list) = rest.strip_prefix('{') {
                let list = list.split('}').next().unwrap_or("");
                list.split(',')
                    .map(|n| n.trim().split("::").next().unwrap_or("").to_string())
                    .collect()
            } else {
                vec![name]
            };
            for n in named {
                if n != module && modules.contains(&n) {
                    uses.get_mut(&module).unwrap().insert(n);
                }
            }
        }
    }
    uses
}

/// The circles among `uses`: each set of two or more modules that reach each other, sorted.
fn circles(
    uses: &std::collections::BTreeMap<String, std::collections::BTreeSet<String>>,
) -> Vec<Vec<String>> {
    let reach = |from: &String| {
        let mut seen = std::collections::BTreeSet::new();
        let mut todo = vec![from.clone()];
        while let Some(m) = todo.pop() {
            for n in uses.get(&m).into_iter().flatten() {
                if seen.insert(n.clone()) {
                    todo.push(n.clone());
                }
            }
        }
        seen
    };
    let reached: std::collections::BTreeMap<&String, _> =
        uses.keys().map(|m| (m, reach(m))).collect();
    let mut found: Vec<Vec<String>> = Vec::new();
    for m in uses.keys() {
        let mut circle: Vec<String> = uses
            .keys()
            .filter(|n| *n == m || (reached[m].contains(*n) && reached[*n].contains(m)))
            .cloned()
            .collect();
        circle.sort();
        if circle.len() > 1 && !found.contains(&circle) {
            found.push(circle);
        }
    }
    found
}

#[test]
fn the_circle_finder_finds_a_circle_and_only_one() {
    let uses = |pairs: &[(&str, &str)]| {
        let mut u: std::collections::BTreeMap<String, std::collections::BTreeSet<String>> =
            Default::default();
        for (a, b) in pairs {
            u.entry(a.to_string()).or_default().insert(b.to_string());
            u.entry(b.to_string()).or_default();
        }
        u
    };
    assert!(circles(&uses(&[("a", "b"), ("b", "c")])).is_empty());
    let found = circles(&uses(&[("a", "b"), ("b", "c"), ("c", "a"), ("c", "d")]));
    assert_eq!(found, [["a", "b", "c"].map(String::from).to_vec()]);
}

/// Inside a crate, files (top-level modules) depend on each other without circles: two files
/// that need each other are one concept not yet named (issue 43 named the last six).
#[test]
fn no_crate_has_a_circle_of_files() {
    let mut problems = Vec::new();
    for name in LAYERS {
        let src = workspace().join("crates").join(name).join("src");
        for circle in circles(&module_uses(&src)) {
            problems.push(format!("crates/{name}: {}", circle.join(" ⇄ ")));
        }
    }
    assert!(problems.is_empty(), "circles of files:\n{}", problems.join("\n"));
}
