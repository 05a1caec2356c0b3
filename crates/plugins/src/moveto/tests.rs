//! Unit tests of the jerk-limited moves: their samples keep every limit, start and end at
//! rest where they should, all motors start and arrive together, and the slowest motor's move
//! takes the time-optimal duration of the closed-form double-S profile (computed apart from
//! Ruckig, which plans the move); the approach puts a path behind its way there.

use super::*;
use crate::motion::*;
use crate::spline::CubicSpline;
use proptest::prelude::*;

const T: f64 = 400e-6;

/// The shipped robot's limits at 4×.
fn limits() -> MotionLimits {
    MotionLimits {
        velocity: [80_000.0; MAX_MOTORS],
        acceleration: [5e6; MAX_MOTORS],
        jerk: [2e9; MAX_MOTORS],
    }
}

/// Per motor, the largest sampled |velocity|, |acceleration| and |jerk| (finite differences
/// from rest before the first sample and after the last).
fn sampled_extremes(q: &[[f64; MAX_MOTORS]], m: usize) -> (f64, f64, f64) {
    let mut p: Vec<f64> = vec![q[0][m]; 3];
    p.extend(q.iter().map(|c| c[m]));
    p.extend([q[q.len() - 1][m]; 3]);
    let d = |x: &[f64]| x.windows(2).map(|w| (w[1] - w[0]) / T).collect::<Vec<f64>>();
    let (v, a) = (d(&p), d(&d(&p)));
    let j = d(&a);
    let max = |x: &[f64]| x.iter().fold(0.0f64, |m, y| m.max(y.abs()));
    (max(&v), max(&a), max(&j))
}

proptest! {
    /// Random moves of three motors: every limit kept, exact ends, one duration for all, and
    /// that duration the slowest motor's time-optimal one within a period.
    #[test]
    fn a_move_keeps_every_limit_and_takes_the_slowest_motors_optimal_time(
        from in proptest::array::uniform3(-20_000.0f64..20_000.0),
        to in proptest::array::uniform3(-20_000.0f64..20_000.0),
        speed in 0.05f64..1.0,
    ) {
        let l = limits().at_speed(speed);
        let (mut f, mut t) = ([0.0; MAX_MOTORS], [0.0; MAX_MOTORS]);
        f[..3].copy_from_slice(&from);
        t[..3].copy_from_slice(&to);
        let q = rest_to_rest(&f, &t, 3, &l, T).unwrap();
        prop_assert_eq!(q[0], f);
        prop_assert_eq!(*q.last().unwrap(), t);
        for m in 0..3 {
            let (v, a, j) = sampled_extremes(&q, m);
            prop_assert!(v <= l.velocity[m] * (1.0 + 1e-6), "motor {m}: v {v}");
            prop_assert!(a <= l.acceleration[m] * (1.0 + 1e-6), "motor {m}: a {a}");
            // The last sample is put exactly on the target: at most a rounding's jump.
            prop_assert!(j <= l.jerk[m] * (1.0 + 1e-3) + 1e-6 / (T * T * T), "motor {m}: j {j}");
        }
        let slowest = (0..3)
            .map(|m| double_s_duration(t[m] - f[m], l.velocity[m], l.acceleration[m], l.jerk[m]))
            .fold(0.0, f64::max);
        let duration = (q.len() - 1) as f64 * T;
        prop_assert!((duration - slowest).abs() <= T * (1.0 + 1e-9), "{duration} vs {slowest}");
        // Time-synchronised: every motor that moves leaves at once and is still on its way a
        // tenth of the move before its end.
        let (first, late) = (q[1], q[q.len() - 1 - q.len() / 10]);
        for m in (0..3).filter(|&m| (t[m] - f[m]).abs() > 1.0 && q.len() >= 20) {
            let d = (t[m] - f[m]).abs();
            prop_assert!((first[m] - f[m]).abs() > 1e-12 * d, "motor {m} starts late");
            prop_assert!((late[m] - t[m]).abs() > 1e-6 * d, "motor {m} arrived early");
        }
    }
}

#[test]
fn no_distance_is_one_sample_and_unused_motors_hold() {
    let from = [1.0, 2.0, 3.0, 4.0];
    assert_eq!(rest_to_rest(&from, &from, 3, &limits(), T).unwrap(), vec![from]);
    let mut to = from;
    to[0] = 501.0;
    to[3] = 99.0; // beyond the motors in use: ignored
    let q = rest_to_rest(&from, &to, 3, &limits(), T).unwrap();
    assert!(q.iter().all(|c| c[1..] == from[1..]), "the others hold");
    assert_eq!(q.last().unwrap()[0], 501.0);
    let bad = MotionLimits { velocity: [f64::NAN; MAX_MOTORS], ..limits() };
    assert!(matches!(rest_to_rest(&from, &to, 3, &bad, T), Err(MoveToError::NoProfile { .. })));
}

/// The approach: the way from where the motors are to the path's first knot, then the path
/// sample for sample; the loop is told how many samples lead in.
#[test]
fn the_approach_puts_the_path_behind_its_way_there() {
    let knots = qmarc_knots::parse_offline(
        "k.txt",
        "3\n0.0 1000 -500\n0.5 1500 -500\n1.0 2000 -500\n",
        &qmarc_knots::KnotRules::new(2),
    )
    .unwrap();
    let path = CubicSpline::from_knots(&knots, T, 10.0).unwrap();
    let alone = path.queue().to_vec();
    let mut a = Approach::new(Box::new(path), 2, T, limits().at_speed(0.25));
    a.start(&[0.0; MAX_MOTORS]).unwrap();
    let lead = a.lead_in();
    assert!(lead > 10, "{lead}");
    assert_eq!(a.samples(), Some(lead + alone.len() as u64));
    let mut cmd = [0.0; MAX_MOTORS];
    assert_eq!(a.sample(0, &mut cmd), Sample::Ready);
    assert_eq!(cmd, [0.0; MAX_MOTORS]);
    for (k, want) in alone.iter().enumerate() {
        assert_eq!(a.sample(lead + k as u64, &mut cmd), Sample::Ready);
        assert_eq!(&cmd, want);
    }
    assert_eq!(a.sample(lead + alone.len() as u64, &mut cmd), Sample::Done);
    let b = a.path_bounds().unwrap();
    assert_eq!(b[0], (0.0, 2000.0));
    assert!(b[1].1 == 0.0 && (b[1].0 + 500.0).abs() < 1e-9, "{:?}", b[1]);
    // Already at the start: no way to go.
    let path = CubicSpline::from_knots(&knots, T, 10.0).unwrap();
    let mut a = Approach::new(Box::new(path), 2, T, limits());
    a.start(&[1000.0, -500.0, 0.0, 0.0]).unwrap();
    assert_eq!(a.lead_in(), 0);
}

/// A jog of motor 2 by `counts`, its top switch toward negative counts.
fn jog_of(counts: f64) -> Jog {
    Jog {
        motor: 1,
        counts,
        n_motors: 3,
        period_s: T,
        limits: limits(),
        speed: 0.1,
        unhomed_speed: 0.025,
        homed: false,
        queue: CommandQueue::default(),
        top_direction: [-1.0; MAX_MOTORS],
        resting: [MotorFlags::default(); MAX_MOTORS],
        observed: false,
        tripped: None,
    }
}

/// Jog: the motor moves its counts, the others hold; slower where its frame is not homed.
#[test]
fn jog_moves_one_motor_slower_where_unhomed() {
    let jog = |homed: bool| {
        let mut j = jog_of(-400.0);
        let flags = [MotorFlags(if homed { MotorFlags::HOMED } else { 0 }); MAX_MOTORS];
        j.observe(&[0.0; MAX_MOTORS], &flags);
        j.start(&[10.0, 20.0, 30.0, 0.0]).unwrap();
        j
    };
    let (homed, unhomed) = (jog(true), jog(false));
    for j in [&homed, &unhomed] {
        assert_eq!(*j.queue.commands().last().unwrap(), [10.0, -380.0, 30.0, 0.0]);
        assert!(j.queue.commands().iter().all(|c| c[0] == 10.0 && c[2] == 30.0));
        assert_eq!(j.end_velocity(), Some([0.0; MAX_MOTORS]));
    }
    assert!(unhomed.samples().unwrap() > 2 * homed.samples().unwrap());
}

/// Jog watches the switches: resting on one, it may leave it, not go further; a switch that
/// trips during the jog (or comes back after clearing) ends it as a limit switch fault.
#[test]
fn jog_leaves_a_switch_it_rests_on_and_stops_on_one_that_trips() {
    let on = |flags: i32| {
        let mut f = [MotorFlags::default(); MAX_MOTORS];
        f[1] = MotorFlags(flags);
        f
    };
    let start = [0.0, 10_600.0, 0.0, 0.0];
    // Resting on its bottom switch (positive counts: away from the top): not further down.
    let mut j = jog_of(500.0);
    j.observe(&start, &on(MotorFlags::BOTTOM));
    let e = j.start(&start).unwrap_err().to_string();
    assert_eq!(
        e,
        "motor 2 rests on its bottom limit switch: jog it away from the switch (--counts of the other sign)"
    );
    // Away from it: it runs, the switch clears, and coming back onto it ends the jog.
    let mut j = jog_of(-500.0);
    j.observe(&start, &on(MotorFlags::BOTTOM));
    j.start(&start).unwrap();
    let mut cmd = [0.0; MAX_MOTORS];
    j.observe(&start, &on(MotorFlags::BOTTOM));
    assert_eq!(j.sample(1, &mut cmd), Sample::Ready);
    j.observe(&start, &on(0));
    assert_eq!(j.sample(2, &mut cmd), Sample::Ready);
    j.observe(&start, &on(MotorFlags::BOTTOM));
    assert_eq!(j.sample(3, &mut cmd), Sample::Failed);
    assert_eq!(j.failure_kind(), FaultKind::LimitSwitch);
    assert_eq!(
        j.failure().unwrap(),
        "jog: motor 2's bottom limit switch tripped (it was not active when the jog began)"
    );
    // Another motor's switch tripping ends it too.
    let mut j = jog_of(-500.0);
    j.observe(&start, &on(0));
    j.start(&start).unwrap();
    let mut other = [MotorFlags::default(); MAX_MOTORS];
    other[2] = MotorFlags(MotorFlags::TOP);
    j.observe(&start, &other);
    assert_eq!(j.sample(1, &mut cmd), Sample::Failed);
    assert_eq!(
        j.failure().unwrap(),
        "jog: motor 3's top limit switch tripped (it was not active when the jog began)"
    );
}
