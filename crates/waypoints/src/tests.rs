//! Paths against knots computed by hand: the notes' IK written out for points on the z axis,
//! where the three arms agree, and its derivative for the PVT velocities.

use super::*;
use qmarc_kinematics::{Geometry, JointFrame};

const CPR: f64 = 4096.0 * 12.0 / std::f64::consts::TAU;

/// θ of every arm for the effector at (0, 0, z), by hand from the notes (x_i = y_i = 0):
/// E = 2L·a, F = 2L·z, G = a² + z² + L² − l², θ = atan2(F, E) + acos(−G/√(E² + F²)).
fn theta_on_axis(z: f64) -> f64 {
    let (a, l_arm, l_rod) = (0.15, 0.3, 0.7);
    let (e, f, g) =
        (2.0 * l_arm * a, 2.0 * l_arm * z, a * a + z * z + l_arm * l_arm - l_rod * l_rod);
    f.atan2(e) + (-g / e.hypot(f)).acos()
}

/// dθ/dz on the axis, by implicit differentiation of E cos θ + F sin θ + G = 0
/// (∂F/∂z = 2L, ∂G/∂z = 2z).
fn dtheta_dz_on_axis(z: f64) -> f64 {
    let (a, l_arm) = (0.15, 0.3);
    let th = theta_on_axis(z);
    let (e, f) = (2.0 * l_arm * a, 2.0 * l_arm * z);
    -(2.0 * l_arm * th.sin() + 2.0 * z) / (-e * th.sin() + f * th.cos())
}

fn robot() -> Robot {
    let home = theta_on_axis(-0.6);
    Robot {
        geometry: Geometry::ASSUMED,
        frame: JointFrame { home_rad: [home; 3], counts_per_rad: CPR },
    }
}

fn waypoints(text: &str) -> Waypoints {
    parse_waypoints("w.txt", text, &KnotRules::new(3)).unwrap()
}

#[test]
fn the_hand_formula_is_the_notes_known_point() {
    assert!((theta_on_axis(-0.6).to_degrees() - 11.3332).abs() < 5e-5);
}

#[test]
fn knots_at_the_waypoints_are_the_hand_computed_counts_and_velocities() {
    // Two waypoints: the natural spline is the straight line, ż = −0.5 m/s throughout.
    let w = waypoints("# a drop of 50 mm in 0.1 s\n0.0  0 0 -0.6\n\n0.1  0 0 -0.65\n");
    let k = joint_knots(&robot(), &w, "w.txt", None).unwrap();
    assert_eq!(k.len(), 2);
    let end = CPR * (theta_on_axis(-0.65) - theta_on_axis(-0.6));
    for m in 0..3 {
        assert!(k[0].counts[m].abs() < 1e-9);
        assert!((k[1].counts[m] - end).abs() < 1e-6, "{} vs {end}", k[1].counts[m]);
        for (knot, z) in [(&k[0], -0.6), (&k[1], -0.65)] {
            let v = CPR * dtheta_dz_on_axis(z) * -0.5;
            assert!(
                (knot.counts_per_s[m] - v).abs() < 1e-6 * v.abs(),
                "{} vs {v}",
                knot.counts_per_s[m]
            );
        }
    }
    assert_eq!((k[0].t_s, k[1].t_s), (0.0, 0.1));
}

#[test]
fn resampling_puts_knots_every_t_ms_and_keeps_the_last_waypoint() {
    let w = waypoints("1.0 0 0 -0.6\n1.1 0 0 -0.65\n");
    let k = joint_knots(&robot(), &w, "w.txt", Some(0.025)).unwrap();
    let times: Vec<f64> = k.iter().map(|k| (k.t_s * 1e6).round() / 1e6).collect();
    assert_eq!(times, [0.0, 0.025, 0.05, 0.075, 0.1]);
    for (i, knot) in k.iter().enumerate() {
        let z = -0.6 - 0.0125 * i as f64;
        let c = CPR * (theta_on_axis(z) - theta_on_axis(-0.6));
        assert!((knot.counts[1] - c).abs() < 1e-6, "knot {i}: {} vs {c}", knot.counts[1]);
    }
    // 30 ms does not divide 100 ms: 0, 30, 60, 90, then the last waypoint at 100.
    let k = joint_knots(&robot(), &w, "w.txt", Some(0.03)).unwrap();
    let times: Vec<f64> = k.iter().map(|k| (k.t_s * 1e6).round() / 1e6).collect();
    assert_eq!(times, [0.0, 0.03, 0.06, 0.09, 0.1]);
}

#[test]
fn the_files_are_the_thesis_formats() {
    let w = waypoints("0.0 0 0 -0.6\n0.1 0 0 -0.65\n");
    let k = joint_knots(&robot(), &w, "w.txt", Some(0.05)).unwrap();
    let end = (CPR * (theta_on_axis(-0.65) - theta_on_axis(-0.6))).round();
    let half = (CPR * (theta_on_axis(-0.625) - theta_on_axis(-0.6))).round();
    let spline = render(&k, KnotFormat::Spline, "test");
    assert_eq!(
        spline,
        format!(
            "# test\n3\n0.000000\t0\t0\t0\n0.050000\t{half}\t{half}\t{half}\n0.100000\t{end}\t{end}\t{end}\n"
        )
    );
    let pvt = render(&k, KnotFormat::Pvt, "");
    let rows: Vec<Vec<&str>> = pvt.lines().map(|l| l.split('\t').collect()).collect();
    assert_eq!(rows.len(), 3);
    assert_eq!(rows[1][..2], ["X", &half.to_string()[..]]);
    assert_eq!((rows[1][3], rows[1][7], rows[2][3]), ("50.00000", "50.00000", "50.00000"));
    let v = CPR * dtheta_dz_on_axis(-0.625) * -0.5;
    assert_eq!(rows[1][2], format!("{v:.3}"));
    assert_eq!(parse_pvt("p", &pvt, &KnotRules::new(3)).unwrap().len(), 3);
    assert_eq!(parse_offline("s", &spline, &KnotRules::new(3)).unwrap().times.len(), 3);
}

#[test]
fn unreachable_points_name_the_line_and_the_arm() {
    let w = waypoints("0.0 0 0 -0.6\n# out of reach:\n0.1 0 0 -1.2\n");
    let e = joint_knots(&robot(), &w, "w.txt", None).unwrap_err();
    assert_eq!(
        e.to_string(),
        "w.txt:3: at t = 0.1 s: arm 1 cannot reach (0.0, 0.0, -1200.0) mm: the point is out of its reach"
    );
    // Issue 28, item 8: said once — the reason is in the message and not chained as a source
    // too, which the starter's `{:#}` would print a second time.
    assert!(std::error::Error::source(&e).is_none(), "{e}");
    // A resampled knot between waypoints names both: the spline through these reachable
    // points (the reach on the axis ends near z = −0.99 m) dips below z = −0.98 m.
    let w = waypoints("0.0 0 0 -0.6\n0.1 0 0 -0.98\n0.12 0 0 -0.6\n");
    assert!(joint_knots(&robot(), &w, "w.txt", None).is_ok());
    let e = joint_knots(&robot(), &w, "w.txt", Some(0.005)).unwrap_err();
    assert!(e.to_string().starts_with("w.txt:1-2: at t = 0.035 s: arm 1 cannot reach"), "{e}");
    assert_eq!(
        joint_knots(&robot(), &w, "w.txt", Some(0.0)).unwrap_err().to_string(),
        "--every-ms must be a finite number of ms > 0, found 0"
    );
    // Issue 28, item 8: the interval as given, not float noise (0.0000010000000000000002).
    assert_eq!(
        joint_knots(&robot(), &w, "w.txt", Some(1e-9)).unwrap_err().to_string(),
        format!(
            "--every-ms 1e-6 makes 120000001 knots, more than the {MAX_KNOTS} a knot file may hold"
        )
    );
}
