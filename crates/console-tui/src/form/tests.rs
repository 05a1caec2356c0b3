//! Unit tests of `form`.

use super::*;

fn shipped() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml"))
        .unwrap()
}

fn form_of(text: &str) -> (tempdir::Dir, Form) {
    let dir = tempdir::Dir::new();
    let path = dir.0.join("qmarc.toml");
    std::fs::write(&path, text).unwrap();
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let form = Form::load_in(&path, &repo).unwrap();
    (dir, form)
}

mod tempdir {
    /// A scratch directory removed on drop.
    pub struct Dir(pub std::path::PathBuf);
    impl Dir {
        pub fn new() -> Dir {
            static N: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
            let n = N.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            let d = std::env::temp_dir().join(format!("qmarc-form-{}-{n}", std::process::id()));
            std::fs::create_dir_all(&d).unwrap();
            Dir(d)
        }
    }
    impl Drop for Dir {
        fn drop(&mut self) {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

#[test]
fn the_shipped_file_loads_checks_and_round_trips_unchanged() {
    let (_d, form) = form_of(&shipped());
    assert!(form.checked.is_some(), "{:?}", form.fields.iter().find(|f| f.error.is_some()));
    assert_eq!(form.motor_tables, 4);
    assert_eq!(form.text(), shipped(), "writing the fields back changes nothing");
    assert!(!form.dirty());
    let kp2 = form.index(Place::Motor(1, "kp")).unwrap();
    assert_eq!(form.fields[kp2].text, "182000");
}

#[test]
fn an_invalid_value_is_marked_on_its_field_with_the_checkers_message() {
    let (_d, mut form) = form_of(&shipped());
    let period = form.index(Place::Key("general", "period_us")).unwrap();
    form.set_text(period, "50");
    assert_eq!(
        form.fields[period].error.as_deref(),
        Some("servo period must be 100‥100000 µs, found 50")
    );
    let kd3 = form.index(Place::Motor(2, "kd")).unwrap();
    form.set_text(kd3, "fast");
    assert_eq!(
        form.fields[kd3].error.as_deref(),
        Some("invalid type: string \"fast\", expected f64")
    );
    // Both are found, not just the first.
    assert!(form.fields[period].error.is_some());
    let (i, msg) = form.blocking(Action::Step).unwrap();
    assert_eq!(i, Some(period));
    assert!(msg.starts_with("general.period_us Period µs: servo period"), "{msg}");
    form.set_text(period, "500");
    form.set_text(kd3, "2500");
    assert!(form.blocking(Action::Save).is_none());
    assert!(form.checked.is_some());
}

#[test]
fn a_bad_knot_file_is_shown_on_the_knots_field_and_blocks_only_run() {
    let (d, mut form) = form_of(&shipped());
    let bad = d.0.join("bad.txt");
    std::fs::write(&bad, "2\n0 0 0 0\n1 5 5\n").unwrap();
    let knots = form.index(Place::Key("trajectory", "knots")).unwrap();
    form.set_text(knots, bad.to_str().unwrap());
    let e = form.fields[knots].error.clone().unwrap();
    assert!(
        e.ends_with("bad.txt:3:6: expected 4 columns (time and 3 motor positions), found 3"),
        "{e}"
    );
    assert!(form.blocking(Action::Run).is_some());
    assert!(form.blocking(Action::Step).is_none() && form.blocking(Action::Home).is_none());
    // The starter accepts such settings for step and home: they can be saved.
    assert!(form.blocking(Action::Save).is_none() && form.checked.is_some());
    // Standard input cannot feed a console's run; a directory is no knot file.
    form.set_text(knots, "-");
    assert!(form.fields[knots].error.as_deref().unwrap().contains("give a file or a FIFO"));
    form.set_text(knots, d.0.to_str().unwrap());
    let e = form.fields[knots].error.clone().unwrap();
    assert!(e.ends_with("cannot read the knot file: it is a directory"), "{e}");
}

#[test]
fn motor_columns_beyond_the_number_of_motors_are_disabled() {
    let (_d, mut form) = form_of(&shipped());
    let kp4 = form.index(Place::Motor(3, "kp")).unwrap();
    assert!(!form.enabled(kp4));
    form.set_text(0, "4");
    assert!(form.enabled(kp4));
    form.set_text(0, "2");
    let kp3 = form.index(Place::Motor(2, "kp")).unwrap();
    assert!(!form.enabled(kp3));
}

#[test]
fn saving_writes_the_edit_and_keeps_the_comments() {
    let (_d, mut form) = form_of(&shipped());
    let kvff1 = form.index(Place::Motor(0, "kvff")).unwrap();
    form.set_text(kvff1, "120500");
    let n2 = form.index(Place::Notch(1, 1)).unwrap();
    form.set_text(n2, "0.25");
    assert!(form.dirty());
    form.save().unwrap();
    let text = std::fs::read_to_string(&form.path).unwrap();
    assert!(text.contains("kvff = 120500.0"), "{text}");
    assert!(text.contains("notch = [0.0, 0.25, 0.0, 0.0]"), "{text}");
    assert!(text.contains("# Per motor: gains (thesis Table 5-1;"), "comments kept");
    assert_eq!(text.lines().count(), shipped().lines().count());
    let again = Form::load_in(&form.path, &form.base).unwrap();
    assert_eq!(again.fields[kvff1].text, "120500");
}

#[test]
fn the_period_must_leave_room_for_what_the_last_move_needed() {
    let (_d, mut form) = form_of(&shipped());
    form.last_cycle_work_us = Some(450.0);
    form.validate();
    let period = form.index(Place::Key("general", "period_us")).unwrap();
    assert_eq!(
        form.fields[period].error.as_deref(),
        Some(
            "a cycle of the last move needed 450 µs of work (two hwserver exchanges and the law, medians): a 400 µs period would overrun every cycle on this machine"
        )
    );
    // It stops moves, not saving (the settings may be for another machine).
    assert!(form.blocking(Action::Step).is_some() && form.blocking(Action::Home).is_some());
    assert!(form.blocking(Action::Save).is_none());
    form.set_text(period, "600");
    assert!(form.fields[period].error.is_none());
}

/// Issue 28, item 9: a file with `kp = 1e308` opens as it is — shown as `1e308`, not 309
/// digits, and not `[modified]` — and an edit back to the same value changes nothing.
#[test]
fn a_huge_value_shows_short_and_opens_unmodified() {
    let text = shipped().replacen("kp = 182000.0", "kp = 1e308", 1);
    let (_d, mut form) = form_of(&text);
    let kp1 = form.index(Place::Motor(0, "kp")).unwrap();
    assert_eq!(form.fields[kp1].text, "1e308");
    assert!(!form.dirty(), "marked modified as it opened");
    assert_eq!(form.text(), text);
    form.fields[kp1].text = "1.0e308".into();
    assert!(!form.dirty(), "the same value, spelt otherwise");
    form.fields[kp1].text = "2e5".into();
    assert!(form.dirty());
    assert!(form.text().contains("kp = 200000.0"), "an edit is written");
}
