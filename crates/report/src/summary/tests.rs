//! The summary's figures and its reading.

use super::*;

/// Nearest rank: of 1‥100 ms the median is 50 ms, the 99th percentile 99 ms; none is 0.
#[test]
fn latencies_are_nearest_rank_percentiles_in_ms() {
    let ns: Vec<u64> = (1..=100).rev().map(|k| k * 1_000_000).collect();
    let l = Latencies::of_ns(&ns);
    assert_eq!((l.count, l.p50, l.p99, l.max), (100, 50.0, 99.0, 100.0));
    let one = Latencies::of_ns(&[2_500_000]);
    assert_eq!((one.p50, one.p99, one.max), (2.5, 2.5, 2.5));
    assert_eq!(Latencies::of_ns(&[]), Latencies { count: 0, p50: 0.0, p99: 0.0, max: 0.0 });
}
use qmarc_controller::stats::AxisErrors;

#[test]
fn figures_convert_to_radians() {
    let mut e = AxisErrors::default();
    for v in [2.0, -3.0, 1.0] {
        e.add(v);
    }
    let s = MotorSummary::new(&e, 2.0);
    assert_eq!(
        (s.min_error_rad, s.accumulated_abs_error_rad, s.sum_squares_error_rad2),
        (-1.5, 3.0, 3.5)
    );
}

#[test]
fn faults_report_their_kind_by_name() {
    let mut f = Fault::from_status(qmarc_proto::Status::limit_top(0), 1234).unwrap();
    f.disabled = true;
    let r = FaultReport::from(&f);
    assert_eq!((r.kind, r.motor, r.cycle), (FaultKind::LimitSwitch, Some(1), 1234));
    let json = serde_json::to_string(&r).unwrap();
    assert!(json.starts_with(r#"{"kind":"limit_switch","motor":1,"cycle":1234"#), "{json}");
    assert_eq!(serde_json::from_str::<FaultReport>(&json).unwrap(), r);
}

/// Issue 28, item 7: figures that are not numbers are written as null and read back as
/// NaN (before, such a summary could not be read, and the starter reported a controller
/// that exited 0 as lost); the move is not ok, and the warning names them.
#[test]
fn figures_that_are_not_numbers_read_back_and_make_the_move_not_ok() {
    let mut s = Summary::controller_lost((Mode::Step, true), 2, 400, 10, String::new());
    (s.fault, s.ok) = (None, true);
    let mut e = AxisErrors::default();
    e.add(1.0);
    s.motors = vec![MotorSummary::new(&e, 1.0); 2];
    s.motors[1].max_error_counts = f64::NAN;
    let mut eff = crate::effector::EffectorSummary::default();
    eff.z.min_mm = f64::INFINITY;
    s.effector = Some(eff);
    s.judge_figures();
    assert!(!s.ok);
    assert_eq!(
        s.warnings,
        ["figures that are not numbers (null in summary.json): motor 2's error, the \
          end-effector's z error; the move is not ok"]
    );
    let json = serde_json::to_string(&s).unwrap();
    assert!(json.contains(r#""max_error_counts":null"#), "{json}");
    let back: Summary = serde_json::from_str(&json).expect("readable");
    assert!(back.motors[1].max_error_counts.is_nan() && !back.ok);
    assert!(back.effector.unwrap().z.min_mm.is_nan());
    assert_eq!(back.figures_not_numbers().len(), 2);
    let mut fine = Summary { motors: vec![MotorSummary::new(&e, 1.0); 2], ..back };
    (fine.effector, fine.ok, fine.warnings) = (None, true, Vec::new());
    fine.judge_figures();
    assert!(fine.ok && fine.warnings.is_empty());
}

/// A warning keeps its kind through summary.json; an older summary's plain string still
/// reads, as an unsorted warning.
#[test]
fn warnings_keep_their_kind_and_old_plain_ones_still_read() {
    let w = Warning::new(WarningKind::EndsMoving, "the path ends moving");
    let json = serde_json::to_string(&w).unwrap();
    assert_eq!(json, r#"{"kind":"ends_moving","message":"the path ends moving"}"#);
    assert_eq!(serde_json::from_str::<Warning>(&json).unwrap(), w);
    let old: Warning = serde_json::from_str(r#""SCHED_FIFO 80 refused""#).unwrap();
    assert_eq!((old.kind, old.message.as_str()), (WarningKind::Unsorted, "SCHED_FIFO 80 refused"));
}
