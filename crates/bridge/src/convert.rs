//! What the robot says, as ROS 2 messages: a telemetry sample as `JointState` (arm angles in
//! the homed frame, rad) and the effector's `PointStamped` (m, through the forward
//! kinematics); the session's state as a `DiagnosticArray`; and back, a ROS target point as
//! the serve mode's move.

use crate::msgs::{
    DiagnosticArray, DiagnosticStatus, Header, JointState, KeyValue, Point, PointStamped, Time,
};
use qmarc_proto::telemetry::TelemetrySample;
use qmarc_proto::{DAC_FULL_SCALE_V, DAC_MAX, MAX_MOTORS, Status};

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
        (1..=self.n_motors).map(|m| format!("motor{m}")).collect()
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
        let rad = |c: f64| c / self.counts_per_rad;
        let dt = prev.map_or(0.0, |p| s.time_ns.saturating_sub(p.time_ns) as f64 * 1e-9);
        let velocity = (0..n)
            .map(|m| match prev {
                Some(p) if dt > 0.0 => rad(s.act[m] - p.act[m]) / dt,
                _ => 0.0,
            })
            .collect();
        JointState {
            header: Header { stamp, frame_id: String::new() },
            name: self.names(),
            position: (0..n).map(|m| rad(s.act[m])).collect(),
            velocity,
            effort: (0..n)
                .map(|m| f64::from(s.dac[m]) * DAC_FULL_SCALE_V / f64::from(DAC_MAX))
                .collect(),
        }
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
}

impl SessionState {
    /// The state a sample shows (the phase, the fault, the e-stop bit) with what the command
    /// service said (homed) and the bridge saw (a refusal).
    pub fn of(s: &TelemetrySample, homed: bool, refused: &str) -> SessionState {
        use qmarc_proto::state::{FaultKind, Phase};
        SessionState {
            phase: Phase::from_code(s.phase).map_or("unknown", Phase::name).to_string(),
            fault: FaultKind::from_wire(s.fault).map_or(String::new(), |f| f.to_string()),
            homed,
            estop: Status(s.status).intersects(Status::ESTOP),
            refused: refused.to_string(),
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
        DiagnosticArray {
            header: Header { stamp, frame_id: String::new() },
            status: vec![DiagnosticStatus {
                level,
                name: "qmarc".into(),
                message,
                hardware_id: hardware_id.into(),
                values: vec![
                    kv("phase", self.phase.clone()),
                    kv("fault", self.fault.clone()),
                    kv("homed", self.homed.to_string()),
                    kv("estop", self.estop.to_string()),
                    kv("refused", self.refused.clone()),
                ],
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
    }

    #[test]
    fn the_diagnostics_say_the_worst_first() {
        let ok = SessionState { phase: "moving".into(), homed: true, ..SessionState::default() };
        let d = ok.diagnostics("sim", Time::default());
        assert_eq!((d.status[0].level, d.status[0].message.as_str()), (0, "moving"));
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
