//! What the robot says, as ROS 2 messages: a telemetry sample as `JointState` (arm angles in
//! the homed frame, rad) and the effector's `PointStamped` (m, through the forward
//! kinematics); the session's state as a `DiagnosticArray`; and back, a ROS target point as
//! the serve mode's move.

use crate::msgs::{
    DiagnosticArray, DiagnosticStatus, Header, JointState, JointTrajectory, KeyValue, Point,
    PointStamped, Time,
};
use qmarc_proto::telemetry::TelemetrySample;
use qmarc_proto::{MAX_MOTORS, Status};
use qmarc_session::wire::{MAX_PATH_KNOTS, PathKnot, PathRequest};

/// The frame the effector's point is in: the Delta's base.
pub const BASE_FRAME: &str = "base";

/// What the bridge knows of the robot to convert its samples.
#[derive(Debug, Clone, Copy)]
pub struct Converter {
    /// Motors driven.
    pub n_motors: usize,
    /// Encoder counts per arm radian.
    pub counts_per_rad: f64,
    /// The Delta, for the effector's point (none: not a Delta).
    pub robot: Option<qmarc_kinematics::Robot>,
}

impl Converter {
    /// The joint names: `motor1` … `motorN`.
    pub fn names(&self) -> Vec<String> {
        crate::msgs::motor_names(self.n_motors)
    }

    /// `s` as joint states stamped `stamp`: positions in rad from home, velocities in rad/s
    /// from the sample before (`prev`, none: 0), efforts the DAC's volts.
    pub fn joint_state(
        &self,
        s: &TelemetrySample,
        prev: Option<&TelemetrySample>,
        stamp: Time,
    ) -> JointState {
        let n = self.n_motors.min(MAX_MOTORS);
        JointState {
            header: Header { stamp, frame_id: String::new() },
            name: self.names(),
            position: self.rad(&s.act),
            velocity: self.rad(&rate(&s.act, prev.map(|p| &p.act), seconds_between(s, prev))),
            effort: (0..n).map(|m| qmarc_proto::dac_volts(s.dac[m])).collect(),
        }
    }

    /// The first `n_motors` of `counts` (or counts/s), in rad (or rad/s).
    pub fn rad(&self, counts: &[f64; MAX_MOTORS]) -> Vec<f64> {
        counts[..self.n_motors.min(MAX_MOTORS)].iter().map(|c| c / self.counts_per_rad).collect()
    }

    /// The motor (0-based) the joint `name` is: `motor1` … `motorN`, exactly.
    pub fn motor_of(&self, name: &str) -> Option<usize> {
        name.strip_prefix("motor")
            .and_then(|k| k.parse::<usize>().ok())
            .filter(|&k| (1..=self.n_motors).contains(&k) && name == format!("motor{k}"))
            .map(|k| k - 1)
    }

    /// The motor each of `names` is (0-based), if they are `motor1`…`motorN`, each once, in
    /// any order.
    pub fn joints_of(&self, names: &[String]) -> Result<Vec<usize>, String> {
        let expected = self.names().join(", ");
        let wrong = || format!("joint_names must be {expected}, each once; found {names:?}");
        if names.len() != self.n_motors {
            return Err(wrong());
        }
        let mut seen = vec![false; self.n_motors];
        let mut motors = Vec::with_capacity(names.len());
        for name in names {
            let m = self.motor_of(name).ok_or_else(wrong)?;
            if std::mem::replace(&mut seen[m], true) {
                return Err(wrong());
            }
            motors.push(m);
        }
        Ok(motors)
    }

    /// A ROS joint trajectory (rad, rad/s, time from its start) as the path the controller
    /// follows (counts, counts/s): its joints checked, its sizes bounded, its numbers finite.
    /// The controller checks the rest (times rising, the limits, the end at rest).
    pub fn path(&self, t: &JointTrajectory) -> Result<Box<PathRequest>, String> {
        let motors = self.joints_of(&t.joint_names)?;
        let n = motors.len();
        if t.points.is_empty() || t.points.len() > MAX_PATH_KNOTS {
            return Err(format!(
                "a trajectory has 1 to {MAX_PATH_KNOTS} points, found {}",
                t.points.len()
            ));
        }
        let velocities = !t.points[0].velocities.is_empty();
        let mut knots = Vec::with_capacity(t.points.len());
        for (i, p) in t.points.iter().enumerate() {
            let point = i + 1;
            let sizes_ok = p.positions.len() == n
                && p.velocities.len() == if velocities { n } else { 0 }
                && (p.accelerations.is_empty() || p.accelerations.len() == n);
            if !sizes_ok {
                return Err(format!(
                    "point {point}: {n} positions, {n} velocities on every point or on none, \
                     {n} accelerations or none; found {}, {}, {}",
                    p.positions.len(),
                    p.velocities.len(),
                    p.accelerations.len()
                ));
            }
            if let Some(v) = p.positions.iter().chain(&p.velocities).find(|v| !v.is_finite()) {
                return Err(format!("point {point}: the numbers must be finite, found {v}"));
            }
            let d = p.time_from_start;
            if d.sec < 0 || d.nanosec >= 1_000_000_000 {
                return Err(format!(
                    "point {point}: time_from_start must be ≥ 0 with nanosec < 1e9, found {} s {} ns",
                    d.sec, d.nanosec
                ));
            }
            let mut k = PathKnot {
                t_s: f64::from(d.sec) + f64::from(d.nanosec) * 1e-9,
                ..PathKnot::default()
            };
            for (j, &m) in motors.iter().enumerate() {
                k.pos[m] = p.positions[j] * self.counts_per_rad;
                if velocities {
                    k.vel[m] = p.velocities[j] * self.counts_per_rad;
                }
            }
            knots.push(k);
        }
        PathRequest::new(&knots, velocities).ok_or_else(|| "too many points".to_string())
    }

    /// Where the effector of `s` is, m, in the base frame (none: not a Delta, or no point).
    pub fn effector(&self, s: &TelemetrySample, stamp: Time) -> Option<PointStamped> {
        let p = self.robot?.point_of(&[s.act[0], s.act[1], s.act[2]]).ok()?;
        if !(p.x.is_finite() && p.y.is_finite() && p.z.is_finite()) {
            return None;
        }
        Some(PointStamped {
            header: Header { stamp, frame_id: BASE_FRAME.into() },
            point: Point { x: p.x, y: p.y, z: p.z },
        })
    }
}

/// Seconds from sample `prev` to `s` (0: none before, or not before).
pub fn seconds_between(s: &TelemetrySample, prev: Option<&TelemetrySample>) -> f64 {
    prev.map_or(0.0, |p| s.time_ns.saturating_sub(p.time_ns) as f64 * 1e-9)
}

/// How fast each of `now` changed since `prev`, `dt` seconds before: per second (0 without
/// a `prev` or a time between).
pub fn rate(
    now: &[f64; MAX_MOTORS],
    prev: Option<&[f64; MAX_MOTORS]>,
    dt: f64,
) -> [f64; MAX_MOTORS] {
    match prev {
        Some(p) if dt > 0.0 => std::array::from_fn(|m| (now[m] - p[m]) / dt),
        _ => [0.0; MAX_MOTORS],
    }
}

/// The session as the diagnostics say it.
#[derive(Debug, Clone, PartialEq, Eq, Default)]
pub struct SessionState {
    /// The loop's phase (`Phase` name), or `gone`.
    pub phase: String,
    /// The fault that ended it, and its words (empty: none).
    pub fault: String,
    /// Every motor homed.
    pub homed: bool,
    /// The emergency stop is latched.
    pub estop: bool,
    /// The last command refused, and why (empty: none).
    pub refused: String,
    /// A conveyor session's parts: queued, picked, missed (none outside one).
    pub parts: Option<[u32; 3]>,
}

impl SessionState {
    /// The state a sample shows (the phase, the fault, the e-stop bit) with what the command
    /// service said (homed) and the bridge saw (a refusal).
    pub fn of(s: &TelemetrySample, homed: bool, refused: &str) -> SessionState {
        use qmarc_proto::state::{FaultKind, Phase};
        SessionState {
            phase: Phase::from_wire(s.phase).map_or("unknown", Phase::name_serving).to_string(),
            fault: FaultKind::from_wire(s.fault).map_or(String::new(), |f| f.to_string()),
            homed,
            estop: Status(s.status).intersects(Status::ESTOP),
            refused: refused.to_string(),
            parts: None,
        }
    }

    /// As a `DiagnosticArray` of one status, `qmarc`, for hardware `hardware_id`.
    pub fn diagnostics(&self, hardware_id: &str, stamp: Time) -> DiagnosticArray {
        let level = if !self.fault.is_empty() || self.estop {
            DiagnosticStatus::ERROR
        } else if !self.homed || !self.refused.is_empty() {
            DiagnosticStatus::WARN
        } else {
            DiagnosticStatus::OK
        };
        let message = match (self.fault.as_str(), self.estop) {
            ("", true) => "emergency stop".to_string(),
            ("", false) if !self.refused.is_empty() => format!("refused: {}", self.refused),
            ("", false) => self.phase.clone(),
            (f, _) => format!("fault: {f}"),
        };
        let kv = |k: &str, v: String| KeyValue { key: k.into(), value: v };
        let mut values = vec![
            kv("phase", self.phase.clone()),
            kv("fault", self.fault.clone()),
            kv("homed", self.homed.to_string()),
            kv("estop", self.estop.to_string()),
            kv("refused", self.refused.clone()),
        ];
        if let Some([queued, picked, missed]) = self.parts {
            values.push(kv("queued", queued.to_string()));
            values.push(kv("picked", picked.to_string()));
            values.push(kv("missed", missed.to_string()));
        }
        DiagnosticArray {
            header: Header { stamp, frame_id: String::new() },
            status: vec![DiagnosticStatus {
                level,
                name: "qmarc".into(),
                message,
                hardware_id: hardware_id.into(),
                values,
            }],
        }
    }
}

/// A ROS target point (m) as the effector point the serve mode moves to (mm), if its numbers
/// are finite and within `limit_m` of the base.
pub fn target_mm(p: &Point, limit_m: f64) -> Result<[f64; 3], String> {
    let v = [p.x, p.y, p.z];
    if v.iter().any(|c| !c.is_finite() || c.abs() > limit_m) {
        return Err(format!("target ({}, {}, {}) m: numbers within ±{limit_m} m", p.x, p.y, p.z));
    }
    Ok(v.map(|c| c * 1e3))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msgs::{Duration, JointTrajectoryPoint};

    fn converter() -> Converter {
        let s = qmarc_config::Settings::load(
            &std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml"),
            &qmarc_config::Names::any(),
        )
        .unwrap();
        Converter { n_motors: 3, counts_per_rad: s.counts_per_rad(), robot: s.robot() }
    }

    #[test]
    fn a_sample_is_joint_states_in_rad_and_the_effector_in_metres() {
        let c = converter();
        let counts = c.robot.unwrap().counts_of(&qmarc_kinematics::Point::new(0.02, -0.01, -0.64));
        let counts = counts.unwrap();
        let mut s = TelemetrySample {
            time_ns: 1_000_000,
            act: [counts[0], counts[1], counts[2], 0.0],
            dac: [8191, -4096, 0, 0],
            n_motors: 3,
            ..TelemetrySample::default()
        };
        let prev =
            TelemetrySample { time_ns: 0, act: [counts[0] - 16.0, counts[1], counts[2], 0.0], ..s };
        let js = c.joint_state(&s, Some(&prev), Time { sec: 3, nanosec: 4 });
        assert_eq!(js.name, ["motor1", "motor2", "motor3"]);
        assert!((js.position[0] - counts[0] / c.counts_per_rad).abs() < 1e-12);
        assert!((js.velocity[0] - 16.0 / c.counts_per_rad / 1e-3).abs() < 1e-9);
        assert_eq!((js.velocity[1], js.effort[0]), (0.0, 10.0));
        assert!((js.effort[1] + 5.0006).abs() < 1e-3);
        let p = c.effector(&s, Time::default()).unwrap();
        assert!((p.point.x - 0.02).abs() < 1e-9 && (p.point.z + 0.64).abs() < 1e-9);
        assert_eq!(p.header.frame_id, "base");
        s.act[2] = f64::NAN;
        assert_eq!(c.effector(&s, Time::default()), None, "no point: none published");
        let no_delta = Converter { robot: None, ..c };
        assert_eq!(no_delta.effector(&prev, Time::default()), None);
        assert_eq!(no_delta.joint_state(&s, None, Time::default()).velocity, [0.0; 3]);
        // A sample no later than the one before: no rate.
        assert_eq!(c.joint_state(&prev, Some(&s), Time::default()).velocity, [0.0; 3]);
    }

    #[test]
    fn the_diagnostics_say_the_worst_first() {
        let ok = SessionState { phase: "serving".into(), homed: true, ..SessionState::default() };
        let d = ok.diagnostics("sim", Time::default());
        assert_eq!((d.status[0].level, d.status[0].message.as_str()), (0, "serving"));
        let unhomed = SessionState { homed: false, ..ok.clone() };
        assert_eq!(unhomed.diagnostics("sim", Time::default()).status[0].level, 1);
        let refused = SessionState { refused: "unreachable: 0, 0, 0 mm".into(), ..ok.clone() };
        let d = refused.diagnostics("sim", Time::default());
        assert_eq!(
            (d.status[0].level, d.status[0].message.as_str()),
            (1, "refused: unreachable: 0, 0, 0 mm")
        );
        let estop = SessionState { estop: true, ..ok.clone() };
        assert_eq!(estop.diagnostics("sim", Time::default()).status[0].message, "emergency stop");
        let fault = SessionState { fault: "limit_switch".into(), estop: true, ..ok };
        let d = fault.diagnostics("sim", Time::default());
        assert_eq!((d.status[0].level, d.status[0].message.as_str()), (2, "fault: limit_switch"));
        assert_eq!(d.status[0].values[3], KeyValue { key: "estop".into(), value: "true".into() });
        assert_eq!(d.status[0].values.len(), 5, "no parts outside a conveyor session");
    }

    #[test]
    fn a_conveyor_session_says_its_parts() {
        let at_belt = SessionState {
            phase: "serving".into(),
            homed: true,
            parts: Some([2, 15, 1]),
            ..SessionState::default()
        };
        let d = at_belt.diagnostics("sim", Time::default());
        let value = |k: &str| {
            d.status[0].values.iter().find(|v| v.key == k).map(|v| v.value.clone()).unwrap()
        };
        assert_eq!(
            (value("queued"), value("picked"), value("missed")),
            ("2".into(), "15".into(), "1".into())
        );
        assert_eq!(d.status[0].level, 0, "parts missed are counted, not a fault");
    }

    fn point(
        positions: &[f64],
        velocities: &[f64],
        sec: i32,
        nanosec: u32,
    ) -> JointTrajectoryPoint {
        JointTrajectoryPoint {
            positions: positions.to_vec(),
            velocities: velocities.to_vec(),
            time_from_start: Duration { sec, nanosec },
            ..JointTrajectoryPoint::default()
        }
    }

    fn trajectory(names: &[&str], points: Vec<JointTrajectoryPoint>) -> JointTrajectory {
        JointTrajectory {
            joint_names: names.iter().map(|n| n.to_string()).collect(),
            points,
            ..JointTrajectory::default()
        }
    }

    #[test]
    fn a_joint_trajectory_is_a_path_in_counts_in_motor_order() {
        let c = converter();
        let k = c.counts_per_rad;
        let t = trajectory(
            &["motor3", "motor1", "motor2"],
            vec![
                point(&[0.1, 0.2, 0.3], &[1.0, 0.0, -1.0], 0, 500_000_000),
                point(&[0.0; 3], &[0.0; 3], 1, 0),
            ],
        );
        let p = c.path(&t).unwrap();
        assert!(p.has_velocities());
        assert_eq!(p.knots().len(), 2);
        let first = p.knots()[0];
        assert_eq!(first.t_s, 0.5);
        assert_eq!(first.pos[..3], [0.2 * k, 0.3 * k, 0.1 * k], "motor3's column is motor 3's");
        assert_eq!(first.vel[..3], [0.0, -k, k]);
        assert_eq!(p.knots()[1].t_s, 1.0);
        let no_velocities =
            trajectory(&["motor1", "motor2", "motor3"], vec![point(&[0.1, 0.2, 0.3], &[], 2, 1)]);
        let p = c.path(&no_velocities).unwrap();
        assert!(!p.has_velocities());
        assert_eq!(p.knots()[0].t_s, 2.000000001);
    }

    #[test]
    fn a_joint_trajectory_that_is_not_one_is_refused_saying_why() {
        let c = converter();
        let names = ["motor1", "motor2", "motor3"];
        let ok = || point(&[0.1, 0.2, 0.3], &[], 1, 0);
        let why = |t: JointTrajectory| c.path(&t).unwrap_err();
        for bad in [
            &["motor1", "motor2"][..],
            &["motor1", "motor2", "motor2"],
            &["motor1", "motor2", "motor4"],
            &["motor1", "motor2", "motor03"],
            &["a", "b", "c"],
        ] {
            assert!(
                why(trajectory(bad, vec![ok()]))
                    .contains("joint_names must be motor1, motor2, motor3, each once"),
                "{bad:?}"
            );
        }
        assert!(why(trajectory(&names, vec![])).contains("1 to 1024 points, found 0"));
        assert!(why(trajectory(&names, vec![ok(); 1025])).contains("found 1025"));
        let short = point(&[0.1, 0.2], &[], 1, 0);
        assert!(why(trajectory(&names, vec![short])).contains("point 1: 3 positions"));
        let some_velocities = vec![point(&[0.1, 0.2, 0.3], &[0.0; 3], 1, 0), ok()];
        assert!(
            why(trajectory(&names, some_velocities))
                .contains("point 2: 3 positions, 3 velocities on every point or on none")
        );
        let accelerations = JointTrajectoryPoint { accelerations: vec![0.0], ..ok() };
        assert!(why(trajectory(&names, vec![accelerations])).contains("found 3, 0, 1"));
        let nan = point(&[0.1, f64::NAN, 0.3], &[], 1, 0);
        assert!(
            why(trajectory(&names, vec![nan]))
                .contains("point 1: the numbers must be finite, found NaN")
        );
        assert!(
            why(trajectory(&names, vec![ok(), point(&[0.0; 3], &[], -1, 0)]))
                .contains("point 2: time_from_start must be ≥ 0")
        );
        assert!(
            why(trajectory(&names, vec![point(&[0.0; 3], &[], 0, 1_000_000_000)]))
                .contains("nanosec < 1e9")
        );
    }

    #[test]
    fn a_target_is_finite_and_near() {
        assert_eq!(
            target_mm(&Point { x: 0.02, y: -0.01, z: -0.64 }, 5.0),
            Ok([20.0, -10.0, -640.0])
        );
        assert!(target_mm(&Point { x: f64::NAN, y: 0.0, z: 0.0 }, 5.0).is_err());
        assert!(target_mm(&Point { x: 0.0, y: 0.0, z: -6.0 }, 5.0).is_err());
    }
}
