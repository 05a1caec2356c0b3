//! Unit tests of the PVT generator: its segments against the end conditions solved
//! directly, their extremes, and whole paths through every knot.

use super::*;
use proptest::prelude::*;

fn knot(pos: f64, vel: f64, dt_ms: f64) -> PvtKnot {
    let mut k = PvtKnot { dt_s: dt_ms / 1000.0, ..PvtKnot::default() };
    k.pos[0] = pos;
    k.vel[0] = vel;
    k
}

#[test]
fn hermite_meets_both_ends() {
    // The thesis' example segment: 0 → 309 counts, 0 → 16 000 counts/s in 25 ms.
    let h = Hermite::new(0.0, 0.0, 309.0, 16_000.0, 0.025);
    assert_eq!((h.position(0.0), h.velocity(0.0)), (0.0, 0.0));
    assert!((h.position(0.025) - 309.0).abs() < 1e-9);
    assert!((h.velocity(0.025) - 16_000.0).abs() < 1e-7);
    // By hand: B = 3·309/0.025² − 16000/0.025 = 1 483 200 − 640 000 = 843 200;
    // A = −2·309/0.025³ + 16000/0.025² = −39 552 000 + 25 600 000 = −13 952 000.
    assert!((h.b - 843_200.0).abs() < 1e-6 && (h.a + 13_952_000.0).abs() < 1e-5, "{h:?}");
    assert!((h.acceleration(0.0) - 2.0 * h.b).abs() < 1e-9);
}

#[test]
fn file_path_is_sampled_segment_by_segment_and_ends() {
    let knots = vec![knot(0.0, 0.0, 10.0), knot(100.0, 5_000.0, 20.0), knot(200.0, 0.0, 10.0)];
    let mut g = Pvt::from_knots(knots, 1, 0.001, 5.0);
    assert_eq!(g.samples(), Some(31));
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    let mut cmd = [0.0; MAX_MOTORS];
    let mut seen = Vec::new();
    let mut n = 0;
    while g.sample(n, &mut cmd) == Sample::Ready {
        seen.push(cmd[0]);
        n += 1;
    }
    assert_eq!(n, 31);
    assert_eq!(seen[0], 0.0);
    assert!((seen[10] - 100.0).abs() < 1e-9, "{}", seen[10]);
    assert!((seen[30] - 200.0).abs() < 1e-9, "{}", seen[30]);
    assert_eq!(g.sample(31, &mut cmd), Sample::Done);
}

#[test]
fn path_far_from_the_robot_is_refused() {
    let knots = vec![knot(500.0, 0.0, 10.0), knot(600.0, 0.0, 10.0), knot(700.0, 0.0, 10.0)];
    let mut g = Pvt::from_knots(knots, 1, 0.001, 5.0);
    let e = g.start(&[0.0; MAX_MOTORS]).unwrap_err().to_string();
    assert!(e.starts_with("motor 1 is at 0 counts but the path starts at 500 counts"), "{e}");
}

proptest! {
    /// Each segment meets its knots' positions and velocities, and its coefficients are
    /// those of an independent 4×4 solve of the end conditions (nalgebra LU).
    #[test]
    fn hermite_agrees_with_the_end_conditions_solved_directly(
        x0 in -1e5f64..1e5, x1 in -1e5f64..1e5, v0 in -5e4f64..5e4, v1 in -5e4f64..5e4, t in 0.001f64..0.2,
    ) {
        let h = Hermite::new(x0, v0, x1, v1, t);
        let scale = 1.0 + x0.abs() + x1.abs() + (v0.abs() + v1.abs()) * t;
        prop_assert!((h.position(0.0) - x0).abs() <= 1e-9 * scale);
        prop_assert!((h.position(t) - x1).abs() <= 1e-9 * scale);
        prop_assert!((h.velocity(0.0) - v0).abs() <= 1e-9 * scale / t);
        prop_assert!((h.velocity(t) - v1).abs() <= 1e-9 * scale / t);
        let m = nalgebra::Matrix4::new(
            1.0, 0.0, 0.0, 0.0,
            0.0, 1.0, 0.0, 0.0,
            1.0, t, t * t, t * t * t,
            0.0, 1.0, 2.0 * t, 3.0 * t * t,
        );
        let dcba = m.lu().solve(&nalgebra::Vector4::new(x0, v0, x1, v1)).unwrap();
        prop_assert!((dcba[0] - h.d).abs() <= 1e-9 * scale);
        prop_assert!((dcba[1] - h.c).abs() <= 1e-6 * scale / t);
        prop_assert!((dcba[2] - h.b).abs() <= 1e-6 * scale / (t * t));
        prop_assert!((dcba[3] - h.a).abs() <= 1e-6 * scale / (t * t * t));
    }

    /// The motion limits' view of a segment (its end accelerations, from which its
    /// extremes are found) is this generator's cubic.
    #[test]
    fn the_limits_see_the_segment_the_generator_samples(
        x0 in -1e5f64..1e5, x1 in -1e5f64..1e5, v0 in -5e4f64..5e4, v1 in -5e4f64..5e4, t in 0.001f64..0.2,
    ) {
        let h = Hermite::new(x0, v0, x1, v1, t);
        let (a0, a1) = qmarc_knots::dynamics::hermite_end_accelerations(x0, v0, x1, v1, t);
        let scale = (1.0 + x0.abs() + x1.abs() + (v0.abs() + v1.abs()) * t) / (t * t);
        prop_assert!((h.acceleration(0.0) - a0).abs() <= 1e-9 * scale);
        prop_assert!((h.acceleration(t) - a1).abs() <= 1e-9 * scale);
    }

    /// The extremes of a segment bound every point of it and are reached: a dense
    /// sweep finds nothing outside them and comes within a hair of both.
    #[test]
    fn segment_extremes_bound_and_touch_the_curve(
        x0 in -1e5f64..1e5, x1 in -1e5f64..1e5, v0 in -5e4f64..5e4, v1 in -5e4f64..5e4, t in 0.001f64..0.2,
    ) {
        let h = Hermite::new(x0, v0, x1, v1, t);
        let (lo, hi) = h.extremes(t);
        let (mut slo, mut shi) = (f64::INFINITY, f64::NEG_INFINITY);
        for i in 0..=20_000 {
            let p = h.position(t * f64::from(i) / 20_000.0);
            slo = slo.min(p);
            shi = shi.max(p);
        }
        let scale = 1.0 + x0.abs() + x1.abs() + (v0.abs() + v1.abs()) * t;
        prop_assert!(slo >= lo - 1e-9 * scale && shi <= hi + 1e-9 * scale);
        prop_assert!(slo - lo <= 1e-6 * scale && hi - shi <= 1e-6 * scale, "{lo} {slo} {hi} {shi}");
    }

    /// A whole random path passes through every knot at its time.
    #[test]
    fn path_meets_every_knot(
        raw in proptest::collection::vec((-1e4f64..1e4, -2e4f64..2e4, 1u32..40), 3..30),
    ) {
        let knots: Vec<PvtKnot> = raw.iter().enumerate()
            .map(|(i, &(p, v, ms))| knot(if i == 0 { 0.0 } else { p.round() }, v, f64::from(ms)))
            .collect();
        let mut g = Pvt::from_knots(knots.clone(), 1, 0.001, 1.0);
        g.start(&[0.0; MAX_MOTORS]).unwrap();
        let mut cmd = [0.0; MAX_MOTORS];
        let mut t_ms = 0u64;
        for k in &knots {
            prop_assert_eq!(g.sample(t_ms, &mut cmd), Sample::Ready);
            prop_assert!((cmd[0] - k.pos[0]).abs() <= 1e-6 * (1.0 + k.pos[0].abs()), "{} vs {}", cmd[0], k.pos[0]);
            t_ms += (k.dt_s * 1000.0).round() as u64;
        }
    }
}
