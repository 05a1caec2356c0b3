//! The kinematics against the notes' known point, each other (round trips), finite
//! differences, and points out of reach.

use super::*;
use proptest::prelude::*;

const G: Geometry = Geometry::ASSUMED;

/// A grid over the notes' workspace: a 200 mm-radius disc at z = −0.6 ± 0.1 m.
fn workspace() -> impl Iterator<Item = Point> {
    (-10..=10).flat_map(|ix| {
        (-10..=10).flat_map(move |iy| {
            (-4..=4).filter_map(move |iz| {
                let p = Point::new(
                    f64::from(ix) * 0.02,
                    f64::from(iy) * 0.02,
                    -0.6 + f64::from(iz) * 0.025,
                );
                (p.x.hypot(p.y) <= 0.2).then_some(p)
            })
        })
    })
}

#[test]
fn the_notes_known_point_has_11_3332_degrees_on_every_arm() {
    let theta = G.inverse(&Point::new(0.0, 0.0, -0.6)).unwrap();
    for t in theta.iter() {
        assert!((t.to_degrees() - 11.3332).abs() < 5e-5, "{}", t.to_degrees());
    }
}

#[test]
fn inverse_then_forward_returns_the_point_within_1e_9_m_over_the_workspace() {
    let mut worst = 0.0f64;
    let mut n = 0;
    for p in workspace() {
        let back = G.forward(&G.inverse(&p).unwrap()).unwrap();
        worst = worst.max((back - p).norm());
        n += 1;
    }
    assert!(n > 1000, "{n} points");
    assert!(worst <= 1e-9, "worst round trip {worst} m");
}

#[test]
fn forward_then_inverse_returns_the_angles() {
    for t in [[0.0, 0.0, 0.0], [0.3, -0.1, 0.5], [-0.2, 0.4, 0.1]] {
        let theta = Angles::from(t);
        let back = G.inverse(&G.forward(&theta).unwrap()).unwrap();
        assert!((back - theta).norm() < 1e-12, "{t:?} → {back:?}");
    }
}

#[test]
fn the_jacobian_matches_finite_differences() {
    let h = 1e-6;
    for p in workspace().step_by(37) {
        let theta = G.inverse(&p).unwrap();
        let j = G.jacobian(&p, &theta).unwrap();
        for k in 0..3 {
            let mut dp = Point::zeros();
            dp[k] = h;
            let numeric =
                (G.inverse(&(p + dp)).unwrap() - G.inverse(&(p - dp)).unwrap()) / (2.0 * h);
            let analytic = j.column(k);
            assert!(
                (numeric - analytic).norm() <= 1e-6 * (1.0 + analytic.norm()),
                "at {p:?}, ∂θ/∂p{k}: {numeric:?} vs {analytic:?}"
            );
        }
    }
}

#[test]
fn the_workspace_is_well_conditioned_as_the_notes_say() {
    let mut worst = 0.0f64;
    for p in workspace().filter(|p| (p.z + 0.6).abs() <= 0.025) {
        let j = G.jacobian(&p, &G.inverse(&p).unwrap()).unwrap();
        let sv = j.singular_values();
        worst = worst.max(sv.max() / sv.min());
    }
    assert!((1.5..2.2).contains(&worst), "condition number up to {worst}");
}

#[test]
fn points_out_of_reach_are_refused_naming_the_arm() {
    // 0.9 m out along arm 1's azimuth: within arm 1's reach, beyond that of arms 2 and 3,
    // whose motors sit on the other side of the base.
    let e = G.inverse(&Point::new(0.9, 0.0, -0.3)).unwrap_err();
    assert!(matches!(e, KinematicsError::Unreachable { .. }), "{e:?}");
    let text = e.to_string();
    assert!(
        text.starts_with("arm ") && text.contains("cannot reach (900.0, 0.0, -300.0) mm"),
        "{text}"
    );
    let e = G.inverse(&Point::new(0.0, 0.0, -1.2)).unwrap_err();
    assert_eq!(e, KinematicsError::Unreachable { arm: 1, point: [0.0, 0.0, -1.2] });
    assert_eq!(G.inverse(&Point::new(f64::NAN, 0.0, -0.6)), Err(KinematicsError::NotFinite));
}

#[test]
fn angles_no_pose_has_are_refused() {
    // Cables of 0.1 m cannot join elbows 0.45 m from the axis.
    let short = Geometry { rod_length_m: 0.1, ..G };
    let e = short.forward(&Angles::new(0.0, 0.0, 0.5)).unwrap_err();
    assert!(matches!(e, KinematicsError::NoPose { .. }), "{e:?}");
    assert!(
        e.to_string().contains("no pose has the arm angles (0.0000°, 0.0000°, 28.6479°)"),
        "{e}"
    );
}

#[test]
fn a_cable_aligned_with_its_arm_is_singular() {
    // Arm 1 straight out and its cable continuing it: the effector on the x axis, at z = 0.
    let p = Point::new(
        G.base_radius_m + G.arm_length_m + G.rod_length_m - G.effector_radius_m,
        0.0,
        0.0,
    );
    let e = G.jacobian(&p, &Angles::new(0.0, 0.0, 0.0)).unwrap_err();
    assert!(matches!(e, KinematicsError::Singular { arm: 1, .. }), "{e:?}");
}

#[test]
fn counts_follow_the_frame() {
    let home = G.inverse(&Point::new(0.0, 0.0, -0.6)).unwrap();
    let robot = Robot {
        geometry: G,
        frame: JointFrame { home_rad: home.into(), counts_per_rad: 4096.0 * 12.0 / TAU },
    };
    let c = robot.counts_of(&Point::new(0.0, 0.0, -0.6)).unwrap();
    assert!(c.iter().all(|c| c.abs() < 1e-9), "{c:?}");
    // The notes: 7 823 counts per rad.
    assert_eq!((robot.frame.counts_per_rad).round(), 7823.0);
    let p = Point::new(0.1, -0.05, -0.58);
    let back = robot.point_of(&robot.counts_of(&p).unwrap()).unwrap();
    assert!((back - p).norm() < 1e-12);
    // The same in mm, both ways.
    let mm = robot.mm_of(&robot.counts_of_mm([100.0, -50.0, -580.0]).unwrap()).unwrap();
    assert!(mm.iter().zip([100.0, -50.0, -580.0]).all(|(a, b)| (a - b).abs() < 1e-9), "{mm:?}");
    assert_eq!(robot.counts_of_mm([100.0, -50.0, -580.0]).unwrap(), robot.counts_of(&p).unwrap());
}

#[test]
fn geometry_is_checked() {
    assert_eq!(G.check(), Ok(()));
    let bad = Geometry { rod_length_m: -0.7, ..G };
    assert_eq!(
        bad.check().unwrap_err().to_string(),
        "rod_length_m must be a finite length above 0 m, found -0.7"
    );
    let same = Geometry { arm_azimuth_rad: [0.0, TAU, 1.0], ..G };
    assert_eq!(same.check(), Err(GeometryError::Coincident(1, 2)));
}

proptest! {
    #[test]
    fn round_trips_anywhere_reachable(x in -0.25f64..0.25, y in -0.25f64..0.25, z in -0.85f64..-0.35) {
        let p = Point::new(x, y, z);
        if let Ok(theta) = G.inverse(&p) {
            prop_assert!(theta.iter().all(|t| t.is_finite()));
            let back = G.forward(&theta).unwrap();
            prop_assert!((back - p).norm() <= 1e-9, "{:?} → {:?}", p, back);
        }
    }
}

/// Issue 42: a point far out of reach is said in a few digits, not 309.
#[test]
fn a_point_far_out_of_reach_is_said_shortly() {
    assert_eq!(crate::mm(1e308), "1e308");
    assert_eq!(crate::mm(-2.5e9), "-2.5e9");
    assert_eq!(crate::mm(-600.04), "-600.0");
}

/// The drawing's joints are the robot's: the shoulder R from the axis at the arm's azimuth
/// on the base plane, the upper arm L long at θ below horizontal, the rod l long, the wrist r
/// from the effector centre toward the arm.
#[test]
fn the_joints_are_the_robots_links() {
    for p in workspace().step_by(37) {
        let theta = G.inverse(&p).unwrap();
        for i in 0..ARMS {
            let [shoulder, elbow, wrist] = G.joints(i, theta[i], &p);
            let (s, c) = G.arm_azimuth_rad[i].sin_cos();
            assert!((shoulder - Point::new(0.2 * c, 0.2 * s, 0.0)).norm() < 1e-12);
            assert!(((elbow - shoulder).norm() - 0.3).abs() < 1e-12);
            assert!(((elbow.z - shoulder.z) + 0.3 * theta[i].sin()).abs() < 1e-12);
            assert!(((wrist - elbow).norm() - 0.7).abs() < 1e-9, "arm {i} at {p:?}");
            assert!((wrist - p - Point::new(0.05 * c, 0.05 * s, 0.0)).norm() < 1e-12);
        }
    }
}
