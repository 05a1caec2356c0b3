//! A sent path's samples: through every knot at its time, from where the robot rests to the
//! path's end at rest; chosen velocities that never overshoot a turn; and every malformed or
//! impossible path refused, saying which point and why.

use super::*;
use crate::generator::SoftLimits;
use std::path::Path;

fn settings() -> Settings {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
    Settings::load(&path, &qmarc_config::Names::any()).unwrap()
}

fn knot(t_s: f64, pos: [f64; 3], vel: [f64; 3]) -> PathKnot {
    PathKnot { t_s, pos: [pos[0], pos[1], pos[2], 0.0], vel: [vel[0], vel[1], vel[2], 0.0] }
}

const START: [f64; MAX_MOTORS] = [100.0, -200.0, 300.0, 0.0];

/// The soft limits of `s`, the frame homed.
fn homed(s: &Settings) -> Option<SoftLimits> {
    crate::generator::ServeLimits::of(s, false).soft
}

fn refusal(r: Result<Vec<[f64; MAX_MOTORS]>, Refused>) -> (Refusal, String) {
    let refused = r.expect_err("refused");
    (refused.kind, refused.why)
}

#[test]
fn a_path_passes_every_knot_at_its_time_from_rest_to_rest() {
    let s = settings();
    let period = s.period_s();
    let knots = [
        knot(0.2, [1100.0, -700.0, 300.0], [4000.0, -2000.0, 0.0]),
        knot(0.4, [1500.0, -1200.0, 800.0], [0.0, 0.0, 0.0]),
    ];
    let q = path_queue(&PathRequest::new(&knots, true).unwrap(), &START, &s, homed(&s)).unwrap();
    assert_eq!(q.len(), (0.4 / period).round() as usize + 1);
    assert_eq!(q[0], START, "it starts where the robot rests");
    for k in &knots {
        let at = q[(k.t_s / period).round() as usize];
        for m in 0..3 {
            assert!((at[m] - k.pos[m]).abs() < 1e-6, "{at:?} at {} s", k.t_s);
        }
    }
    assert_eq!(q[q.len() - 1], knots[1].pos);
    // The velocity given at the first knot is the path's there (a backward difference).
    let i = (0.2 / period).round() as usize;
    let v = (q[i + 1][0] - q[i - 1][0]) / (2.0 * period);
    assert!((v - 4000.0).abs() < 5.0, "{v}");
    // The motors beyond the robot's stay where they are.
    assert!(q.iter().all(|c| c[3] == 0.0));
    // Many segments: each knot is passed in its own (not the one before, carried on).
    let zigzag: Vec<PathKnot> = (1..=7)
        .map(|i| {
            let up = if i % 2 == 0 { 400.0 } else { 0.0 };
            knot(0.1 * i as f64, [100.0 + up, -200.0 - up, 300.0 + up], [0.0; 3])
        })
        .collect();
    let q = path_queue(&PathRequest::new(&zigzag, false).unwrap(), &START, &s, homed(&s)).unwrap();
    for k in &zigzag {
        let at = q[(k.t_s / period).round() as usize];
        assert!((0..3).all(|m| (at[m] - k.pos[m]).abs() < 1e-6), "{at:?} at {} s", k.t_s);
    }
}

#[test]
fn chosen_velocities_never_overshoot_a_turn_and_end_at_rest() {
    let s = settings();
    // Up, further up, then back down: the middle knot turns motor 1.
    let knots = [
        knot(0.1, [400.0, -200.0, 300.0], [0.0; 3]),
        knot(0.2, [900.0, -200.0, 300.0], [0.0; 3]),
        knot(0.35, [200.0, -200.0, 300.0], [0.0; 3]),
    ];
    let q = path_queue(&PathRequest::new(&knots, false).unwrap(), &START, &s, homed(&s)).unwrap();
    let peak = q.iter().map(|c| c[0]).fold(f64::MIN, f64::max);
    assert!((peak - 900.0).abs() < 1e-9, "the turn is the highest point: {peak}");
    let low = q.iter().map(|c| c[0]).fold(f64::MAX, f64::min);
    assert!((low - 100.0).abs() < 1e-9, "nothing below the start: {low}");
    // Rising through the first knot: its velocity is the parabola's, not 0.
    let i = (0.1 / s.period_s()).round() as usize;
    assert!(q[i + 1][0] - q[i - 1][0] > 1.0, "moving through knot 1");
    let n = q.len();
    assert!((q[n - 1][0] - q[n - 2][0]).abs() < 0.1, "at rest at the end");
    assert_eq!(inner_velocity(2.0, 1.0, 4.0, 1.0), 3.0);
    assert_eq!(inner_velocity(2.0, 1.0, 4.0, 3.0), 2.5);
    assert_eq!(inner_velocity(2.0, 1.0, 0.0, 1.0), 0.0, "a stop after a rise is a turn too");
    assert_eq!(
        (inner_velocity(2.0, 1.0, -4.0, 1.0), inner_velocity(0.0, 1.0, 4.0, 1.0)),
        (0.0, 0.0)
    );
}

#[test]
fn a_point_at_time_zero_is_where_the_robot_rests() {
    let s = settings();
    let here = knot(0.0, [130.0, -200.0, 300.0], [0.0; 3]);
    let then = knot(0.2, [500.0, -200.0, 300.0], [0.0; 3]);
    let q =
        path_queue(&PathRequest::new(&[here, then], true).unwrap(), &START, &s, homed(&s)).unwrap();
    assert_eq!(q[0], START);
    let away = knot(0.0, [300.0, -200.0, 300.0], [0.0; 3]);
    let (r, why) =
        refusal(path_queue(&PathRequest::new(&[away, then], true).unwrap(), &START, &s, homed(&s)));
    assert_eq!(r, Refusal::BadRequest);
    assert!(why.contains("point 1: at time 0") && why.contains("motor 1"), "{why}");
    // Only that point: nothing to follow, the path is where the robot rests.
    let q = path_queue(&PathRequest::new(&[here], false).unwrap(), &START, &s, homed(&s)).unwrap();
    assert_eq!(q, vec![START]);
    // A refusal names the request's point, the one at time 0 counted.
    let fast = knot(0.3, [9100.0, -200.0, 300.0], [0.0; 3]);
    let r =
        path_queue(&PathRequest::new(&[here, then, fast], false).unwrap(), &START, &s, homed(&s));
    assert!(r.unwrap_err().why.starts_with("point 3: motor 1"), "the third point");
    let moving = knot(0.0, [100.0, -200.0, 300.0], [10.0, 0.0, 0.0]);
    assert!(
        path_queue(&PathRequest::new(&[moving, then], true).unwrap(), &START, &s, homed(&s))
            .is_err()
    );
}

#[test]
fn malformed_and_impossible_paths_are_refused_naming_the_point() {
    let s = settings();
    let ok = knot(0.2, [500.0, -200.0, 300.0], [0.0; 3]);
    let check = |knots: &[PathKnot], given: bool| {
        refusal(path_queue(&PathRequest::new(knots, given).unwrap(), &START, &s, homed(&s)))
    };
    let (r, why) = check(&[], false);
    assert_eq!(r, Refusal::BadRequest);
    assert!(why.contains("1 to 1024 points, found 0"), "{why}");
    // As many points as a request holds: taken.
    let full: Vec<PathKnot> = (1..=MAX_PATH_KNOTS)
        .map(|i| knot(i as f64 * 1e-3, [100.0, -200.0, 300.0], [0.0; 3]))
        .collect();
    check_ok(&s, &full, false);
    let lying = PathRequest { n_knots: MAX_PATH_KNOTS as u32 + 1, ..PathRequest::default() };
    assert!(path_queue(&lying, &START, &s, homed(&s)).unwrap_err().why.contains("found 1025"));
    let (_, why) = check(&[ok, knot(0.2, [600.0, -200.0, 300.0], [0.0; 3])], false);
    assert!(
        why.contains("point 2: time_from_start 0.2 s is not after the point before's"),
        "{why}"
    );
    let (_, why) = check(&[knot(f64::NAN, [0.0; 3], [0.0; 3])], false);
    assert!(why.contains("point 1: time_from_start must be ≥ 0 s, found NaN"), "{why}");
    let (_, why) = check(&[ok, knot(0.3, [f64::INFINITY, 0.0, 0.0], [0.0; 3])], false);
    assert!(why.contains("point 2: the numbers must be finite, found inf"), "{why}");
    let (_, why) = check(&[ok, knot(0.3, [0.0; 3], [0.0, f64::NAN, 0.0])], true);
    assert!(why.contains("point 2: the numbers must be finite"), "{why}");
    // Velocities not given are not looked at.
    check_ok(&s, &[ok, knot(0.4, [0.0; 3], [f64::NAN, 0.0, 0.0])], false);
    let (_, why) = check(&[knot(0.2, [500.0, -200.0, 300.0], [100.0, 0.0, 0.0])], true);
    assert!(
        why.contains("point 1: a path ends at rest") && why.contains("motor 1's is 100"),
        "{why}"
    );
    // 9000 counts in 0.1 s: 135 000 counts/s at the segment's middle, over motor 1's 80 000.
    let (_, why) = check(&[knot(0.1, [9100.0, -200.0, 300.0], [0.0; 3])], false);
    assert!(
        why.contains("point 1: motor 1: the path moves at")
            && why.contains("max_velocity_counts_per_s = 80000"),
        "{why}"
    );
    let (r, why) = check(
        &[
            knot(1.0, [100.0, -200.0, 9900.0], [0.0; 3]),
            knot(2.0, [100.0, -200.0, 10_300.0], [0.0; 3]),
        ],
        false,
    );
    assert_eq!(r, Refusal::SoftLimits, "{why}");
    assert!(
        why.contains("the path takes motor 3 to")
            && why.contains("outside its soft limits [-9000, 10000]"),
        "{why}"
    );
    // Unhomed (--unhomed), the soft limits do not hold.
    let q = path_queue(
        &PathRequest::new(&[knot(1.0, [100.0, -200.0, 10_300.0], [0.0; 3])], false).unwrap(),
        &START,
        &s,
        None,
    );
    assert!(q.is_ok());
    let mut short = s.clone();
    short.trajectory.max_duration_s = 0.1;
    let r = path_queue(&PathRequest::new(&[ok], false).unwrap(), &START, &short, homed(&short));
    assert!(r.unwrap_err().why.contains("the path lasts 0.2 s: longer than the longest path"));
    // A path exactly as long as the longest allowed: taken.
    short.trajectory.max_duration_s = 0.2;
    check_ok(&short, &[ok], false);
}

fn check_ok(s: &Settings, knots: &[PathKnot], given: bool) {
    let r = path_queue(&PathRequest::new(knots, given).unwrap(), &START, s, homed(s));
    assert!(r.is_ok(), "{r:?}");
}

/// Without velocities, each inner knot's is the parabola's through it and its neighbours:
/// (s₀h₁ + s₁h₀)/(h₀ + h₁) of the slopes s and lengths h of the segments either side — here
/// unequal, so each term counts — and the path moves at it through the knot.
#[test]
fn a_chosen_velocity_is_the_parabolas_through_the_knot() {
    let s = settings();
    let period = s.period_s();
    let knots = [
        knot(0.1, [400.0, -200.0, 300.0], [0.0; 3]),
        knot(0.3, [1400.0, -200.0, 300.0], [0.0; 3]),
        knot(0.4, [1600.0, -200.0, 300.0], [0.0; 3]),
        knot(0.6, [1600.0, -200.0, 300.0], [0.0; 3]),
    ];
    let q = path_queue(&PathRequest::new(&knots, false).unwrap(), &START, &s, homed(&s)).unwrap();
    // The velocity through a knot, from the samples either side (a knot joins two cubics
    // whose accelerations differ: the difference is off by a quarter period of that step).
    let through = |t: f64| {
        let i = (t / period).round() as usize;
        (q[i + 1][0] - q[i - 1][0]) / (2.0 * period)
    };
    // At 0.1 s: s₀ = 300 / 0.1 = 3000, s₁ = 1000 / 0.2 = 5000 counts/s.
    let expected = (3000.0 * 0.2 + 5000.0 * 0.1) / 0.3;
    assert!((through(0.1) - expected).abs() < 50.0, "{} ≠ {expected}", through(0.1));
    // At 0.3 s: s₀ = 5000 over 0.2 s, s₁ = 200 / 0.1 = 2000 over 0.1 s.
    let expected = (5000.0 * 0.1 + 2000.0 * 0.2) / 0.3;
    assert!((through(0.3) - expected).abs() < 50.0, "{} ≠ {expected}", through(0.3));
    // At 0.4 s the path stops (a turn): 0.
    assert!(through(0.4).abs() < 50.0, "{}", through(0.4));
    // A point at time 0 exactly the start tolerance away is still where the robot rests.
    let edge = knot(0.0, [200.0, -200.0, 300.0], [0.0; 3]);
    let tol = s.trajectory.start_tolerance_counts;
    assert_eq!(tol, 100.0, "the shipped tolerance this point sits on");
    let then = knot(0.2, [500.0, -200.0, 300.0], [0.0; 3]);
    assert!(
        path_queue(&PathRequest::new(&[edge, then], false).unwrap(), &START, &s, homed(&s)).is_ok()
    );
}

/// A path may take at most the queue's budget (256 MiB of samples, 3355 s at 2.5 kHz, here
/// 1000 samples) even where `trajectory.max_duration_s` allows more: one sample more is
/// refused, saying so.
#[test]
fn a_path_longer_than_the_queue_holds_is_refused() {
    let mut s = settings();
    s.trajectory.max_duration_s = 1e6;
    let per_sample = std::mem::size_of::<[f64; MAX_MOTORS]>() as u64;
    let budget = 1000 * per_sample;
    // 1000 samples: the start and 999 periods.
    let end = 999.0 * s.period_s();
    let rest = [START[0], START[1], START[2]];
    let queue = |t: f64| {
        let req = PathRequest::new(&[knot(t, rest, [0.0; 3])], false).unwrap();
        path_queue_within(&req, &START, &s, homed(&s), budget)
    };
    assert_eq!(queue(end).map(|q| q.len()), Ok(1000));
    let (_, why) = refusal(queue(end + s.period_s()));
    assert!(why.contains("1001 samples, more than the 0.0 MiB a path may take"), "{why}");
    // The real budget, in MiB.
    let (_, why) = refusal(path_queue(
        &PathRequest::new(&[knot(3400.0, rest, [0.0; 3])], false).unwrap(),
        &START,
        &s,
        homed(&s),
    ));
    assert!(why.contains("more than the 256.0 MiB a path may take"), "{why}");
}
