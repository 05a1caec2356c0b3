//! The tuner's constraints and its in-process moves, on the shipped settings and the X-Z path.

use qmarc_config::{Mode, MotorGains, Names, RunSpec, Settings};
use qmarc_tune::eval::{Evaluator, Objective, Param, SimEvaluator};
use qmarc_tune::optimise::{Plan, Verdict, judge};
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;

fn workspace() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// The shipped settings on the X-Z path, the simulated robot at its start.
fn xz_spec() -> RunSpec {
    let names = Names { laws: vec!["pidff"], methods: vec!["spline", "pvt"], any_plugin: false };
    let mut s = Settings::load(&workspace().join("config/qmarc.toml"), &names).unwrap();
    s.set_knots(&workspace().join("knots/xz-pick-place-spline.txt"));
    let s = qmarc_tune::local::on_the_path(&s).unwrap();
    qmarc_tune::local::local_spec(s, Mode::Run)
}

fn all_params() -> Vec<Param> {
    qmarc_config::TUNE_PARAMS.iter().filter_map(|p| Param::named(p)).collect()
}

/// The constraints: the thesis' gains are feasible; a gain set that drives the DAC into its
/// limit is refused for saturating; one that rings is refused by the stability step; one
/// outside the bounds is not even run.
#[test]
fn the_constraints_refuse_saturating_ringing_and_out_of_bounds_gains() {
    let spec = xz_spec();
    let stop = AtomicBool::new(false);
    let mut eval = SimEvaluator::new(&spec, &stop);
    let s = &spec.settings;
    let params = all_params();
    let plan = Plan {
        tune: &s.tune,
        params: &params,
        objective: Objective::Abs,
        budget: 1,
        law: (s.fe_scale, (s.gains_period_us, s.period_us)),
    };
    let best = &s.motors[..3];
    let verdict =
        |eval: &mut SimEvaluator<'_>, g: MotorGains| judge(&plan, best, 0, &g, eval).unwrap().1;
    assert_eq!(verdict(&mut eval, best[0]), Verdict::Feasible { best: true });
    let moves = eval.moves();
    let saturating = MotorGains { kp: best[0].kp * 2.0, ..best[0] };
    assert!(matches!(verdict(&mut eval, saturating), Verdict::Saturates(f) if f > 0.01));
    // Without Kd and with 40 % more Kp the loop rings: the step does not settle.
    let ringing = MotorGains { kd: 0.0, kp: best[0].kp * 1.4, ..best[0] };
    let v = verdict(&mut eval, ringing);
    assert!(matches!(v, Verdict::Unsettled { margin: false, .. }), "{v:?}");
    // With 20 % more Kp and 30× Ki it settles, but not with the margin's 25 % more.
    let marginal = MotorGains { kd: 0.0, kp: best[0].kp * 1.2, ki: best[0].ki * 30.0, ..best[0] };
    let v = verdict(&mut eval, marginal);
    assert!(matches!(v, Verdict::Unsettled { margin: true, .. }), "{v:?}");
    let outside = MotorGains { kp: s.tune.bounds[0][1] * 2.0, ..best[0] };
    let before = eval.moves();
    assert_eq!(verdict(&mut eval, outside), Verdict::OutOfBounds);
    // Within the bounds, but a gain the settings would refuse (eq. 3-1: one count per period
    // of commanded acceleration asking more than full scale): not run either (issue 27).
    let insane = MotorGains { kp: s.tune.bounds[0][1], kaff: s.tune.bounds[4][1], ..best[0] };
    assert!(qmarc_config::effective_gains_problem(&insane, s.fe_scale, (400, 400)).is_some());
    assert_eq!(verdict(&mut eval, insane), Verdict::OutOfBounds);
    assert_eq!(eval.moves(), before, "not run");
    assert!(before > moves);
}

/// An in-process move is deterministic: the same gains give the same figures, bit for bit.
#[test]
fn in_process_moves_repeat_bit_for_bit() {
    let spec = xz_spec();
    let stop = AtomicBool::new(false);
    let mut eval = SimEvaluator::new(&spec, &stop);
    let gains = &spec.settings.motors[..3];
    let (a, b) = (eval.path(gains).unwrap(), eval.path(gains).unwrap());
    assert_eq!(a, b);
    assert!(a.fault.is_none() && a.motors.iter().all(|m| m.abs_rad > 0.1));
}

/// Issue 28, item 8: a step a fault cut short a few cycles in gave the motors no time to
/// follow: its fault says what happened, and only the motor it names is judged — never every
/// motor "DID NOT FOLLOW … a seized joint?".
#[test]
fn a_move_cut_short_is_not_judged_for_following() {
    let mut s = xz_spec().settings;
    s.step.duration_s = 0.5;
    for m in &mut s.safety {
        m.max_integrated_error_counts = 12_000.0; // Σ FE of a 1000-count step: ~13 cycles
    }
    let spec = qmarc_tune::local::local_spec(s, Mode::Step);
    let done = qmarc_tune::local::run_local(&spec, &AtomicBool::new(false)).unwrap();
    let summary = done.summary;
    assert_eq!(summary.fault.as_ref().map(|f| f.kind.name()), Some("following_error"));
    assert!((5..50).contains(&summary.cycles), "{}", summary.cycles);
    // The motors the fault does not name had no time to follow, and are not judged.
    let faulted = summary.fault.as_ref().and_then(|f| f.motor).expect("a motor") - 1;
    for (m, motor) in summary.motors.iter().enumerate().filter(|(m, _)| *m != faulted) {
        assert!(motor.followed, "motor {}: {:?}", m + 1, summary.warnings);
    }
    let said = summary.warnings.iter().filter(|w| w.contains("did not follow"));
    assert!(said.count() <= 1, "{:?}", summary.warnings);
    // The same step run to its end, on a seized motor, is still judged.
    let mut s = xz_spec().settings;
    s.step.duration_s = 0.5;
    s.sim.plant.stall_motor = Some(2);
    for m in &mut s.safety {
        m.max_integrated_error_counts = 1e9; // the seized motor runs the step to its end
    }
    let spec = qmarc_tune::local::local_spec(s, Mode::Step);
    let done = qmarc_tune::local::run_local(&spec, &AtomicBool::new(false)).unwrap();
    assert!(done.summary.fault.is_none(), "{:?}", done.summary.fault);
    assert!(!done.summary.motors[1].followed);
}
