//! Unit tests of `ui`.

use super::*;
use crate::form::{Form, Place};
use crate::results::{MoveResult, Series};
use qmarc_proto::state::FaultKind;
use qmarc_report::summary::{FaultReport, Summary};
use ratatui::Terminal;
use ratatui::backend::TestBackend;
use ratatui::buffer::Buffer;

struct Scratch(std::path::PathBuf);
impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn app() -> (Scratch, App) {
    static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
    let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("qmarc-ui-{}-{n}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let shipped = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
    let cfg = dir.join("qmarc.toml");
    std::fs::copy(shipped, &cfg).unwrap();
    // Relative paths (knots) resolve from the repository, as when run from its root.
    let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let mut form = Form::load_in(&cfg, &repo).unwrap();
    let out = form.index(Place::Key("gather", "out_dir")).unwrap();
    form.set_text(out, dir.join("out").to_str().unwrap());
    let app = App::new(form, "qmarc-starter".into(), repo);
    (Scratch(dir), app)
}

fn render(app: &App, w: u16, h: u16) -> Buffer {
    let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
    t.draw(|f| draw(f, app)).unwrap();
    t.backend().buffer().clone()
}

fn text(b: &Buffer) -> String {
    let a = b.area;
    (0..a.height)
        .map(|y| (0..a.width).map(|x| b[(x, y)].symbol()).collect::<String>())
        .collect::<Vec<_>>()
        .join("\n")
}

/// The position of the first occurrence of `needle` (in cells).
fn find(b: &Buffer, needle: &str) -> Option<(u16, u16)> {
    let a = b.area;
    (0..a.height).find_map(|y| {
        let row: Vec<&str> = (0..a.width).map(|x| b[(x, y)].symbol()).collect();
        let chars: Vec<char> = needle.chars().collect();
        (0..row.len().saturating_sub(chars.len() - 1)).find_map(|x| {
            chars
                .iter()
                .enumerate()
                .all(|(k, c)| row[x + k] == c.to_string())
                .then_some((x as u16, y))
        })
    })
}

#[test]
fn setup_shows_the_five_sections_and_the_actions_at_80x24() {
    let (_d, app) = app();
    let b = render(&app, 80, 24);
    let s = text(&b);
    for want in [
        "General",
        "Motors",
        "Period µs",
        "Trajectory",
        "‹ spline ›",
        "knots/sine-3motors.txt",
        "Step",
        "Size",
        "Duration s",
        "Data gathering",
        "Every",
        "Out dir",
        "Fields",
        "Gains (one column per motor)",
        "Home",
        "Kp",
        "Kvff",
        "d2",
        "182000",
        "119000",
        "Home robot",
        "Start controller",
        "Step motors now",
        "Exit (save)",
        "Cancel (leave without saving)",
    ] {
        assert!(s.contains(want), "missing {want:?} in\n{s}");
    }
}

#[test]
fn gain_columns_beyond_the_number_of_motors_are_disabled() {
    let (_d, mut app) = app();
    let b = render(&app, 80, 24);
    let (x, y) = find(&b, "M4").unwrap();
    assert_eq!(b[(x, y)].fg, Color::DarkGray, "motor 4 disabled with 3 motors");
    let (x3, y3) = find(&b, "M3").unwrap();
    assert_ne!(b[(x3, y3)].fg, Color::DarkGray);
    // The Kp of motor 4 is dim too, and not focusable.
    let kp4 = app.form.index(Place::Motor(3, "kp")).unwrap();
    assert!(!app.form.enabled(kp4));
    app.form.set_text(0, "4");
    let b = render(&app, 80, 24);
    let (x, y) = find(&b, "M4").unwrap();
    assert_ne!(b[(x, y)].fg, Color::DarkGray, "enabled with 4 motors");
}

#[test]
fn an_invalid_field_shows_its_message_in_place_and_blocks_the_actions() {
    let (_d, mut app) = app();
    let period = app.form.index(Place::Key("general", "period_us")).unwrap();
    app.form.set_text(period, "50");
    let b = render(&app, 80, 24);
    let s = text(&b);
    assert!(s.contains("↳ servo period must be 100‥100000"), "{s}");
    assert!(s.contains("Step motors now — blocked"), "{s}");
    let (x, y) = find(&b, "50 ").unwrap();
    assert_eq!(b[(x, y)].fg, Color::Red);
    // A bad gain: red in its cell, the reason on the message line when focused.
    let kd2 = app.form.index(Place::Motor(1, "kd")).unwrap();
    app.form.set_text(kd2, "x");
    app.focus = kd2;
    app.on_key(ratatui::crossterm::event::KeyEvent::from(
        ratatui::crossterm::event::KeyCode::Char('y'),
    ));
    let s = text(&render(&app, 80, 24));
    assert!(s.contains("invalid type: string \"y\", expected f64"), "{s}");
}

fn result(fault: bool) -> MoveResult {
    let mut summary =
        Summary::controller_lost((qmarc_config::Mode::Step, false), 3, 400, 0, String::new());
    summary.fault = fault.then(|| FaultReport {
        kind: FaultKind::LimitSwitch,
        motor: Some(1),
        cycle: 12,
        message: "motor 1 hit its top limit switch at cycle 12; all motors disabled".into(),
        hw_time_ns: None,
    });
    summary.trajectory = "step".into();
    summary.ok = !fault;
    let csv =
        "cycle,time_s,cmd1,act1,dac1\n0,0,0,0,0\n1,0.0004,1000,3,8191\n2,0.0008,1000,20,500\n";
    MoveResult {
        summary,
        series: Ok(Series::parse(csv, 0.0004).unwrap()),
        end: crate::results::EndRow::parse(
            csv.lines().next().unwrap(),
            csv.lines().last().unwrap(),
        ),
        written: None,
        plots: vec!["out/arms.png".into(), "out/error.png".into()],
        dir: "out".into(),
    }
}

#[test]
fn results_show_a_fault_in_red_and_the_charts_draw() {
    let (_d, mut app) = app();
    app.last = Some(result(true));
    app.page = Page::Results;
    let b = render(&app, 80, 24);
    let (x, y) = find(&b, "FAULT limit_switch").unwrap();
    assert_eq!(b[(x, y)].fg, Color::Red);
    assert!(text(&b).contains("motor 1 hit its top limit switch"));
    app.page = Page::Charts;
    let s = text(&render(&app, 80, 24));
    for want in ["command vs actual", "following error", "servo period"] {
        assert!(s.contains(want), "{s}");
    }
    // Issue 13: the charts page names the move's PNG plots.
    assert!(s.contains("PNG plots: out/arms.png  out/error.png"), "{s}");
    app.last.as_mut().unwrap().plots.clear();
    assert!(text(&render(&app, 80, 24)).contains("PNG plots: none for this move"));
}

#[test]
fn no_page_panics_at_any_size() {
    let (_d, mut app) = app();
    app.last = Some(result(false));
    app.log = (0..100).map(|i| format!("line {i}")).collect();
    for page in [Page::Setup, Page::Log, Page::Results, Page::Charts, Page::History] {
        app.page = page;
        for (w, h) in [(1, 1), (10, 3), (40, 10), (80, 24), (79, 23), (200, 60)] {
            render(&app, w, h);
        }
    }
}

#[test]
fn history_trends_compare_whole_moves_of_the_same_kind() {
    let (_d, mut app) = app();
    let entry = |n, what: &str, fault: Option<FaultKind>, acc: f64| crate::results::HistoryEntry {
        n,
        what: what.into(),
        fault,
        accumulated: vec![acc; 3],
        gains: vec![(182000.0, 3000.0, 119000.0); 3],
    };
    app.history = vec![
        entry(1, "step", None, 9000.0),
        entry(2, "step", Some(FaultKind::FollowingError), 500.0),
        entry(3, "run (spline)", None, 100.0),
        entry(4, "step", None, 8000.0),
    ];
    app.page = Page::History;
    let s = text(&render(&app, 80, 24));
    let row = |n: &str| s.lines().find(|l| l.starts_with(&format!("│{n}   "))).unwrap().to_string();
    // The cut-short move and the first run have nothing to compare with; move 4 is
    // compared with move 1, not with the faulted move 2 or the run.
    assert!(!row("2").contains('↓') && !row("2").contains('↑'), "{s}");
    assert!(!row("3").contains('↓') && !row("3").contains('↑'), "{s}");
    assert!(row("4").contains("8000 ↓"), "{s}");
    assert!(row("2").contains("following_error"), "{s}");
    assert!(s.contains("Kp/Kd/Kvff 182000/3000/119000"), "{s}");
}

fn key(code: ratatui::crossterm::event::KeyCode) -> ratatui::crossterm::event::KeyEvent {
    ratatui::crossterm::event::KeyEvent::from(code)
}

/// Issue 10, item 17: the log wraps long lines and scrolls (↑↓ PgUp PgDn Home End).
#[test]
fn the_log_wraps_and_scrolls() {
    use ratatui::crossterm::event::KeyCode;
    let (_d, mut app) = app();
    app.log = (0..60).map(|i| format!("line {i}")).collect();
    let long = format!("qmarc-controller: error: {}END", "x".repeat(150));
    app.log.push(long);
    app.on_key(key(KeyCode::F(3)));
    let s = text(&render(&app, 80, 24));
    assert!(s.contains("END"), "the end of a long line is shown, wrapped:\n{s}");
    assert!(!s.contains("line 0 "), "{s}");
    app.on_key(key(KeyCode::Home));
    let s = text(&render(&app, 80, 24));
    assert!(s.contains("line 0"), "Home: the first line:\n{s}");
    assert!(s.contains("rows 1‥"), "the title says where:\n{s}");
    app.on_key(key(KeyCode::End));
    app.on_key(key(KeyCode::PageUp));
    let s = text(&render(&app, 80, 24));
    assert!(!s.contains("END") && s.contains("line 5"), "a page up:\n{s}");
    // The message line has the page's keys, not the setup page's hint.
    assert!(app.status.0.starts_with("↑↓ PgUp PgDn scroll"), "{:?}", app.status);
}

/// Issue 10, item 17: Ctrl-U empties a field instead of typing a `u`; a hint never
/// outlives its page or its key.
#[test]
fn ctrl_u_clears_a_field_and_hints_follow_the_page() {
    use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
    let (_d, mut app) = app();
    let period = app.form.index(Place::Key("general", "period_us")).unwrap();
    app.focus = period;
    app.on_key(KeyEvent::new(KeyCode::Char('u'), KeyModifiers::CONTROL));
    assert_eq!(app.form.fields[period].text, "", "emptied");
    assert!(app.status.1, "an empty period is an error: {:?}", app.status);
    app.on_key(key(KeyCode::Esc));
    assert_eq!(app.form.fields[period].text, "400", "Esc brings it back");
    app.on_key(KeyEvent::new(KeyCode::Char('x'), KeyModifiers::ALT));
    assert_eq!(app.form.fields[period].text, "400", "Alt-x types nothing");
    app.on_key(key(KeyCode::F(7)));
    assert!(app.status.0.starts_with("←/→ or 1–4"), "{:?}", app.status);
    app.on_key(key(KeyCode::F(1)));
    assert!(app.status.0.starts_with("Period µs: type a value"), "{:?}", app.status);
}

/// Issue 10, item 17: the charts have legends; the results of a homing show where each
/// switch was found.
#[test]
fn charts_have_legends_and_homing_results_show_the_switches() {
    let (_d, mut app) = app();
    let mut r = result(false);
    r.summary.mode = qmarc_config::Mode::Home;
    r.summary.homing = Some(qmarc_report::summary::HomingReport {
        motors: vec![qmarc_report::summary::MotorHome {
            motor: 1,
            switch_found_counts: Some(-9500.0),
            switch_cleared_counts: Some(-9498.0),
            home_counts: Some(-7498.0),
            ended_counts: Some(-7498.0),
            started_on_switch: false,
            home: true,
        }],
        after: None,
    });
    app.last = Some(r);
    app.page = Page::Charts;
    let s = text(&render(&app, 80, 24));
    for want in ["command", "actual", "command − actual", "period"] {
        assert!(s.contains(want), "legend {want:?}:\n{s}");
    }
    app.page = Page::Results;
    let s = text(&render(&app, 80, 24));
    assert!(s.contains("M1 switch found -9500, cleared -9498, home -7498 ✓ reads 0"), "{s}");
}

/// Issue 10, item 17: the actions never overflow their box, however small the terminal.
#[test]
fn the_actions_fit_their_box_at_any_size() {
    let (_d, app) = app();
    for (w, h) in [(80, 24), (80, 18), (60, 14), (40, 10)] {
        let s = text(&render(&app, w, h));
        let box_rows: Vec<&str> =
            s.lines().filter(|l| l.contains("F12") || l.contains("ready:")).collect();
        assert!(!box_rows.is_empty() || h < 12, "{w}×{h}: no actions:\n{s}");
        for l in s.lines() {
            assert_eq!(
                l.chars().count(),
                usize::from(w),
                "{w}×{h}: a row of the wrong width:\n{s}"
            );
        }
    }
    let s = text(&render(&app, 80, 18));
    assert!(s.contains("ready: F2 F5 F6 F10 F12"), "compact at 80×18:\n{s}");
}

/// A tuning's results page fits 80 columns (three motors' before → after cells side by side)
/// and Ctrl-A puts exactly the tuned gains into the form, unsaved.
#[test]
fn a_tuning_is_shown_before_after_and_ctrl_a_takes_its_gains() {
    use crate::tuning::TuneResult;
    use qmarc_tune::eval::Figures;
    use qmarc_tune::report::{MotorOutcome, TuneSummary};
    let (_scratch, mut app) = app();
    let fig = |abs: f64| Figures {
        abs_rad: abs,
        sse_rad2: abs * 1e-3,
        max_rad: 0.01,
        min_rad: -0.01,
        saturated: 0.0,
    };
    let motor = |m: f64| MotorOutcome {
        before: fig(2.0 + m),
        after: Some(fig(0.5 + m * 0.1)),
        gains_before: [182_000.0, 0.0, 2_800.0, 180_000.0, 100.0, 0.0],
        gains_after: [190_000.5 + m, 0.0, 2_900.0, 200_000.0, 1_000_000.0, 0.0],
    };
    app.tuned = Some(TuneResult {
        summary: TuneSummary {
            starter_pid: 1,
            knots: "knots/xz-pick-place-spline.txt".into(),
            method: "spline".into(),
            objective: "abs".into(),
            params: vec!["kp".into(), "kvff".into(), "kaff".into()],
            candidates: 898,
            moves: 0,
            ended_early: None,
            motors: (0..3).map(|m| motor(f64::from(m))).collect(),
        },
        dir: "out/tune".into(),
        latest: true,
    });
    app.page = Page::Results;
    let s = text(&render(&app, 80, 24));
    for want in ["Results of the last tuning", "898 candidates", "2.000→0.500 ×0.25", "kaff"] {
        assert!(s.contains(want), "{want} missing:\n{s}");
    }
    // Each motor's cell starts in its own column: M3's is whole within 80 columns.
    assert!(s.contains("4.000→0.700 ×0.17"), "motor 3 cut:\n{s}");
    use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
    let text_at = |app: &App, m: usize, key: &'static str| {
        app.form.fields[app.form.index(Place::Motor(m, key)).unwrap()].text.clone()
    };
    let kd = text_at(&app, 0, "kd");
    app.on_key(KeyEvent::new(KeyCode::Char('a'), KeyModifiers::CONTROL));
    assert_eq!(text_at(&app, 2, "kp"), "190002.5");
    assert_eq!(text_at(&app, 0, "kaff"), "1000000.0");
    // Kd was not tuned: left as it was (not the summary's value).
    assert_eq!(text_at(&app, 0, "kd"), kd);
    assert!(app.form.dirty(), "taken into the form, not saved");
    assert!(app.status.0.contains("tuned gains in the form"), "{:?}", app.status);
}

/// Issue 27, item 3: the jog keys — Ctrl-↑/↓ choose the motor (within the motors in use),
/// Ctrl-←/→ jog it by `[jog] counts` through the starter's `jog`, on the log, results and
/// history pages (not where arrows edit or choose).
#[test]
fn the_jog_keys_choose_a_motor_and_jog_it_through_the_starter() {
    use crate::starter_process::Mode;
    use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
    let ctrl = |code| KeyEvent::new(code, KeyModifiers::CONTROL);
    let (_d, mut app) = app();
    // Not on the setup page, where Ctrl-arrows belong to the field typed.
    app.on_key(ctrl(KeyCode::Down));
    assert_eq!(app.jog_motor, 1, "no jog key on the setup page");
    app.on_key(key(KeyCode::F(4)));
    for _ in 0..2 {
        app.on_key(ctrl(KeyCode::Down));
    }
    assert_eq!(app.status.0, "jog: motor 3 (Ctrl-← / Ctrl-→ move it ∓100 counts)");
    // Issue 30: past the motors, the effector's axes (the shipped settings describe a Delta).
    for _ in 0..5 {
        app.on_key(ctrl(KeyCode::Down));
    }
    assert_eq!(app.jog_motor, 6, "three motors in use, then x, y, z");
    assert_eq!(app.status.0, "jog: the effector along z (Ctrl-← / Ctrl-→ move it ∓5 mm)");
    app.on_key(ctrl(KeyCode::Right));
    assert!(app.status.0.starts_with("cannot start jog (qmarc-starter): "), "{:?}", app.status);
    assert_eq!(
        Mode::JogAxis { axis: 2, mm: 5.0 }.args(),
        ["jog", "--axis=z", "--mm=5"],
        "a Cartesian jog"
    );
    for _ in 0..4 {
        app.on_key(ctrl(KeyCode::Up));
    }
    assert_eq!(app.jog_motor, 2);
    app.on_key(ctrl(KeyCode::Left));
    // The test's starter is not on the PATH: the jog was tried, by name.
    assert!(app.status.0.starts_with("cannot start jog (qmarc-starter): "), "{:?}", app.status);
    assert_eq!(Mode::Jog { motor: 2, counts: -100 }.args(), ["jog", "--motor=2", "--counts=-100"]);
    assert_eq!(Mode::Run.args(), ["run", "--approach"], "the console's Run approaches the path");
}

/// Issue 30: Ctrl-G asks for a point and goes there through `move --xyz`; Esc cancels, a
/// malformed point is said and kept for correction; Ctrl-O closes the gripper where the robot
/// is (`move --grip on`), the next opens it once a close has succeeded.
#[test]
fn go_to_asks_for_a_point_and_the_gripper_key_grips() {
    use crate::starter_process::Mode;
    use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
    let ctrl = |code| KeyEvent::new(code, KeyModifiers::CONTROL);
    let (_d, mut app) = app();
    app.on_key(key(KeyCode::F(4)));
    app.on_key(ctrl(KeyCode::Char('g')));
    assert_eq!(app.prompt.as_deref(), Some(""));
    assert!(app.status.0.starts_with("go to X Y Z (mm)"));
    for c in "20 -10 -64q0".chars() {
        app.on_key(key(KeyCode::Char(c)));
    }
    assert_eq!(app.prompt.as_deref(), Some("20 -10 -640"), "only what a number holds");
    app.on_key(key(KeyCode::Backspace));
    assert_eq!(app.prompt.as_deref(), Some("20 -10 -64"));
    app.on_key(key(KeyCode::Esc));
    assert_eq!((app.prompt.as_deref(), app.status.0.as_str()), (None, "go to: cancelled"));
    app.on_key(ctrl(KeyCode::Char('g')));
    for c in "20 -10".chars() {
        app.on_key(key(KeyCode::Char(c)));
    }
    app.on_key(key(KeyCode::Enter));
    assert_eq!(app.status, ("go to X Y Z (mm): three numbers, found 2".into(), true));
    assert!(app.prompt.is_some(), "kept for correction");
    for c in " -640".chars() {
        app.on_key(key(KeyCode::Char(c)));
    }
    app.on_key(key(KeyCode::Enter));
    assert_eq!(app.prompt, None);
    assert!(app.status.0.starts_with("cannot start move (qmarc-starter): "), "{:?}", app.status);
    assert_eq!(Mode::GoTo { xyz: [20.0, -10.0, -640.0] }.args(), ["move", "--xyz=20,-10,-640"]);
    app.on_key(ctrl(KeyCode::Char('o')));
    assert!(app.status.0.starts_with("cannot start move (qmarc-starter): "), "{:?}", app.status);
    assert!(!app.grip_closed, "not closed: the move did not run");
    assert_eq!(Mode::Grip { close: true }.args(), ["move", "--grip=on"]);
    assert_eq!(Mode::Grip { close: false }.args(), ["move", "--grip=off"]);
}

/// An executable shell script `name` in `dir` with `body`: a stand-in for `qmarc-starter`.
fn script(dir: &std::path::Path, name: &str, body: &str) -> std::path::PathBuf {
    use std::os::unix::fs::PermissionsExt;
    let path = dir.join(name);
    std::fs::write(&path, format!("#!/bin/sh\n{body}\n")).unwrap();
    std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o755)).unwrap();
    path
}

/// The rows of the screen from the one holding `first` on, each up to a column's border, joined
/// without their margins: a wrapped text read back whole.
fn unwrapped(b: &Buffer, first: &str) -> String {
    let s = text(b);
    let rows: Vec<&str> = s.lines().collect();
    let at = rows.iter().position(|r| r.contains(first)).unwrap_or(rows.len());
    rows[at..]
        .iter()
        .map(|r| r.split('│').next().unwrap_or_default().trim())
        .collect::<Vec<_>>()
        .join(" ")
}

/// Issue 42, item 1: at 80 columns the message line wraps instead of being cut: a fault
/// message and the log page's keys are read whole.
#[test]
fn the_message_line_wraps_whole_at_80_columns() {
    use ratatui::crossterm::event::KeyCode;
    let (_d, mut app) = app();
    let fault = "FAULT limit_switch: motor 1 hit its top limit switch at cycle 12; all motors \
                 disabled (the host stalled 3 times in the second before: 41 periods went by \
                 without a cycle, the longest 12.3 ms) END";
    app.say(fault, true);
    app.page = Page::Results;
    let b = render(&app, 80, 24);
    assert!(unwrapped(&b, "FAULT limit_switch").contains(fault), "{}", text(&b));
    let (x, y) = find(&b, "END").unwrap();
    assert_eq!(b[(x, y)].fg, Color::Red, "an error in red on every row");
    // The keys bar stays the last row.
    assert!(text(&b).lines().last().unwrap().contains("F12 Cancel"), "{}", text(&b));
    // The log page's keys: longer than a row.
    app.on_key(key(KeyCode::F(3)));
    assert!(app.status.0.chars().count() > 80, "{:?}", app.status);
    let b = render(&app, 80, 24);
    assert!(unwrapped(&b, "↑↓ PgUp PgDn").contains(&app.status.0), "{}", text(&b));
    // However long, it never takes more than a quarter of the screen, its cut end marked.
    app.say("word ".repeat(400), false);
    let s = text(&render(&app, 80, 24));
    let rows = s.lines().filter(|l| l.starts_with(" word")).count();
    assert_eq!(rows, 6, "{s}");
    let last = s.lines().rfind(|l| l.starts_with(" word")).unwrap();
    assert!(last.trim_end().ends_with('…'), "{s}");
}

/// A move in progress for the tests: a stand-in starter that waits (stopped when dropped),
/// with live homing progress, the effector and the gripper.
fn homing_in_progress(app: &mut App, dir: &std::path::Path) {
    use crate::starter_process::{Mode, Running};
    let starter = script(dir, "waiting-starter", "exec sleep 30");
    let r = Running::start(&starter, &[], &app.form.path, Mode::Home, dir).unwrap();
    let mut live = crate::live::Live::new(qmarc_proto::service::IpcLocation::new(
        "qmarc_uitest_",
        &dir.display().to_string(),
    ));
    live.stage = Some("homing motor 2: approaching the top switch".into());
    live.effector_mm = Some([12.5, -3.25, -612.0]);
    live.gripper = qmarc_proto::Gripper(qmarc_proto::Gripper::CLOSE | qmarc_proto::Gripper::CLOSED);
    app.running = Some(r);
    app.live = Some(live);
}

/// Issue 42, item 1: homing's motor and stage, where the effector is and the gripper are shown
/// whole at 80×24 on every page (they were at the end of the title bar, cut at 80 columns).
#[test]
fn homing_progress_is_shown_whole_at_80x24_on_every_page() {
    let (d, mut app) = app();
    homing_in_progress(&mut app, &d.0);
    for page in [Page::Setup, Page::Log, Page::Results, Page::Charts, Page::History] {
        app.page = page;
        let b = render(&app, 80, 24);
        let s = text(&b);
        let whole = unwrapped(&b, "home running");
        for want in [
            "homing motor 2: approaching the top switch",
            "effector 12.5 -3.2 -612.0 mm",
            "gripper closed",
        ] {
            assert!(whole.contains(want), "{page:?}: {want:?} missing:\n{s}");
        }
        assert!(s.lines().last().unwrap().contains("F12 Cancel"), "{page:?}:\n{s}");
    }
    // The setup page keeps its actions whole: the move is in its left column.
    app.page = Page::Setup;
    let s = text(&render(&app, 80, 24));
    assert!(s.contains("Cancel (leave without saving)"), "{s}");
    app.running = None;
}

/// Issue 42, item 2: at rest the setup page says where the robot is (counts, and the effector
/// through `[robot]`), which motors are homed and the gripper, with where that comes from —
/// the simulated robot starts every move at `[sim] start_counts` — and its actions stay whole
/// at 80×24.
#[test]
fn at_rest_the_setup_page_shows_where_the_robot_is() {
    let (_d, app) = app();
    let b = render(&app, 80, 24);
    let s = text(&b);
    let whole = unwrapped(&b, "At rest:");
    for want in [
        "At rest: M1 0 M2 0 M3 0 counts",
        "effector 0.0 0.0 -600.0 mm",
        "homed M1 M2 M3",
        "gripper open",
        "every move starts at [sim] start_counts",
        "[sim] homed = true",
    ] {
        assert!(whole.replace("  ", " ").contains(want), "{want:?} missing:\n{s}");
    }
    assert!(s.contains("Cancel (leave without saving)"), "the actions whole:\n{s}");
    // What is not known is said so, not shown as a number.
    let mut app = app;
    app.rest = crate::rest::Rest::unknown("not known: the settings do not validate");
    let b = render(&app, 80, 24);
    let s = text(&b);
    assert!(
        unwrapped(&b, "At rest:").starts_with("At rest: not known: the settings do not validate"),
        "{s}"
    );
    assert!(!s.contains("M1 0"), "{s}");
}

/// A folder with the results of an earlier move (its starter's pid 1): a step's
/// `summary.json` and `gather.csv`.
fn earlier_results(out: &std::path::Path) {
    std::fs::create_dir_all(out).unwrap();
    let mut r = result(false);
    r.summary.starter_pid = 1;
    qmarc_report::output::amend_summary(out, &r.summary).unwrap();
    std::fs::write(
        out.join("gather.csv"),
        "cycle,time_s,cmd1,act1,dac1\n0,0,0,0,0\n1,0.0004,1000,3,8191\n2,0.0008,1000,20,500\n",
    )
    .unwrap();
}

/// Issue 42, item 3: a go-to the starter refuses before anything moves (exit 3, the output
/// folder left as it was) leaves F7 charting the gathered data that are there — an earlier
/// move's, said so — not "No gathered data yet."; F4 says the same of the results.
#[test]
fn after_a_refused_go_to_f7_charts_the_data_that_are_there() {
    use ratatui::crossterm::event::{KeyCode, KeyEvent, KeyModifiers};
    let (d, app0) = app();
    let out = app0.out_dir();
    earlier_results(&out);
    // The console opens on them.
    let mut app = App::new(app0.form, d.0.join("starter"), app0.workdir);
    app.iox_root = format!("{}/", d.0.display());
    assert!(app.last.is_some() && app.results_note.is_none());
    app.starter = script(
        &d.0,
        "refusing-starter",
        "echo 'qmarc-starter: error: --xyz: 2000.0, -10.0, -640.0 mm is unreachable' >&2; exit 3",
    );
    app.on_key(KeyEvent::new(KeyCode::Char('g'), KeyModifiers::CONTROL));
    for c in "2000 -10 -640".chars() {
        app.on_key(key(KeyCode::Char(c)));
    }
    app.on_key(key(KeyCode::Enter));
    assert!(app.running.is_some(), "{:?}", app.status);
    let start = std::time::Instant::now();
    while app.running.is_some() && start.elapsed() < std::time::Duration::from_secs(20) {
        app.poll();
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    assert!(
        app.status.0.starts_with("move ended (exit status: 3) without results"),
        "{:?}",
        app.status
    );
    assert!(app.log.iter().any(|l| l.contains("is unreachable")), "{:?}", app.log);
    app.on_key(key(KeyCode::F(7)));
    let b = render(&app, 80, 24);
    let s = text(&b);
    assert!(!s.contains("No gathered data yet"), "{s}");
    for want in ["command vs actual", "following error", "earlier move (step"] {
        assert!(s.contains(want), "{want:?} missing:\n{s}");
    }
    let note = unwrapped(&b, "The gathered data of an earlier move");
    assert!(note.contains("the last move (move) left none of its own (exit status: 3)"), "{s}");
    app.on_key(key(KeyCode::F(4)));
    let s = text(&render(&app, 80, 24));
    assert!(s.contains("Results of an earlier move") && s.contains("step: ok"), "{s}");
}

/// Issue 42, item 3: what F7 shows, decided: a move's data; an earlier move's when the last
/// left none, said so; and when there is nothing to chart, precisely why — a `gather.csv`
/// without its summary, a summary whose data cannot be read (the complete set kept in
/// `previous/` named), or no move yet.
#[test]
fn what_f7_shows_is_the_data_there_or_why_not() {
    use crate::results::ChartsView;
    let (_d, mut app) = app();
    let out = app.out_dir();
    let gather = out.join("gather.csv");
    assert!(
        matches!(app.charts_view(), ChartsView::Nothing(ref w)
            if *w == format!("No gathered data yet: no move has written {}.", gather.display())),
        "{:?}",
        app.charts_view()
    );
    app.last = Some(result(false));
    assert!(matches!(app.charts_view(), ChartsView::Gathered { note: None, .. }));
    app.results_note = Some("the last move (move) left none of its own (exit status: 3)".into());
    match app.charts_view() {
        ChartsView::Gathered { note: Some(n), .. } => assert!(
            n.starts_with("The gathered data of an earlier move (step)")
                && n.ends_with("left none of its own (exit status: 3)"),
            "{n}"
        ),
        other => panic!("{other:?}"),
    }
    // A gather.csv without a summary: the console opens on nothing, and says why.
    std::fs::create_dir_all(&out).unwrap();
    std::fs::write(&gather, "cycle,act1\n0,1\n").unwrap();
    let mut fresh = App::new(app.form.clone(), "qmarc-starter".into(), app.workdir.clone());
    assert!(fresh.last.is_none());
    match fresh.charts_view() {
        ChartsView::Nothing(w) => assert!(
            w.starts_with(&format!(
                "Nothing to chart: {} is there, but not a summary",
                gather.display()
            )),
            "{w}"
        ),
        other => panic!("{other:?}"),
    }
    // A summary whose data cannot be read: why, and where the last complete set is.
    let mut r = result(false);
    r.series = Err(format!("{}: No such file or directory (os error 2)", gather.display()));
    r.dir = out.clone();
    std::fs::create_dir_all(out.join("previous")).unwrap();
    std::fs::write(out.join("previous").join("gather.csv"), "cycle\n").unwrap();
    fresh.last = Some(r);
    fresh.results_note = None;
    match fresh.charts_view() {
        ChartsView::Nothing(w) => assert_eq!(
            w,
            format!(
                "No gathered data to chart for the step move: {}: No such file or directory (os \
                 error 2); the last complete set is in {}",
                gather.display(),
                out.join("previous").display()
            )
        ),
        other => panic!("{other:?}"),
    }
}
