//! The Cartesian side of a move's report (thesis 5.2): the end-effector error, command
//! against actual through the forward kinematics, and the arms' error figures over the
//! gathered rows only — the thesis summed its Table 5-2 over data gathered every 4th cycle,
//! so these compare with it like for like.

use crate::figures::MotorSummary;
use qmarc_controller::gather::GatherRow;
use qmarc_controller::stats::{AxisErrors, ErrorStats};
use qmarc_kinematics::{ARMS, Robot};
use serde::{Deserialize, Serialize};

/// One axis of the end-effector error (command − actual), mm.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct AxisMm {
    /// Smallest.
    #[serde(deserialize_with = "crate::figures::figure")]
    pub min_mm: f64,
    /// Largest.
    #[serde(deserialize_with = "crate::figures::figure")]
    pub max_mm: f64,
    /// Root mean square.
    #[serde(deserialize_with = "crate::figures::figure")]
    pub rms_mm: f64,
    /// Largest magnitude.
    #[serde(deserialize_with = "crate::figures::figure")]
    pub max_abs_mm: f64,
}

impl AxisMm {
    fn of(e: &AxisErrors) -> AxisMm {
        let n = e.count.max(1) as f64;
        AxisMm {
            min_mm: e.min,
            max_mm: e.max,
            rms_mm: (e.sum_sq / n).sqrt(),
            max_abs_mm: e.min.abs().max(e.max.abs()),
        }
    }
}

/// `"effector"` in `summary.json`: the end-effector error over the gathered rows of the path.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct EffectorSummary {
    /// Gathered rows of the path it is computed over.
    pub rows: u64,
    /// Rows whose command or actual arm angles have no pose (left out).
    pub no_pose_rows: u64,
    /// x, mm.
    pub x: AxisMm,
    /// y, mm.
    pub y: AxisMm,
    /// z, mm.
    pub z: AxisMm,
    /// |command − actual|, mm: `min_mm` is the smallest distance, `rms_mm` and `max_mm` as
    /// named (`max_abs_mm` equals `max_mm`).
    pub distance: AxisMm,
}

/// The end-effector error of `rows` (the path's gathered rows) on `robot`.
pub fn effector<'a>(robot: &Robot, rows: impl Iterator<Item = &'a GatherRow>) -> EffectorSummary {
    let mut axes = [AxisErrors::default(); 4];
    let mut s = EffectorSummary::default();
    for r in rows {
        s.rows += 1;
        let arm = |v: &[f64]| -> [f64; ARMS] { std::array::from_fn(|i| v[i]) };
        let (Ok(cmd), Ok(act)) = (robot.point_of(&arm(&r.cmd)), robot.point_of(&arm(&r.act)))
        else {
            s.no_pose_rows += 1;
            continue;
        };
        let e = (cmd - act) * 1e3;
        for k in 0..3 {
            axes[k].add(e[k]);
        }
        axes[3].add(e.norm());
    }
    [s.x, s.y, s.z, s.distance] = axes.each_ref().map(AxisMm::of);
    s
}

/// `"gathered"` in `summary.json`: each motor's error figures over the gathered rows of the
/// path only (every `every`-th cycle).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct GatheredErrors {
    /// Gathered every this many cycles.
    pub every: u32,
    /// Rows of the path.
    pub rows: u64,
    /// Per motor.
    pub motors: Vec<MotorSummary>,
}

/// The figures of `rows` for `n_motors`, `counts_per_rad` to convert.
pub fn gathered<'a>(
    rows: impl Iterator<Item = &'a GatherRow>,
    n_motors: usize,
    counts_per_rad: f64,
    every: u32,
) -> GatheredErrors {
    // The loop's own accumulator, over the gathered rows.
    let mut errors = ErrorStats::default();
    for r in rows {
        errors.add(n_motors, &r.cmd, &r.act);
    }
    let axes = &errors.axes[..n_motors];
    GatheredErrors {
        every,
        rows: axes.first().map_or(0, |a| a.count),
        motors: axes.iter().map(|a| MotorSummary::new(a, counts_per_rad)).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qmarc_kinematics::{Geometry, JointFrame, Point};

    fn robot() -> Robot {
        let home = Geometry::ASSUMED.inverse(&Point::new(0.0, 0.0, -0.6)).unwrap();
        Robot {
            geometry: Geometry::ASSUMED,
            frame: JointFrame { home_rad: home.into(), counts_per_rad: 7822.78 },
        }
    }

    fn row(cmd: [f64; 3], act: [f64; 3]) -> GatherRow {
        let mut r = GatherRow {
            cycle: 0,
            time_s: 0.0,
            cmd: [0.0; 4],
            act: [0.0; 4],
            dac: [0; 4],
            grip: 0,
            conv: 0,
        };
        r.cmd[..3].copy_from_slice(&cmd);
        r.act[..3].copy_from_slice(&act);
        r
    }

    #[test]
    fn the_effector_error_is_command_minus_actual_through_the_forward_kinematics() {
        let robot = robot();
        // The actual point 1 mm below the command on the axis, 2 mm beside it elsewhere.
        let a = robot.counts_of(&Point::new(0.0, 0.0, -0.6)).unwrap();
        let b = robot.counts_of(&Point::new(0.0, 0.0, -0.601)).unwrap();
        let c = robot.counts_of(&Point::new(0.05, 0.0, -0.6)).unwrap();
        let d = robot.counts_of(&Point::new(0.05, 0.002, -0.6)).unwrap();
        let s = effector(&robot, [row(a, b), row(c, d)].iter());
        assert_eq!((s.rows, s.no_pose_rows), (2, 0));
        let close = |x: f64, y: f64| (x - y).abs() < 1e-9;
        assert!(close(s.z.max_mm, 1.0) && close(s.z.min_mm, 0.0), "{:?}", s.z);
        assert!(close(s.y.min_mm, -2.0) && close(s.y.max_abs_mm, 2.0), "{:?}", s.y);
        assert!(close(s.distance.max_mm, 2.0) && close(s.distance.rms_mm, (2.5f64).sqrt()));
        // Arm angles no pose has are counted, not summed.
        let short = Robot {
            geometry: Geometry { rod_length_m: 0.1, ..Geometry::ASSUMED },
            frame: JointFrame { home_rad: [0.0; 3], counts_per_rad: 7822.78 },
        };
        let s = effector(&short, [row([0.0; 3], [0.0; 3])].iter());
        assert_eq!((s.rows, s.no_pose_rows), (1, 1));
    }

    #[test]
    fn gathered_figures_sum_the_rows() {
        let rows = [row([2.0, 0.0, 0.0], [0.0; 3]), row([0.0, 0.0, 0.0], [1.0, 0.0, 0.0])];
        let g = gathered(rows.iter(), 3, 1.0, 4);
        assert_eq!((g.every, g.rows), (4, 2));
        assert_eq!((g.motors[0].min_error_counts, g.motors[0].max_error_counts), (-1.0, 2.0));
        assert_eq!(
            (g.motors[0].accumulated_abs_error_counts, g.motors[0].sum_squares_error_counts2),
            (3.0, 5.0)
        );
    }
}
