//! The online planner and the `move` generator: the closed-form double-S time, limits,
//! time synchronisation and mid-motion retargeting as properties.

use super::*;
use crate::motion::*;
use proptest::prelude::*;

const T: f64 = 400e-6;

/// The shipped robot's limits (config/qmarc.toml), per motor.
fn limits() -> MotionLimits {
    MotionLimits {
        velocity: [80_000.0; MAX_MOTORS],
        acceleration: [5.0e6; MAX_MOTORS],
        jerk: [2.0e9; MAX_MOTORS],
    }
}

/// How far above 1 [`sampled_ratio`] may read from rounding alone: its jerk is a third
/// difference of positions of up to 10⁴ counts over T³, which carries about 8·ε·10⁴/T³ ≈
/// 3·10⁻¹¹ counts/s³ per count/s³ of a slow limit (2.5·10⁵ at speed 0.05) — under 10⁻⁶ in
/// the cube root.
const ROUNDING: f64 = 1e-6;

fn arr(v: &[f64]) -> [f64; MAX_MOTORS] {
    let mut a = [0.0; MAX_MOTORS];
    a[..v.len()].copy_from_slice(v);
    a
}

/// Every sample of `g` until it is done, from sample `from`.
fn run(g: &mut OnlineMove, from: u64, queue: &mut Vec<[f64; MAX_MOTORS]>) {
    let mut cmd = [0.0; MAX_MOTORS];
    let mut n = from;
    while g.sample(n, &mut cmd) == Sample::Ready {
        queue.push(cmd);
        n += 1;
        assert!(n < 1_000_000, "the move does not end");
    }
}

fn moved(
    start: &[f64],
    target: &[f64],
    lim: &MotionLimits,
) -> (OnlineMove, Vec<[f64; MAX_MOTORS]>) {
    let mut g = OnlineMove::new(arr(target), 3, T, *lim);
    g.start(&arr(start)).unwrap();
    let mut q = Vec::new();
    run(&mut g, 0, &mut q);
    (g, q)
}

/// The index of the last sample at which motor `m` moved.
fn last_moving(q: &[[f64; MAX_MOTORS]], m: usize) -> usize {
    (1..q.len()).rev().find(|&i| q[i][m] != q[i - 1][m]).unwrap_or(0)
}

#[test]
fn a_one_motor_move_lasts_the_closed_form_double_s_time() {
    // The double-S rest-to-rest time (Biagiotti & Melchiorri 3.4), independent of Ruckig, in
    // each of its regimes: cruising, turning back before the velocity, and before the
    // acceleration.
    let lim = limits();
    for d in [1.0, 37.0, 500.0, 4_000.0, 20_000.0, -9_000.0] {
        let mut p = Profile::new(1, [0.0; MAX_MOTORS]);
        p.plan(&MotionState::default(), &arr(&[d]), &lim).unwrap();
        let want = double_s_duration(d, 80_000.0, 5.0e6, 2.0e9);
        assert!((p.duration() - want).abs() < 1e-9 * want.max(1.0), "{d}: {}", p.duration());
    }
}

#[test]
fn the_move_starts_where_the_motors_are_and_ends_exactly_on_the_target() {
    let (g, q) = moved(&[10.0, -20.0, 30.0], &[1000.0, -500.0, 250.0], &limits());
    assert_eq!(q[0][..3], [10.0, -20.0, 30.0]);
    assert_eq!(q.last().unwrap()[..3], [1000.0, -500.0, 250.0]);
    assert_eq!(g.samples(), Some(q.len() as u64));
    let expected = (g.duration() / T).ceil() as usize + 1;
    assert_eq!(q.len(), expected);
}

#[test]
fn a_move_of_no_distance_is_one_sample_at_rest() {
    let (g, q) = moved(&[5.0, 6.0, 7.0], &[5.0, 6.0, 7.0], &limits());
    assert_eq!(q, vec![arr(&[5.0, 6.0, 7.0])]);
    assert_eq!(g.duration(), 0.0);
}

#[test]
fn the_bounds_cover_every_sample_and_no_more() {
    let mut g = OnlineMove::new(arr(&[3000.0, -3000.0, 100.0]), 3, T, limits());
    g.start(&arr(&[0.0, 0.0, 0.0])).unwrap();
    let b = g.path_bounds().unwrap();
    let mut q = Vec::new();
    run(&mut g, 0, &mut q);
    let seen = qmarc_controller::traj::bounds_of(&q);
    for m in 0..3 {
        assert!((b[m].0 - seen[m].0).abs() < 1e-6 && (b[m].1 - seen[m].1).abs() < 1e-6);
    }
}

#[test]
fn the_speed_is_a_time_scaling() {
    // Half speed: the same move in twice the time.
    let lim = limits();
    let (full, _) = moved(&[0.0; 3], &[4000.0, 1000.0, -2000.0], &lim);
    let (half, _) = moved(&[0.0; 3], &[4000.0, 1000.0, -2000.0], &lim.at_speed(0.5));
    assert!((half.duration() - 2.0 * full.duration()).abs() < 1e-9);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    /// Rest to rest: the sampled command's velocity, acceleration and jerk never above the
    /// limits; every motor that moves starts at the first sample and stops with the last
    /// (time-synchronised); the slowest motor as fast as the closed form allows.
    #[test]
    fn rest_to_rest_keeps_the_limits_and_is_time_synchronised(
        start in prop::array::uniform3(-8000.0..8000.0f64),
        target in prop::array::uniform3(-8000.0..8000.0f64),
        speed in 0.05..=1.0f64,
    ) {
        let lim = limits().at_speed(speed);
        let (g, q) = moved(&start, &target, &lim);
        prop_assert!(sampled_ratio(&q, 3, T, &lim) <= 1.0 + ROUNDING);
        let slowest = (0..3)
            .map(|m| double_s_duration(target[m] - start[m], lim.velocity[m], lim.acceleration[m], lim.jerk[m]))
            .fold(0.0, f64::max);
        prop_assert!((g.duration() - slowest).abs() < 1e-7 * slowest.max(1.0));
        let ends: Vec<usize> = (0..3)
            .filter(|&m| (target[m] - start[m]).abs() > 1.0)
            .map(|m| last_moving(&q, m))
            .collect();
        let (lo, hi) = (ends.iter().min(), ends.iter().max());
        prop_assert!(hi.zip(lo).is_none_or(|(h, l)| h - l <= 1), "motors stop at samples {ends:?}");
        for m in 0..3 {
            if (target[m] - start[m]).abs() > 1.0 {
                prop_assert!(q[1][m] != q[0][m], "motor {} does not start with the others", m + 1);
            }
        }
    }

    /// A new target mid-motion: the command goes on from the state it was in, with no jump in
    /// position, velocity or acceleration (its sampled jerk stays within the limit across
    /// the switch), and ends exactly on the new target.
    #[test]
    fn a_new_target_mid_motion_takes_over_without_a_jump(
        target in prop::array::uniform3(-8000.0..8000.0f64),
        second in prop::array::uniform3(-8000.0..8000.0f64),
        at in 1u64..200,
    ) {
        let lim = limits();
        let mut g = OnlineMove::new(arr(&target), 3, T, lim);
        g.start(&[0.0; MAX_MOTORS]).unwrap();
        let mut q = Vec::new();
        let mut cmd = [0.0; MAX_MOTORS];
        for n in 0..at {
            if g.sample(n, &mut cmd) == Sample::Ready {
                q.push(cmd);
            }
        }
        let before = q.len() as u64;
        g.retarget(&arr(&second), &lim).unwrap();
        run(&mut g, before, &mut q);
        prop_assert!(sampled_ratio(&q, 3, T, &lim) <= 1.0 + ROUNDING);
        prop_assert_eq!(q.last().unwrap()[..3].to_vec(), second.to_vec());
        prop_assert!(q[before as usize] != q[before as usize - 1] || second == target);
    }
}

#[test]
fn a_new_target_changes_the_very_next_sample() {
    // Moving toward +4000, a target behind the motors: the next sample already brakes.
    let lim = limits();
    let mut g = OnlineMove::new(arr(&[4000.0, 4000.0, 4000.0]), 3, T, lim);
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    let mut cmd = [0.0; MAX_MOTORS];
    for n in 0..30 {
        g.sample(n, &mut cmd);
    }
    let mut old = OnlineMove::new(arr(&[4000.0, 4000.0, 4000.0]), 3, T, lim);
    old.start(&[0.0; MAX_MOTORS]).unwrap();
    let mut old_cmd = [0.0; MAX_MOTORS];
    old.sample(30, &mut old_cmd);
    g.retarget(&arr(&[0.0, 0.0, 0.0]), &lim).unwrap();
    g.sample(30, &mut cmd);
    assert!(cmd[0] < old_cmd[0], "sample 30 is still the old profile's: {} {}", cmd[0], old_cmd[0]);
}

#[test]
fn a_stalled_cycle_samples_the_profile_on_the_wall_clock() {
    // Samples 10‥14 skipped (a host stall): sample 15 is where the profile is at 15·T.
    let (_, q) = moved(&[0.0; 3], &[2000.0, 0.0, 0.0], &limits());
    let mut g = OnlineMove::new(arr(&[2000.0, 0.0, 0.0]), 3, T, limits());
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    let mut cmd = [0.0; MAX_MOTORS];
    for n in (0..10).chain(15..16) {
        g.sample(n, &mut cmd);
    }
    assert_eq!(cmd, q[15]);
}

#[test]
fn unusable_limits_or_states_plan_nothing() {
    let mut p = Profile::new(3, [0.0; MAX_MOTORS]);
    let mut bad = limits();
    bad.jerk[1] = 0.0;
    assert_eq!(p.plan(&MotionState::default(), &arr(&[1.0, 1.0, 1.0]), &bad), Err(NoProfile));
    let nan = MotionState { v: arr(&[f64::NAN]), ..MotionState::default() };
    assert_eq!(p.plan(&nan, &arr(&[1.0, 1.0, 1.0]), &limits()), Err(NoProfile));
    assert_eq!(p.plan(&MotionState::default(), &arr(&[f64::INFINITY]), &limits()), Err(NoProfile));
}

#[test]
fn a_state_with_only_an_acceleration_is_not_at_rest() {
    // On its target, not moving, but accelerating: the profile must take the acceleration
    // away (jerk-limited), not jump to rest.
    let lim = limits();
    let from = MotionState { a: arr(&[2.0e6, 0.0, -1.0e6]), ..MotionState::default() };
    for stop in [false, true] {
        let mut p = Profile::new(3, [0.0; MAX_MOTORS]);
        if stop {
            p.plan_stop(&from, &lim).unwrap();
        } else {
            p.plan(&from, &[0.0; MAX_MOTORS], &lim).unwrap();
        }
        assert!(p.duration() >= 2.0e6 / 2.0e9, "stop {stop}: {} s", p.duration());
        let s = p.state_at(0.0);
        assert!((s.a[0] - 2.0e6).abs() < 1.0 && (s.a[2] + 1.0e6).abs() < 1.0, "{s:?}");
    }
}

#[test]
fn a_stop_from_full_speed_comes_to_rest_within_the_limits() {
    let lim = limits();
    let from = MotionState {
        p: arr(&[0.0, 100.0, 0.0]),
        v: arr(&[80_000.0, -40_000.0, 0.0]),
        a: arr(&[0.0, 1.0e6, 0.0]),
    };
    let mut p = Profile::new(3, [0.0; MAX_MOTORS]);
    p.plan_stop(&from, &lim).unwrap();
    // From 80 000 counts/s at 5·10⁶ counts/s² and 2·10⁹ counts/s³: 16 ms plus the jerk's
    // 2.5 ms, the motors stopping together.
    assert!((p.duration() - 0.0185).abs() < 1e-4, "{} s", p.duration());
    let mut q = vec![from.p];
    let mut k = 1;
    while (k as f64) * T < p.duration() + T {
        q.push(p.state_at(k as f64 * T).p);
        k += 1;
    }
    // The first samples continue the motion (no jump); the last is at rest, where it stops.
    assert!((q[1][0] - 80_000.0 * T).abs() < 1.0, "{:?}", q[1]);
    assert_eq!(*q.last().unwrap(), *p.target());
    assert!(p.target()[0] > 600.0 && p.target()[1] < 100.0, "{:?}", p.target());
    let end = p.state_at(p.duration());
    assert_eq!((end.v, end.a), ([0.0; MAX_MOTORS], [0.0; MAX_MOTORS]));
}

#[test]
fn a_plan_refused_keeps_the_last_one() {
    let mut p = Profile::new(3, [0.0; MAX_MOTORS]);
    p.plan(&MotionState::default(), &arr(&[5000.0, -100.0, 20.0]), &limits()).unwrap();
    let (before, d) = (p.state_at(0.01), p.duration());
    let nan = MotionState { a: arr(&[0.0, f64::NAN]), ..MotionState::default() };
    assert_eq!(p.plan(&nan, &arr(&[1.0, 1.0, 1.0]), &limits()), Err(NoProfile));
    assert_eq!((p.state_at(0.01), p.duration()), (before, d));
}

#[test]
fn the_bounds_cover_an_overshoot_from_a_moving_state() {
    // Moving up at full speed toward a target below: the motor overshoots before it turns.
    let mut p = Profile::new(3, [0.0; MAX_MOTORS]);
    let from =
        MotionState { p: arr(&[500.0, 0.0, 0.0]), v: arr(&[80_000.0]), ..Default::default() };
    p.plan(&from, &arr(&[-1000.0, 0.0, 0.0]), &limits()).unwrap();
    let b = p.bounds();
    let mut seen = (f64::INFINITY, f64::NEG_INFINITY);
    let mut t = 0.0;
    while t <= p.duration() {
        let x = p.state_at(t).p[0];
        seen = (seen.0.min(x), seen.1.max(x));
        t += 1e-5;
    }
    assert!(seen.1 > 1000.0, "it overshoots: {seen:?}");
    assert!((b[0].0 - seen.0).abs() < 0.5 && (b[0].1 - seen.1).abs() < 0.5, "{:?} {seen:?}", b[0]);
}

#[test]
fn a_new_profile_is_held_to_both_soft_limits_with_the_motor_and_where() {
    let soft = [(-9_000.0, 10_000.0); MAX_MOTORS];
    let mut g = OnlineMove::new([0.0; MAX_MOTORS], 3, T, limits()).with_soft_limits(soft);
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    // Exactly on either limit is inside.
    g.retarget(&arr(&[-9_000.0, 10_000.0, 0.0]), &limits()).unwrap();
    assert_eq!(*g.target(), arr(&[-9_000.0, 10_000.0, 0.0]));
    // Moving down fast near the lower limit, a slow turn would carry motor 2 below it.
    g.continue_from(
        10,
        MotionState {
            p: arr(&[0.0, -8_000.0, 0.0]),
            v: arr(&[0.0, -80_000.0]),
            ..Default::default()
        },
    );
    match g.retarget(&arr(&[0.0, 0.0, 0.0]), &limits().at_speed(0.1)) {
        Err(RetargetError::SoftLimits { motor, counts }) => {
            assert_eq!(motor, 2);
            assert!(counts < -9_000.0, "{counts}");
        }
        other => panic!("{other:?}"),
    }
    assert_eq!(g.last().0, 10, "the move goes on as it was");
    // The same from the upper side, motor 3.
    g.continue_from(
        20,
        MotionState {
            p: arr(&[0.0, 0.0, 9_000.0]),
            v: arr(&[0.0, 0.0, 80_000.0]),
            ..Default::default()
        },
    );
    match g.retarget(&arr(&[0.0, 0.0, 0.0]), &limits().at_speed(0.1)) {
        Err(RetargetError::SoftLimits { motor, counts }) => {
            assert_eq!(motor, 3);
            assert!(counts > 10_000.0, "{counts}");
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn continuing_from_a_state_holds_it_from_that_sample() {
    let mut g = OnlineMove::new([0.0; MAX_MOTORS], 3, T, limits());
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    let at = MotionState::at_rest(arr(&[1.0, 2.0, 3.0]));
    g.continue_from(500, at);
    let mut cmd = [0.0; MAX_MOTORS];
    assert_eq!(g.sample(500, &mut cmd), Sample::Ready);
    assert_eq!(cmd, at.p);
    assert_eq!(g.last(), (500, at));
    assert!(!g.moving());
    assert_eq!(g.sample(501, &mut cmd), Sample::Done, "nothing more to move");
    assert_eq!(g.name(), "move");
    assert_eq!(g.end_velocity(), Some([0.0; MAX_MOTORS]), "every move ends at rest");
}

#[test]
fn the_move_is_moving_until_its_last_sample() {
    let mut g = OnlineMove::new(arr(&[1000.0, 0.0, 0.0]), 3, T, limits());
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    let last = g.samples().unwrap() - 1;
    let mut cmd = [0.0; MAX_MOTORS];
    for n in 0..last {
        g.sample(n, &mut cmd);
        assert!(g.moving(), "sample {n}");
    }
    g.sample(last, &mut cmd);
    assert!(!g.moving(), "at its last sample it is on the target");
    assert_eq!(cmd[0], 1000.0);
}

#[test]
fn the_last_sample_is_the_target_even_when_its_time_falls_a_rounding_short() {
    // A move whose duration is a whole number of periods to within rounding: its last sample
    // time may fall just short of the profile's end, and still commands the target exactly.
    for target in [[3000.0, -2500.0, 800.0], [1000.0, 0.0, 0.0], [-7321.0, 12.5, 4000.0]] {
        let (_, q) = moved(&[0.0; 3], &target, &limits());
        assert_eq!(q.last().unwrap()[..3], target);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// The bounds are the profile's extremes: from any state — moving, turning inside a jerk
    /// segment or a constant-acceleration one, braking from beyond slower limits first — every
    /// position of the profile is within them, and they are reached (dense sampling finds
    /// them to within a tenth of a count: what a position moves in a sampling step there).
    #[test]
    fn the_bounds_are_the_profiles_extremes(
        p in prop::array::uniform3(-5000.0..5000.0f64),
        v in prop::array::uniform3(-1.5..1.5f64),
        a in prop::array::uniform3(-1.4..1.4f64),
        to in prop::array::uniform3(-5000.0..5000.0f64),
        speed in 0.3..=1.0f64,
    ) {
        let full = limits();
        let lim = full.at_speed(speed);
        // Velocities up to 1.5 ×, accelerations up to 1.4 × the slower limits: Ruckig brakes
        // first.
        let from = MotionState {
            p: arr(&p),
            v: arr(&v.map(|x| x * lim.velocity[0])),
            a: arr(&a.map(|x| x * lim.acceleration[0])),
        };
        let mut pr = Profile::new(3, [0.0; MAX_MOTORS]);
        pr.plan(&from, &arr(&to), &lim).unwrap();
        let b = pr.bounds();
        let mut seen = [(f64::INFINITY, f64::NEG_INFINITY); 3];
        let steps = 4000;
        for k in 0..=steps {
            let s = pr.state_at(pr.duration() * k as f64 / steps as f64);
            for (sm, x) in seen.iter_mut().zip(s.p) {
                *sm = (sm.0.min(x), sm.1.max(x));
            }
        }
        for m in 0..3 {
            prop_assert!(b[m].0 <= seen[m].0 + 1e-6 && b[m].1 >= seen[m].1 - 1e-6, "motor {m}: {:?} {:?}", b[m], seen[m]);
            prop_assert!(seen[m].0 - b[m].0 < 0.1 && b[m].1 - seen[m].1 < 0.1, "motor {m}: {:?} {:?}", b[m], seen[m]);
        }
    }
}
