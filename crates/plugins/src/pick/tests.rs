//! The pick cycle: it starts and ends at rest at the pick point, passes through the cycle's
//! points in order and dwells at both ends, keeps every motor limit and reaches them (each
//! leg is time-optimal), and played at half speed takes twice the time of its motion.

use super::*;
use qmarc_config::Names;
use qmarc_kinematics::Point;

const T: f64 = 400e-6;

fn shipped() -> Settings {
    let names = Names {
        laws: crate::registry::law_names(),
        methods: crate::registry::path_generator_names(),
        any_plugin: false,
    };
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
    Settings::load(&dir.join("qmarc.toml"), &names).expect("shipped settings")
}

fn cycle(s: &Settings) -> Vec<[f64; MAX_MOTORS]> {
    PickCycle::from_settings(s).expect("the shipped cycle").commands().to_vec()
}

/// Samples at which every motor stands still (the same command as the sample before).
fn still(q: &[[f64; MAX_MOTORS]]) -> usize {
    q.windows(2).filter(|w| (0..ARMS).all(|m| w[0][m] == w[1][m])).count()
}

#[test]
fn the_cycle_goes_through_its_points_and_back_at_rest() {
    let s = shipped();
    let q = cycle(&s);
    let robot = s.robot().expect("a Delta");
    let counts: Vec<[f64; 3]> = cycle_points(&s.pick)
        .iter()
        .map(|p| robot.counts_of(&Point::new(p[0] / 1e3, p[1] / 1e3, p[2] / 1e3)).unwrap())
        .collect();
    let at = |c: &[f64; 3]| q.iter().position(|x| (0..ARMS).all(|m| x[m] == c[m]));
    assert_eq!(&q[0][..ARMS], &counts[0][..], "starts at the pick point");
    assert_eq!(&q[q.len() - 1][..ARMS], &counts[0][..], "ends there");
    // The points in order: pick, above it, above the place, the place.
    let firsts: Vec<usize> = counts.iter().map(|c| at(c).expect("passes the point")).collect();
    assert!(firsts.windows(2).all(|w| w[0] < w[1]), "{firsts:?}");
    // The dwell at the pick point before the first leg and at the place, 50 ms each; the
    // six legs each begin and end at rest.
    let dwell = (s.pick.dwell_s / T).round() as usize;
    assert!(q[..=dwell].iter().all(|x| x == &q[0]));
    assert!(q[dwell + 1] != q[0], "the first leg starts after the dwell");
    let place = firsts[3];
    assert!(q[place..=place + dwell].iter().all(|x| x == &q[place]));
    assert!(still(&q) >= 2 * dwell, "{} still samples", still(&q));
}

#[test]
fn the_cycle_keeps_the_motor_limits_and_reaches_them() {
    let s = shipped();
    let q = cycle(&s);
    let l = MotionLimits::of(&s);
    for m in 0..ARMS {
        let p: Vec<f64> = q.iter().map(|c| c[m]).collect();
        let d = |x: &[f64]| x.windows(2).map(|w| (w[1] - w[0]) / T).collect::<Vec<f64>>();
        let (v, a) = (d(&p), d(&d(&p)));
        let max = |x: &[f64]| x.iter().fold(0.0f64, |acc, y| acc.max(y.abs()));
        // Sampled differences of a profile at its limits stay within them (a sample's
        // mean over a period cannot exceed the peak), up to rounding.
        assert!(max(&v) <= l.velocity[m] * (1.0 + 1e-9), "motor {m}: {}", max(&v));
        assert!(max(&a) <= l.acceleration[m] * 1.01, "motor {m}: {}", max(&a));
    }
    // Time-optimal legs: some motor of the cycle reaches 90 % of its acceleration limit.
    let peak = (0..ARMS)
        .map(|m| {
            let p: Vec<f64> = q.iter().map(|c| c[m]).collect();
            p.windows(3)
                .map(|w| ((w[2] - 2.0 * w[1] + w[0]) / (T * T)).abs() / l.acceleration[m])
                .fold(0.0, f64::max)
        })
        .fold(0.0, f64::max);
    assert!(peak > 0.9, "the cycle's fastest acceleration is {peak:.2} of the limit");
}

/// A time scaling: velocity × s, acceleration × s², jerk × s³ plays the same motion 1/s
/// times as long (the dwells apart).
#[test]
fn half_speed_takes_twice_the_motion_time() {
    let mut s = shipped();
    let motion = |s: &Settings| {
        let q = cycle(s);
        (q.len() - 1 - 2 * (s.pick.dwell_s / T).round() as usize) as f64 * T
    };
    let full = motion(&s);
    s.pick.speed = 0.5;
    let half = motion(&s);
    // Each of the six legs rounds its duration up to a whole period.
    assert!((half - 2.0 * full).abs() <= 12.0 * T, "{full} s at 1, {half} s at 0.5");
}

#[test]
fn a_point_out_of_reach_or_no_delta_is_refused_naming_pick() {
    let mut s = shipped();
    s.pick.cross_mm = 1500.0;
    let e = PickCycle::from_settings(&s).unwrap_err().to_string();
    assert!(e.contains("[pick]") && e.contains("out of reach"), "{e}");
    let mut s = shipped();
    s.robot = None;
    let e = PickCycle::from_settings(&s).unwrap_err().to_string();
    assert!(e.contains("no [robot] table"), "{e}");
}
