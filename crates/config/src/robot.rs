//! `[robot]`: the robot's geometry and its joint-count frame, for the Cartesian side of the
//! controller — `qmarc-starter path` and the end-effector report (`../shared/notes/deltabot.md`).
//! Optional: without the table nothing Cartesian is done.

use crate::ConfigLoadError;
use crate::source::{S, Source, positive, span_of};
use qmarc_kinematics::{ARMS, Geometry, GeometryError, JointFrame, Point, Robot};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use toml::Spanned;

/// The point a default `home_angle_deg` puts at 0 counts on every arm: the notes' work
/// centre, m.
pub const WORK_CENTRE_M: [f64; 3] = [0.0, 0.0, -0.6];

/// The robot: its dimensions and the arm angles its homed frame counts from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RobotSettings {
    /// Its dimensions.
    pub geometry: Geometry,
    /// θ_home per arm: the arm angle at which the homed frame reads 0, rad.
    pub home_rad: [f64; ARMS],
}

impl RobotSettings {
    /// The robot in the joint-count frame of `counts_per_rad`.
    pub fn robot(&self, counts_per_rad: f64) -> Robot {
        Robot {
            geometry: self.geometry,
            frame: JointFrame { home_rad: self.home_rad, counts_per_rad },
        }
    }
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(crate) struct RawRobot {
    base_radius_m: S<f64>,
    effector_radius_m: S<f64>,
    arm_length_m: S<f64>,
    rod_length_m: S<f64>,
    arm_azimuth_deg: S<Vec<f64>>,
    home_angle_deg: S<Vec<f64>>,
}

/// Three finite numbers.
fn three(v: &[f64]) -> Result<(), String> {
    if v.len() != ARMS {
        return Err(format!("one value per arm: {ARMS} numbers, found {}", v.len()));
    }
    match v.iter().find(|x| !x.is_finite()) {
        Some(bad) => Err(format!("must be finite numbers, found {bad}")),
        None => Ok(()),
    }
}

impl RawRobot {
    /// Checked; `table` is where the `[robot]` table is.
    pub(crate) fn check(
        &self,
        src: &Source<'_>,
        table: Range<usize>,
    ) -> Result<RobotSettings, ConfigLoadError> {
        let d = Geometry::ASSUMED;
        let deg = |r: [f64; ARMS]| r.map(f64::to_degrees).to_vec();
        let azimuth = src.take(
            &self.arm_azimuth_deg,
            "robot.arm_azimuth_deg",
            deg(d.arm_azimuth_rad),
            |v| three(v),
        )?;
        let geometry = Geometry {
            base_radius_m: src.take(
                &self.base_radius_m,
                "robot.base_radius_m",
                d.base_radius_m,
                positive,
            )?,
            effector_radius_m: src.take(
                &self.effector_radius_m,
                "robot.effector_radius_m",
                d.effector_radius_m,
                positive,
            )?,
            arm_length_m: src.take(
                &self.arm_length_m,
                "robot.arm_length_m",
                d.arm_length_m,
                positive,
            )?,
            rod_length_m: src.take(
                &self.rod_length_m,
                "robot.rod_length_m",
                d.rod_length_m,
                positive,
            )?,
            arm_azimuth_rad: std::array::from_fn(|i| azimuth[i].to_radians()),
        };
        if let Err(e) = geometry.check() {
            let (field, span) = match e {
                GeometryError::Length { field, .. } => (field, self.span_of_length(field)),
                _ => ("arm_azimuth_deg", span_of(&self.arm_azimuth_deg)),
            };
            return Err(src.invalid(span, &format!("robot.{field}"), e.to_string()));
        }
        let home_rad = match &self.home_angle_deg {
            Some(v) => {
                three(v.get_ref()).map_err(|m| src.invalid(v.span(), "robot.home_angle_deg", m))?;
                std::array::from_fn(|i| v.get_ref()[i].to_radians())
            }
            None => geometry.inverse(&Point::from(WORK_CENTRE_M)).map(Into::into).map_err(|e| {
                src.invalid(
                    table.clone(),
                    "robot.home_angle_deg",
                    format!(
                        "not set, and its default, the arm angles of the work centre (0, 0, −600) \
                         mm, does not exist: {e}; set home_angle_deg"
                    ),
                )
            })?,
        };
        let robot = RobotSettings { geometry, home_rad };
        // The homed frame must be a pose of this robot.
        if let Err(e) = geometry.forward(&home_rad.into()) {
            return Err(src.invalid(
                self.home_angle_deg.as_ref().map_or(table, Spanned::span),
                "robot.home_angle_deg",
                format!("the homed frame is no pose of this robot: {e}"),
            ));
        }
        Ok(robot)
    }

    fn span_of_length(&self, field: &str) -> Range<usize> {
        span_of(match field {
            "base_radius_m" => &self.base_radius_m,
            "effector_radius_m" => &self.effector_radius_m,
            "arm_length_m" => &self.arm_length_m,
            _ => &self.rod_length_m,
        })
    }
}
