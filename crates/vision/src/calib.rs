//! [`Calibration`]: from a frame's pixels to belt coordinates — the lens' radial distortion
//! undone, then a homography onto the belt's surface — fitted to the dots of a target lying
//! on the belt, and written to (read from) the file `[camera] calibration` names.
//!
//! Undistorted pixel = c + (p − c)·(1 + k₁ρ² + k₂ρ⁴), ρ = |p − c| / `radius_px` (c the
//! frame's centre, `radius_px` half its diagonal). The homography is the linear fit of the
//! undistorted dots to their belt points (normalised DLT), the two k the Nelder–Mead
//! search (argmin) of the smallest residual around it.

use argmin::core::{CostFunction, Executor};
use argmin::solver::neldermead::NelderMead;
use nalgebra::{Matrix3, SMatrix, Vector3};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// How the fit did: the dots against where the calibration puts their belt points.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Reprojection {
    /// Mean and largest distance in the frame, px.
    pub mean_px: f64,
    /// See `mean_px`.
    pub max_px: f64,
    /// Mean and largest distance on the belt, mm.
    pub mean_mm: f64,
    /// See `mean_mm`.
    pub max_mm: f64,
}

/// Pixels to belt coordinates.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Calibration {
    /// The frames' columns and rows it holds for.
    pub image_px: [u32; 2],
    /// The distortion's centre, px.
    pub centre_px: [f64; 2],
    /// The distortion's unit radius, px.
    pub radius_px: f64,
    /// k₁, k₂.
    pub k: [f64; 2],
    /// Undistorted pixel (u, v, 1) → belt (along, across, w) mm, row by row.
    pub homography: [[f64; 3]; 3],
    /// How the fit did.
    pub reprojection: Reprojection,
}

/// Why a calibration could not be fitted or read.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum CalibrationError {
    /// Too few points, or all on a line.
    #[error("the calibration cannot be fitted: {0}")]
    Degenerate(String),
    /// The file could not be read.
    #[error("{file}: cannot read the calibration: {reason}")]
    Read {
        /// The file.
        file: std::path::PathBuf,
        /// Why.
        reason: std::io::Error,
    },
    /// The file is not a calibration (its line, column and field).
    #[error("{0}")]
    Invalid(qmarc_config::ConfigLoadError),
    /// The file reads, but a value cannot be a calibration's.
    #[error("{file}: {field}: {reason}")]
    Bad {
        /// The file.
        file: std::path::PathBuf,
        /// The field.
        field: &'static str,
        /// Why.
        reason: String,
    },
}

impl Calibration {
    /// The calibration that puts each of `pixels` (dots found in a frame of `image_px`) on
    /// the belt point of the same index in `belt` (mm).
    pub fn fit(
        pixels: &[[f64; 2]],
        belt: &[[f64; 2]],
        image_px: [u32; 2],
    ) -> Result<Calibration, CalibrationError> {
        if pixels.len() != belt.len() || pixels.len() < 6 {
            let n = pixels.len().min(belt.len());
            return Err(CalibrationError::Degenerate(format!("{n} points, 6 at least")));
        }
        if flatness(pixels) < 1e-6 || flatness(belt) < 1e-6 {
            return Err(CalibrationError::Degenerate("the points lie on a line".into()));
        }
        let [w, h] = image_px.map(f64::from);
        let centre_px = [(w - 1.0) / 2.0, (h - 1.0) / 2.0];
        let radius_px = f64::hypot(w, h) / 2.0;
        let trial = |k: [f64; 2]| {
            let c = Calibration {
                image_px,
                centre_px,
                radius_px,
                k,
                homography: [[0.0; 3]; 3],
                reprojection: Reprojection { mean_px: 0.0, max_px: 0.0, mean_mm: 0.0, max_mm: 0.0 },
            };
            let undistorted: Vec<_> = pixels.iter().map(|&p| c.undistort(p)).collect();
            homography(&undistorted, belt).map(|m| Calibration { homography: rows_of(&m), ..c })
        };
        let linear = trial([0.0; 2]).ok_or_else(|| {
            CalibrationError::Degenerate("the points lie on a line or repeat".into())
        })?;
        let problem = Residual { trial: &trial, pixels, belt };
        let simplex = vec![vec![0.0, 0.0], vec![0.02, 0.0], vec![0.0, 0.02]];
        let best = NelderMead::new(simplex)
            .with_sd_tolerance(1e-12)
            .and_then(|s| Executor::new(problem, s).configure(|st| st.max_iters(400)).run())
            .ok()
            .and_then(|r| r.state.best_param.clone())
            .and_then(|k| trial([k[0], k[1]]))
            .filter(|c| squared_mm(c, pixels, belt) < squared_mm(&linear, pixels, belt))
            .unwrap_or(linear);
        let reprojection = best.reprojection_of(pixels, belt);
        Ok(Calibration { reprojection, ..best })
    }

    /// The homography as a matrix.
    fn matrix(&self) -> Matrix3<f64> {
        let h = &self.homography;
        Matrix3::from_row_slice(&[h[0], h[1], h[2]].concat())
    }

    /// Pixel `p` with the lens' distortion undone.
    pub fn undistort(&self, p: [f64; 2]) -> [f64; 2] {
        let (dx, dy) = (p[0] - self.centre_px[0], p[1] - self.centre_px[1]);
        let r2 = (dx * dx + dy * dy) / (self.radius_px * self.radius_px);
        let s = 1.0 + self.k[0] * r2 + self.k[1] * r2 * r2;
        [self.centre_px[0] + dx * s, self.centre_px[1] + dy * s]
    }

    /// The pixel whose undistorted point is `u` (the inverse of [`Calibration::undistort`],
    /// by fixed-point iteration).
    pub fn distort(&self, u: [f64; 2]) -> [f64; 2] {
        let mut p = u;
        for _ in 0..50 {
            let q = self.undistort(p);
            p = [p[0] + (u[0] - q[0]), p[1] + (u[1] - q[1])];
        }
        p
    }

    /// The belt point (along, across, mm) on the belt's surface that pixel `p` sees.
    pub fn belt_of(&self, p: [f64; 2]) -> [f64; 2] {
        apply(&self.matrix(), self.undistort(p))
    }

    /// The pixel that sees belt point `b` (on the surface).
    pub fn pixel_of(&self, b: [f64; 2]) -> [f64; 2] {
        let inverse = self.matrix().try_inverse().unwrap_or_else(Matrix3::zeros);
        self.distort(apply(&inverse, b))
    }

    /// The camera's centre in belt coordinates, mm (its height the third), for a camera of
    /// `intrinsics` (`[fx, fy, cx, cy]`, px): the homography decomposed (a plane seen by a
    /// pinhole). `None` when the homography is not one such a camera gives.
    pub fn camera_centre(&self, intrinsics: [f64; 4]) -> Option<[f64; 3]> {
        let [fx, fy, cx, cy] = intrinsics;
        let k = Matrix3::new(fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0);
        let m = k.try_inverse()? * self.matrix().try_inverse()?;
        let (n1, n2) = (m.column(0).norm(), m.column(1).norm());
        // A pinhole's view of a plane: two columns of one length, at right angles; wrong
        // intrinsics give neither.
        let right = m.column(0).dot(&m.column(1)).abs() / (n1 * n2);
        if (n1 - n2).abs() > 0.02 * (n1 + n2) || right > 0.02 {
            return None;
        }
        let mut scale = 2.0 / (n1 + n2);
        if m[(2, 2)] * scale < 0.0 {
            scale = -scale;
        }
        let (r1, r2, t) = (m.column(0) * scale, m.column(1) * scale, m.column(2) * scale);
        let r = Matrix3::from_columns(&[r1, r2, r1.cross(&r2)]);
        let c = -(r.transpose() * t);
        (c.iter().all(|v| v.is_finite()) && c.z > 0.0).then(|| [c.x, c.y, c.z])
    }

    /// The calibration's fit to `pixels` against `belt`.
    fn reprojection_of(&self, pixels: &[[f64; 2]], belt: &[[f64; 2]]) -> Reprojection {
        let (mut px, mut mm) = (Vec::new(), Vec::new());
        for (p, b) in pixels.iter().zip(belt) {
            let q = self.pixel_of(*b);
            px.push(f64::hypot(q[0] - p[0], q[1] - p[1]));
            let c = self.belt_of(*p);
            mm.push(f64::hypot(c[0] - b[0], c[1] - b[1]));
        }
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let max = |v: &[f64]| v.iter().copied().fold(0.0, f64::max);
        Reprojection { mean_px: mean(&px), max_px: max(&px), mean_mm: mean(&mm), max_mm: max(&mm) }
    }

    /// The calibration as its file holds it (TOML), headed by `comment` lines.
    pub fn to_toml(&self, comment: &str) -> String {
        let body = toml::to_string(self).unwrap_or_default();
        let head: String = comment.lines().map(|l| format!("# {l}\n")).collect();
        format!(
            "{head}# A pixel p is undistorted to c + (p − c)(1 + k[0] ρ² + k[1] ρ⁴), ρ = |p − c| / \
             radius_px, c = centre_px;\n# then homography · (u, v, 1) is the belt point (along, \
             across, w) mm, on the belt's surface.\n{body}"
        )
    }

    /// The calibration in file `path`.
    pub fn load(path: &Path) -> Result<Calibration, CalibrationError> {
        let text = std::fs::read_to_string(path)
            .map_err(|reason| CalibrationError::Read { file: path.into(), reason })?;
        let c: Calibration = toml::from_str(&text).map_err(|e| {
            CalibrationError::Invalid(qmarc_config::toml_file_error(path, &text, &e))
        })?;
        let bad = |field, reason: &str| CalibrationError::Bad {
            file: path.into(),
            field,
            reason: reason.to_string(),
        };
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if c.image_px.contains(&0) {
            return Err(bad("image_px", "a frame's columns and rows, each > 0"));
        }
        if !finite(&c.centre_px) || !finite(&c.k) {
            return Err(bad(if finite(&c.k) { "centre_px" } else { "k" }, "finite numbers"));
        }
        if !(c.radius_px.is_finite() && c.radius_px > 0.0) {
            return Err(bad("radius_px", "a finite number > 0"));
        }
        let m = c.matrix();
        if !finite(m.as_slice()) || m.try_inverse().is_none() {
            return Err(bad("homography", "finite numbers, an invertible matrix"));
        }
        Ok(c)
    }
}

/// How far `points` are from lying on a line: their scatter's smaller eigenvalue over its
/// larger (0: on a line).
fn flatness(points: &[[f64; 2]]) -> f64 {
    let n = points.len() as f64;
    let (mx, my) = points.iter().fold((0.0, 0.0), |(a, b), p| (a + p[0] / n, b + p[1] / n));
    let (mut xx, mut yy, mut xy) = (0.0, 0.0, 0.0);
    for p in points {
        let (dx, dy) = (p[0] - mx, p[1] - my);
        (xx, yy, xy) = (xx + dx * dx, yy + dy * dy, xy + dx * dy);
    }
    let spread = f64::hypot(xx - yy, 2.0 * xy) / 2.0;
    let (big, small) = ((xx + yy) / 2.0 + spread, (xx + yy) / 2.0 - spread);
    if big > 0.0 { small / big } else { 0.0 }
}

/// `m`'s rows.
fn rows_of(m: &Matrix3<f64>) -> [[f64; 3]; 3] {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

/// Σ of the squared belt distances of `pixels` under `c` from `belt`, mm².
fn squared_mm(c: &Calibration, pixels: &[[f64; 2]], belt: &[[f64; 2]]) -> f64 {
    pixels
        .iter()
        .zip(belt)
        .map(|(p, b)| {
            let q = c.belt_of(*p);
            (q[0] - b[0]).powi(2) + (q[1] - b[1]).powi(2)
        })
        .sum()
}

/// The distortion search's cost: the squared belt residual of the fit at k.
struct Residual<'a, F> {
    trial: &'a F,
    pixels: &'a [[f64; 2]],
    belt: &'a [[f64; 2]],
}

impl<F: Fn([f64; 2]) -> Option<Calibration>> CostFunction for Residual<'_, F> {
    type Param = Vec<f64>;
    type Output = f64;

    fn cost(&self, k: &Vec<f64>) -> Result<f64, argmin::core::Error> {
        Ok((self.trial)([k[0], k[1]])
            .map_or(f64::INFINITY, |c| squared_mm(&c, self.pixels, self.belt)))
    }
}

/// `m` applied to point `p` (homogeneous, divided out).
fn apply(m: &Matrix3<f64>, p: [f64; 2]) -> [f64; 2] {
    let v = m * Vector3::new(p[0], p[1], 1.0);
    [v.x / v.z, v.y / v.z]
}

/// The homography taking each of `from` to the point of the same index in `to`: the
/// normalised direct linear transform (Hartley), least squares over all the points.
pub fn homography(from: &[[f64; 2]], to: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    let (nf, nt) = (normaliser(from)?, normaliser(to)?);
    let mut ata = SMatrix::<f64, 9, 9>::zeros();
    for (p, q) in from.iter().zip(to) {
        let (x, y) = {
            let v = apply(&nf, *p);
            (v[0], v[1])
        };
        let (u, v) = {
            let w = apply(&nt, *q);
            (w[0], w[1])
        };
        let rows = [
            [-x, -y, -1.0, 0.0, 0.0, 0.0, u * x, u * y, u],
            [0.0, 0.0, 0.0, -x, -y, -1.0, v * x, v * y, v],
        ];
        for r in rows {
            let r = SMatrix::<f64, 9, 1>::from_row_slice(&r);
            ata += r * r.transpose();
        }
    }
    let eig = ata.symmetric_eigen();
    let smallest = eig.eigenvalues.imin();
    let h = eig.eigenvectors.column(smallest);
    let m = Matrix3::from_row_slice(h.as_slice());
    let full = nt.try_inverse()? * m * nf;
    let full = full / full[(2, 2)];
    full.iter().all(|v| v.is_finite()).then_some(full)
}

/// The similarity that moves `points` to their centroid and scales them to a mean distance
/// of √2 from it; `None` if they all coincide.
fn normaliser(points: &[[f64; 2]]) -> Option<Matrix3<f64>> {
    let n = points.len() as f64;
    let (mx, my) = points.iter().fold((0.0, 0.0), |(a, b), p| (a + p[0] / n, b + p[1] / n));
    let d = points.iter().map(|p| f64::hypot(p[0] - mx, p[1] - my)).sum::<f64>() / n;
    (d > 1e-12).then(|| {
        let s = std::f64::consts::SQRT_2 / d;
        Matrix3::new(s, 0.0, -s * mx, 0.0, s, -s * my, 0.0, 0.0, 1.0)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::camera::CameraModel;

    /// Belt points of a 9×7 grid, 20 mm apart, and where `cam` sees them.
    fn grid(cam: &CameraModel) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let belt: Vec<[f64; 2]> = (0..9)
            .flat_map(|i| {
                (0..7).map(move |j| [70.0 + 20.0 * f64::from(i), -60.0 + 20.0 * f64::from(j)])
            })
            .collect();
        let px = belt.iter().map(|b| cam.pixel_of([b[0], b[1], 0.0]).unwrap()).collect();
        (px, belt)
    }

    /// Exact points of a tilted camera without distortion: the homography is exact, the
    /// camera's centre comes back from it.
    #[test]
    fn a_tilted_cameras_plane_is_fitted_exactly() {
        let cam = CameraModel {
            pose: [150.0, 10.0, 800.0, 85.0, 4.0, -3.0],
            intrinsics: [1600.0, 1600.0, 639.5, 511.5],
            size_px: [1280, 1024],
            k1: 0.0,
        };
        let (px, belt) = grid(&cam);
        let c = Calibration::fit(&px, &belt, cam.size_px).unwrap();
        assert!(c.reprojection.max_px < 1e-6 && c.reprojection.max_mm < 1e-6, "{c:?}");
        let b = c.belt_of(cam.pixel_of([123.0, 45.0, 0.0]).unwrap());
        assert!((b[0] - 123.0).abs() < 1e-6 && (b[1] - 45.0).abs() < 1e-6, "{b:?}");
        let centre = c.camera_centre(cam.intrinsics).unwrap();
        for k in 0..3 {
            assert!((centre[k] - cam.pose[k]).abs() < 1e-6, "{centre:?}");
        }
    }

    /// A barrel-distorted lens: the fitted distortion takes the error well below a
    /// homography's alone.
    #[test]
    fn a_lens_distortion_is_undone() {
        let mut cam = CameraModel::overhead([150.0, 0.0], 800.0, 0.5, [1280, 1024]);
        cam.k1 = -0.1;
        let (px, belt) = grid(&cam);
        let c = Calibration::fit(&px, &belt, cam.size_px).unwrap();
        let plain = homography(&px, &belt).unwrap();
        let plain_err = px
            .iter()
            .zip(&belt)
            .map(|(p, b)| {
                let q = apply(&plain, *p);
                f64::hypot(q[0] - b[0], q[1] - b[1])
            })
            .fold(0.0, f64::max);
        assert!(c.reprojection.max_mm < plain_err / 10.0, "{c:?} against {plain_err}");
        assert!(c.reprojection.mean_px < 0.05, "{c:?}");
    }

    /// Fewer than six points, or points on a line, are refused.
    #[test]
    fn degenerate_points_are_refused() {
        let line: Vec<[f64; 2]> = (0..8).map(|i| [f64::from(i), 2.0 * f64::from(i)]).collect();
        let few = Calibration::fit(&line[..5], &line[..5], [10, 10]).unwrap_err();
        assert_eq!(few.to_string(), "the calibration cannot be fitted: 5 points, 6 at least");
        let on_a_line = Calibration::fit(&line, &line, [10, 10]).unwrap_err();
        assert!(on_a_line.to_string().ends_with("the points lie on a line"), "{on_a_line}");
    }

    /// The file holds the calibration exactly; a bad file names its line and field.
    #[test]
    fn the_file_round_trips_and_a_bad_one_says_where() {
        let cam = CameraModel::overhead([150.0, 0.0], 800.0, 0.5, [640, 480]);
        let (px, belt) = grid(&cam);
        let c = Calibration::fit(&px, &belt, cam.size_px).unwrap();
        let dir = std::env::temp_dir().join(format!("qmarc-vision-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("cal.toml");
        std::fs::write(&file, c.to_toml("a test")).unwrap();
        assert_eq!(Calibration::load(&file).unwrap(), c);
        // Written row by row: a camera looking straight down is affine, its last row 0 0 1.
        let last = c.homography[2];
        assert!(last[0].abs() < 1e-9 && last[1].abs() < 1e-9 && last[2] == 1.0, "{last:?}");
        let bad = c.to_toml("").replace("radius_px =", "radius_px = \"x\" #");
        std::fs::write(&file, bad).unwrap();
        let e = Calibration::load(&file).unwrap_err().to_string();
        assert!(e.contains("cal.toml:") && e.contains("radius_px"), "{e}");
        let zero = c.to_toml("").replace("radius_px = 400.0", "radius_px = 0.0");
        std::fs::write(&file, zero).unwrap();
        let e = Calibration::load(&file).unwrap_err().to_string();
        assert!(e.ends_with("cal.toml: radius_px: a finite number > 0"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
