//! The conformance suite on every registered backend: one test per check, each run on every
//! backend that has a rig at hand (the simulator always; a card when the environment names its
//! device). A backend added to the registry is checked here without a line of test code.

use qmarc_hwserver::backends::BACKENDS;
use qmarc_hwserver::conformance::CHECKS;

/// Runs the check `name` on every backend with a rig; panics with every failure.
fn check(name: &str) {
    let check = CHECKS.iter().find(|c| c.name == name).expect("a check of that name");
    let mut failures = Vec::new();
    let mut ran = 0;
    for entry in BACKENDS {
        let Some(mut rig) = (entry.rig)() else {
            eprintln!("{}: no rig at hand (no device named): `{name}` not run", entry.kind);
            continue;
        };
        ran += 1;
        if let Err(e) = (check.run)(rig.as_mut()) {
            failures.push(format!("{}: {e}", entry.kind));
        }
    }
    assert!(ran > 0, "no backend could be checked");
    assert!(failures.is_empty(), "{name}: {failures:#?}");
}

#[test]
fn every_check_has_a_test() {
    let listed = [
        "enable_and_disable",
        "dacs_zero_on_every_exit_path",
        "limit_switch_within_one_read",
        "counter_wraps_at_24_bits",
        "watchdog_makes_safe_and_refuses",
        "homing_preset",
        "estop_disables_at_once_and_latches",
    ];
    let names: Vec<&str> = CHECKS.iter().map(|c| c.name).collect();
    assert_eq!(names, listed, "a check without its test below");
}

#[test]
fn enable_and_disable() {
    check("enable_and_disable");
}

#[test]
fn dacs_zero_on_every_exit_path() {
    check("dacs_zero_on_every_exit_path");
}

#[test]
fn limit_switch_within_one_read() {
    check("limit_switch_within_one_read");
}

#[test]
fn counter_wraps_at_24_bits() {
    check("counter_wraps_at_24_bits");
}

#[test]
fn watchdog_makes_safe_and_refuses() {
    check("watchdog_makes_safe_and_refuses");
}

#[test]
fn homing_preset() {
    check("homing_preset");
}

#[test]
fn estop_disables_at_once_and_latches() {
    check("estop_disables_at_once_and_latches");
}
