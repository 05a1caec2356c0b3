//! The tracker against a belt it reads as the loop does — whole counts, at read times that
//! jitter by up to half a period: at a constant speed it sits on the belt and its jerk is
//! a thousandth of the raw counts'; through a change of speed at the belt's acceleration it
//! stays within a few counts and settles back on it.

use super::*;

const T: f64 = 400e-6;

/// A belt at `v0` counts/s that goes to `v1` at `acc` counts/s² from `t1`: its position.
fn belt(t: f64, (v0, v1, t1, acc): (f64, f64, f64, f64)) -> f64 {
    let ramp = (v1 - v0).abs() / acc;
    let s = (v1 - v0).signum();
    if t < t1 {
        return v0 * t;
    }
    let dt = (t - t1).min(ramp);
    v0 * t1 + v0 * dt + 0.5 * s * acc * dt * dt + v1 * (t - t1 - ramp).max(0.0)
}

/// Reads `cycles` cycles of `motion` (counts at jittered times, floored): per cycle the
/// estimate and the belt's true position at the cycle's time.
fn follow(motion: (f64, f64, f64, f64), cycles: usize) -> Vec<(f64, f64)> {
    let mut tracker = BeltTracker::new(T);
    let mut seed = 0x2545_f491_4f6c_dd1d_u64;
    (0..cycles)
        .map(|k| {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            let jitter = (seed % 1000) as f64 / 1000.0 * T / 2.0;
            let t = k as f64 * T;
            tracker.read(k as u64, belt(t + jitter, motion).floor() as i64);
            (tracker.position(), belt(t, motion))
        })
        .collect()
}

fn third_differences(x: &[f64]) -> Vec<f64> {
    x.windows(4).map(|w| w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0]).collect()
}

fn rms(x: &[f64]) -> f64 {
    (x.iter().map(|v| v * v).sum::<f64>() / x.len() as f64).sqrt()
}

#[test]
fn at_a_constant_speed_it_sits_on_the_belt_with_a_smooth_jerk() {
    // 487 mm/s at 0.05 mm a count: not a whole number of counts a period.
    let speed = 9_740.0;
    let run = follow((speed, speed, f64::INFINITY, 1.0), 5_000);
    let settled = &run[2_500..];
    let worst = settled.iter().map(|(p, b)| (p - b).abs()).fold(0.0, f64::max);
    // Whole counts read up to half a period late: about a count and a half at most.
    assert!(worst < 2.5, "{worst} counts off the belt");
    let estimate: Vec<f64> = settled.iter().map(|r| r.0).collect();
    let raw: Vec<f64> = settled.iter().map(|r| r.1.floor()).collect();
    let (smooth, rough) = (rms(&third_differences(&estimate)), rms(&third_differences(&raw)));
    assert!(rough > 0.5, "the raw counts' jerk {rough}");
    assert!(smooth < rough / 1_000.0, "the estimate's jerk {smooth}, the counts' {rough}");
}

#[test]
fn it_follows_a_change_of_speed_and_settles_on_the_belt() {
    // 500 → 300 mm/s at 2000 mm/s² (the shipped belt's), in counts.
    let motion = (10_000.0, 6_000.0, 1.0, 40_000.0);
    let run = follow(motion, 5_000);
    let during = run[2_400..3_000].iter().map(|(p, b)| (p - b).abs()).fold(0.0, f64::max);
    assert!(during < 8.0, "{during} counts off while the belt slows (0.4 mm)");
    let after = run[4_000..].iter().map(|(p, b)| (p - b).abs()).fold(0.0, f64::max);
    assert!(after < 2.0, "{after} counts off after it");
}

#[test]
fn before_the_speed_is_measured_it_is_the_counts_read() {
    let mut tracker = BeltTracker::new(T);
    for k in 0..SPEED_CYCLES as i64 {
        let before = tracker.position();
        tracker.read(k as u64, 100 + 4 * k);
        assert_eq!(tracker.position(), (100 + 4 * k) as f64);
        if k > 0 {
            assert_eq!(tracker.position_before(), before);
            assert!((tracker.speed() - 4.0 / T).abs() < 1e-6, "{}", tracker.speed());
        }
    }
}

/// After missed periods the reads are more than a period apart: the estimate is carried over
/// the time between them. A belt at a constant speed read every third period for a while
/// stays followed all through (not only at the end), a stall of 250 periods restarts the
/// loop on the belt, and at a 10 ms servo period the loop (its bandwidth lowered) follows
/// as well.
#[test]
fn missed_periods_and_long_periods_keep_the_estimate_on_the_belt() {
    let follow_at = |period: f64, skip: &dyn Fn(u64) -> bool| {
        let speed = 9_740.0;
        let at = |n: u64| speed * n as f64 * period;
        let mut t = BeltTracker::new(period);
        let mut worst = 0.0f64;
        for n in 0..4_000u64 {
            if skip(n) {
                continue;
            }
            t.read(n, at(n).floor() as i64);
            if n > 500 {
                worst = worst.max((t.position() - at(n)).abs());
                assert!((t.speed() - speed).abs() < 0.05 * speed, "{n}: {} counts/s", t.speed());
            }
        }
        worst
    };
    let punctual = follow_at(T, &|_| false);
    let every_third = follow_at(T, &|n| (1_000..1_300).contains(&n) && n % 3 != 0);
    let stalled = follow_at(T, &|n| (2_000..2_250).contains(&n));
    let long_period = follow_at(0.01, &|_| false);
    for (name, worst) in [
        ("punctual", punctual),
        ("every third", every_third),
        ("a 250-period stall", stalled),
        ("a 10 ms period", long_period),
    ] {
        assert!(worst < 2.0, "{name}: {worst} counts off the belt");
    }
}

/// Over a gap (missed periods, fewer than a restart's) the estimate is carried by the
/// belt's kinematics: on a belt accelerating hard (4·10⁷ counts/s², so that its motion over
/// a few periods dwarfs a count) the estimate right after a 7-period gap is where the belt
/// is, and so is its speed.
#[test]
fn a_gap_carries_the_estimate_with_the_belts_acceleration() {
    let acc = 4e7;
    let at = |n: u64| 0.5 * acc * (n as f64 * T).powi(2);
    let mut t = BeltTracker::new(T);
    for n in 0..3_000u64 {
        t.read(n, at(n).floor() as i64);
    }
    let n = 3_006;
    t.read(n, at(n).floor() as i64);
    assert!((t.position() - at(n)).abs() < 2.0, "{} for {}", t.position(), at(n));
    let speed = acc * n as f64 * T;
    assert!((t.speed() - speed).abs() < 2e3, "{} counts/s for {speed}", t.speed());
}

/// Over a gap the estimate is carried exactly as its own jerk moves it (constant jerk over
/// the gap's time), whatever the read then says; a gap of [`RESTART_PERIODS`] is carried,
/// a longer one restarts the estimate at the counts read and their measured speed.
#[test]
fn a_gap_is_crossed_at_the_estimates_own_jerk_a_longer_one_restarts() {
    let change = (12_500.0, 7_500.0, 0.5, 4e4);
    for gap in [2, 5, RESTART_PERIODS, RESTART_PERIODS + 1] {
        let mut t = BeltTracker::new(T);
        // In the change of speed: an estimate with speed, acceleration and jerk.
        let n0 = 1_300u64;
        for n in 0..=n0 {
            t.read(n, belt(n as f64 * T, change).floor() as i64);
        }
        let ([p, v, a], j) = (t.now, t.jerk);
        assert!(a.abs() > 1e3 && j.abs() > 1e4, "a = {a}, j = {j}");
        let n = n0 + gap;
        let z = belt(n as f64 * T, change).floor() as i64;
        t.read(n, z);
        let dt = gap as f64 * T;
        let carried = [
            p + v * dt + a * dt * dt / 2.0 + j * dt.powi(3) / 6.0,
            v + a * dt + j * dt * dt / 2.0,
            a + j * dt,
        ];
        if gap <= RESTART_PERIODS {
            for (k, (got, want)) in t.now.iter().zip(carried).enumerate() {
                let scale = want.abs().max(1.0);
                assert!((got - want).abs() <= 1e-9 * scale, "gap {gap}, [{k}]: {got} for {want}");
            }
        } else {
            assert_eq!(t.now, [z as f64, t.measured_speed(), 0.0], "gap {gap}: restarted");
            assert_eq!((t.jerk, t.integral), (0.0, 0.0));
        }
    }
}
