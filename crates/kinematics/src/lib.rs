//! Kinematics of the Deltabot, a Clavel Delta (3-RSS) while its cables are taut
//! (`../shared/notes/deltabot.md`): the closed-form inverse ([`Geometry::inverse`]), the
//! forward solution by trilateration ([`Geometry::forward`]), the Jacobian
//! ([`Geometry::jacobian`]), and the frame between arm angles and joint counts
//! ([`JointFrame`]). Everything is on nalgebra's fixed-size types and allocates nothing; a
//! point that has no answer is an error naming the arm, never a NaN.
//!
//! Conventions: z up, origin at the base centre, the effector below it (z < 0); arm i sits at
//! azimuth φᵢ; θᵢ is the arm angle from horizontal, positive with the arm tip below the base;
//! the elbow-out branch.
//!
//! ```
//! use qmarc_kinematics::{Geometry, Point};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let g = Geometry::ASSUMED;
//! let theta = g.inverse(&Point::new(0.0, 0.0, -0.6))?;
//! assert!((theta[0].to_degrees() - 11.3332).abs() < 1e-4);
//! let p = g.forward(&theta)?;
//! assert!((p - Point::new(0.0, 0.0, -0.6)).norm() < 1e-12);
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

mod frame;
#[cfg(test)]
mod tests;

pub use frame::{JointFrame, Robot};

use nalgebra::{Matrix3, Vector3};
use serde::{Deserialize, Serialize};
use std::f64::consts::{PI, TAU};

/// The Delta has three arms.
pub const ARMS: usize = 3;

/// A point of the effector centre, m.
pub type Point = Vector3<f64>;
/// The three arm angles, rad.
pub type Angles = Vector3<f64>;

/// Below this |sᵢ·bᵢ| / (|sᵢ|·|bᵢ|), an arm is taken as singular: its cable is within about
/// 0.06° of the arm's own direction, where a finite effector speed needs an unbounded arm
/// speed.
pub const SINGULAR_COSINE: f64 = 1e-3;
/// Below this |det[s₁ s₂ s₃]| / (|s₁|·|s₂|·|s₃|), the three cables are taken as coplanar:
/// the effector can move across their plane with the arms still.
pub const COPLANAR_SINE: f64 = 1e-3;

/// A length in mm as a person reads it: to a tenth, or in exponent notation where that would
/// be a wall of digits (1e308 is 309 of them).
pub fn mm(x: f64) -> String {
    if x.is_finite() && x.abs() >= 1e7 {
        let short = format!("{x:.3e}");
        match short.split_once('e') {
            Some((m, e)) => format!("{}e{e}", m.trim_end_matches('0').trim_end_matches('.')),
            None => short,
        }
    } else {
        format!("{x:.1}")
    }
}

/// A point or pose the kinematics cannot answer. Arms are 1-based.
#[derive(Debug, Clone, Copy, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum KinematicsError {
    /// No arm angle puts the effector there: the point is out of the arm's reach.
    #[error(
        "arm {arm} cannot reach ({}, {}, {}) mm: the point is out of its reach",
        mm(point[0] * 1e3), mm(point[1] * 1e3), mm(point[2] * 1e3)
    )]
    Unreachable {
        /// 1-based arm.
        arm: u8,
        /// The point, m.
        point: [f64; 3],
    },
    /// The arm and its cable are aligned: the arm cannot move the effector along the cable.
    #[error(
        "arm {arm} is singular at ({:.1}, {:.1}, {:.1}) mm: its cable is aligned with the arm",
        point[0] * 1e3, point[1] * 1e3, point[2] * 1e3
    )]
    Singular {
        /// 1-based arm.
        arm: u8,
        /// The point, m.
        point: [f64; 3],
    },
    /// The three cables lie in one plane: the effector can move with the arms still.
    #[error(
        "the cables are coplanar at ({:.1}, {:.1}, {:.1}) mm: the pose is singular",
        point[0] * 1e3, point[1] * 1e3, point[2] * 1e3
    )]
    Coplanar {
        /// The point, m.
        point: [f64; 3],
    },
    /// The three cable spheres of these arm angles do not meet: no pose has them.
    #[error(
        "no pose has the arm angles ({:.4}°, {:.4}°, {:.4}°): the cables cannot all reach one point",
        angles_deg[0], angles_deg[1], angles_deg[2]
    )]
    NoPose {
        /// The arm angles, degrees.
        angles_deg: [f64; 3],
    },
    /// A coordinate or angle is not a finite number.
    #[error("a coordinate or angle is not a finite number")]
    NotFinite,
}

/// The geometry was refused.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum GeometryError {
    /// A length is not finite and positive.
    #[error("{field} must be a finite length above 0 m, found {value}")]
    Length {
        /// Which length.
        field: &'static str,
        /// Its value.
        value: f64,
    },
    /// An azimuth is not finite.
    #[error("arm_azimuth_deg must be finite, found {0}")]
    Azimuth(f64),
    /// Two arms share an azimuth (less than 1° apart), which no Delta has.
    #[error("arms {0} and {1} are less than 1° apart")]
    Coincident(u8, u8),
}

/// The dimensions of a Delta robot (the notes' notation: R, r, L, l, φᵢ).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Geometry {
    /// R: base centre to each motor axis, m.
    pub base_radius_m: f64,
    /// r: effector centre to each cable pair's midpoint, m.
    pub effector_radius_m: f64,
    /// L: upper arm, m.
    pub arm_length_m: f64,
    /// l: cable parallelogram, m.
    pub rod_length_m: f64,
    /// φᵢ: azimuth of each arm about z, rad.
    pub arm_azimuth_rad: [f64; ARMS],
}

impl Geometry {
    /// The notes' assumed Deltabot (its real dimensions are not public): R 0.2 m, r 0.05 m,
    /// L 0.3 m, l 0.7 m, arms at 0°, 120°, 240°.
    pub const ASSUMED: Geometry = Geometry {
        base_radius_m: 0.2,
        effector_radius_m: 0.05,
        arm_length_m: 0.3,
        rod_length_m: 0.7,
        arm_azimuth_rad: [0.0, 120f64.to_radians(), 240f64.to_radians()],
    };

    /// Checks the numbers: every length finite and positive, arms at distinct azimuths.
    pub fn check(&self) -> Result<(), GeometryError> {
        for (field, value) in [
            ("base_radius_m", self.base_radius_m),
            ("effector_radius_m", self.effector_radius_m),
            ("arm_length_m", self.arm_length_m),
            ("rod_length_m", self.rod_length_m),
        ] {
            if !(value.is_finite() && value > 0.0) {
                return Err(GeometryError::Length { field, value });
            }
        }
        if let Some(&bad) = self.arm_azimuth_rad.iter().find(|a| !a.is_finite()) {
            return Err(GeometryError::Azimuth(bad.to_degrees()));
        }
        for i in 0..ARMS {
            for j in i + 1..ARMS {
                let d = (self.arm_azimuth_rad[i] - self.arm_azimuth_rad[j]).rem_euclid(TAU);
                if d.min(TAU - d) < 1f64.to_radians() {
                    return Err(GeometryError::Coincident(i as u8 + 1, j as u8 + 1));
                }
            }
        }
        Ok(())
    }

    /// uᵢ: the unit vector from the base centre toward arm i.
    fn u(&self, i: usize) -> Vector3<f64> {
        let phi = self.arm_azimuth_rad[i];
        Vector3::new(phi.cos(), phi.sin(), 0.0)
    }

    /// Jᵢ: the elbow of arm i at angle θ.
    fn elbow(&self, i: usize, theta: f64) -> Vector3<f64> {
        let l = self.arm_length_m;
        (self.base_radius_m + l * theta.cos()) * self.u(i) - l * theta.sin() * Vector3::z()
    }

    /// Arm i's three joints with the arm at `theta` and the effector centre at `p`, m: the
    /// shoulder (the motor's axis, on the base), the elbow (the upper arm's tip, where the
    /// cable pair hangs) and the wrist (the pair's midpoint on the effector). The drawing of
    /// the robot; elbow to wrist is the rod length where `p` is the forward solution.
    pub fn joints(&self, i: usize, theta: f64, p: &Point) -> [Point; 3] {
        let u = self.u(i);
        [self.base_radius_m * u, self.elbow(i, theta), p + self.effector_radius_m * u]
    }

    /// The arm angles that put the effector centre at `p` (closed form, elbow out).
    pub fn inverse(&self, p: &Point) -> Result<Angles, KinematicsError> {
        if !p.iter().all(|v| v.is_finite()) {
            return Err(KinematicsError::NotFinite);
        }
        let (l_arm, l_rod) = (self.arm_length_m, self.rod_length_m);
        let a = self.base_radius_m - self.effector_radius_m;
        let mut theta = Angles::zeros();
        for i in 0..ARMS {
            let (s, c) = self.arm_azimuth_rad[i].sin_cos();
            let xi = p.x * c + p.y * s;
            let yi = -p.x * s + p.y * c;
            let e = 2.0 * l_arm * (a - xi);
            let f = 2.0 * l_arm * p.z;
            let g = (xi - a).powi(2) + yi * yi + p.z * p.z + l_arm * l_arm - l_rod * l_rod;
            let norm = e.hypot(f);
            if norm == 0.0 || g.abs() > norm {
                return Err(KinematicsError::Unreachable { arm: i as u8 + 1, point: (*p).into() });
            }
            theta[i] = f.atan2(e) + (-g / norm).acos();
        }
        // One branch for every angle: (−π, π].
        Ok(theta.map(|t| if t > PI { t - TAU } else { t }))
    }

    /// Where the effector centre is with the arms at `theta`: the lower intersection of the
    /// three cable spheres.
    pub fn forward(&self, theta: &Angles) -> Result<Point, KinematicsError> {
        if !theta.iter().all(|v| v.is_finite()) {
            return Err(KinematicsError::NotFinite);
        }
        let no_pose = || KinematicsError::NoPose { angles_deg: theta.map(f64::to_degrees).into() };
        let r = self.effector_radius_m;
        let c: [Vector3<f64>; ARMS] =
            std::array::from_fn(|i| self.elbow(i, theta[i]) - r * self.u(i));
        let d = (c[1] - c[0]).norm();
        if d < f64::EPSILON * self.rod_length_m {
            return Err(no_pose());
        }
        let ex = (c[1] - c[0]) / d;
        let i = ex.dot(&(c[2] - c[0]));
        let across = c[2] - c[0] - i * ex;
        let across_norm = across.norm();
        if across_norm < f64::EPSILON * self.rod_length_m {
            return Err(no_pose());
        }
        let ey = across / across_norm;
        let j = ey.dot(&(c[2] - c[0]));
        let ez = ex.cross(&ey);
        let x = d / 2.0;
        let y = (i * i + j * j - 2.0 * i * x) / (2.0 * j);
        let z2 = self.rod_length_m.powi(2) - x * x - y * y;
        if z2 < 0.0 || z2.is_nan() {
            return Err(no_pose());
        }
        let z = z2.sqrt();
        let base = c[0] + x * ex + y * ey;
        let (up, down) = (base + z * ez, base - z * ez);
        Ok(if up.z < down.z { up } else { down })
    }

    /// J with θ̇ = J·Ṗ at the pose (`p`, `theta`) (`theta` = [`Geometry::inverse`] of `p`):
    /// from [s₁ s₂ s₃]ᵀ·Ṗ = diag(sᵢ·bᵢ)·θ̇, sᵢ = P + r·uᵢ − Jᵢ, bᵢ = ∂Jᵢ/∂θᵢ.
    pub fn jacobian(&self, p: &Point, theta: &Angles) -> Result<Matrix3<f64>, KinematicsError> {
        if !(p.iter().chain(theta.iter()).all(|v| v.is_finite())) {
            return Err(KinematicsError::NotFinite);
        }
        let l = self.arm_length_m;
        // sᵢ: from each elbow to its cable's end on the effector.
        let s: [Vector3<f64>; ARMS] = std::array::from_fn(|i| {
            p + self.effector_radius_m * self.u(i) - self.elbow(i, theta[i])
        });
        let mut rows = Matrix3::zeros();
        for (i, si) in s.iter().enumerate() {
            let b = l * (-theta[i].sin() * self.u(i) - theta[i].cos() * Vector3::z());
            let sb = si.dot(&b);
            if sb.abs() < SINGULAR_COSINE * si.norm() * b.norm() {
                return Err(KinematicsError::Singular { arm: i as u8 + 1, point: (*p).into() });
            }
            rows.set_row(i, &(si.transpose() / sb));
        }
        let det = Matrix3::from_columns(&s).determinant();
        if det.abs() < COPLANAR_SINE * s.iter().map(|si| si.norm()).product::<f64>() {
            return Err(KinematicsError::Coplanar { point: (*p).into() });
        }
        Ok(rows)
    }
}
