//! [`CameraModel`]: where a camera is above the belt and how it images it — a pinhole camera
//! with one radial distortion coefficient. The renderer draws the belt through it; the
//! calibration recovers its effect from a target; detection uses it to see a part's top face
//! (above the belt) where it is.
//!
//! Frames: belt coordinates are mm along the belt's travel, across it (the travel turned +90°
//! about the vertical), and up from its surface. A pixel's coordinates are (column, row), the
//! centre of pixel (0, 0) at (0, 0).

use nalgebra::{Matrix3, Rotation3, Vector3};

/// A camera looking down at the belt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraModel {
    /// Its pose: `[along, across, height]` mm of its centre in belt coordinates, then
    /// `[yaw, pitch, roll]` degrees. Looking straight down with yaw 0, the image's x axis runs
    /// along the belt and its y axis against the across direction; yaw turns the camera about
    /// the vertical (yaw 90: x across, y along the travel); pitch then tilts its optical axis
    /// toward the image's x, roll toward its y.
    pub pose: [f64; 6],
    /// `[fx, fy, cx, cy]`: focal lengths and principal point, px.
    pub intrinsics: [f64; 4],
    /// Columns and rows.
    pub size_px: [u32; 2],
    /// Radial distortion: a normalised image point (x, y) is seen at (x, y)·(1 + k1·(x² + y²))
    /// (negative: barrel).
    pub k1: f64,
}

impl CameraModel {
    /// A camera looking straight down at `[along, across]` from `height_mm` above the belt,
    /// its x axis across the belt and its y axis along the travel (yaw 90°), seeing
    /// `mm_per_px` at the belt's surface over `size_px`, without distortion.
    pub fn overhead(
        at_mm: [f64; 2],
        height_mm: f64,
        mm_per_px: f64,
        size_px: [u32; 2],
    ) -> CameraModel {
        let f = height_mm / mm_per_px;
        let (cx, cy) = ((f64::from(size_px[0]) - 1.0) / 2.0, (f64::from(size_px[1]) - 1.0) / 2.0);
        CameraModel {
            pose: [at_mm[0], at_mm[1], height_mm, 90.0, 0.0, 0.0],
            intrinsics: [f, f, cx, cy],
            size_px,
            k1: 0.0,
        }
    }

    /// The camera's centre in belt coordinates, mm.
    pub fn centre(&self) -> Vector3<f64> {
        Vector3::new(self.pose[0], self.pose[1], self.pose[2])
    }

    /// The rotation from the camera's axes (x right, y down the image, z the optical axis)
    /// to the belt's.
    pub fn rotation(&self) -> Matrix3<f64> {
        let [yaw, pitch, roll] = [self.pose[3], self.pose[4], self.pose[5]].map(f64::to_radians);
        let down = Matrix3::from_diagonal(&Vector3::new(1.0, -1.0, -1.0));
        *Rotation3::from_axis_angle(&Vector3::z_axis(), yaw).matrix()
            * down
            * Rotation3::from_axis_angle(&Vector3::y_axis(), pitch).matrix()
            * Rotation3::from_axis_angle(&Vector3::x_axis(), roll).matrix()
    }

    /// Where belt point `p` (mm, up from the surface) is seen, px; `None` behind the camera.
    pub fn pixel_of(&self, p: [f64; 3]) -> Option<[f64; 2]> {
        let c = self.rotation().transpose() * (Vector3::from(p) - self.centre());
        if c.z <= 1e-9 {
            return None;
        }
        let (x, y) = (c.x / c.z, c.y / c.z);
        let d = 1.0 + self.k1 * (x * x + y * y);
        let [fx, fy, cx, cy] = self.intrinsics;
        Some([fx * x * d + cx, fy * y * d + cy])
    }

    /// The direction, in belt coordinates, of the ray pixel `px` sees.
    pub fn ray(&self, px: [f64; 2]) -> Vector3<f64> {
        let [fx, fy, cx, cy] = self.intrinsics;
        let (xd, yd) = ((px[0] - cx) / fx, (px[1] - cy) / fy);
        // Undo the distortion: x·(1 + k1 r²) = xd by fixed-point iteration (a contraction for
        // the distortions a lens has).
        let (mut x, mut y) = (xd, yd);
        for _ in 0..20 {
            let d = 1.0 + self.k1 * (x * x + y * y);
            (x, y) = (xd / d, yd / d);
        }
        self.rotation() * Vector3::new(x, y, 1.0)
    }

    /// The point at `height_mm` above the belt that pixel `px` sees, `[along, across]` mm;
    /// `None` if its ray never comes down to that height.
    pub fn belt_of(&self, px: [f64; 2], height_mm: f64) -> Option<[f64; 2]> {
        let (c, d) = (self.centre(), self.ray(px));
        let t = (height_mm - c.z) / d.z;
        (t > 0.0 && t.is_finite()).then(|| [c.x + t * d.x, c.y + t * d.y])
    }

    /// How many mm of the plane at `height_mm` one pixel covers near pixel `px` (the larger
    /// of its two sides).
    pub fn mm_per_px(&self, px: [f64; 2], height_mm: f64) -> f64 {
        let at = |p: [f64; 2]| self.belt_of(p, height_mm).unwrap_or([f64::NAN; 2]);
        let (o, x, y) = (at(px), at([px[0] + 1.0, px[1]]), at([px[0], px[1] + 1.0]));
        f64::hypot(x[0] - o[0], x[1] - o[1]).max(f64::hypot(y[0] - o[0], y[1] - o[1]))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tilted() -> CameraModel {
        CameraModel {
            pose: [150.0, -20.0, 800.0, 80.0, 3.0, -2.0],
            intrinsics: [1600.0, 1610.0, 640.0, 500.0],
            size_px: [1280, 1024],
            k1: -0.08,
        }
    }

    /// A point seen at a pixel is on that pixel's ray, at any height, distortion and tilt.
    #[test]
    fn a_pixels_ray_goes_back_through_the_point_it_sees() {
        let cam = tilted();
        for p in [[150.0, -20.0, 0.0], [300.0, 100.0, 0.0], [10.0, -180.0, 25.0]] {
            let px = cam.pixel_of(p).unwrap();
            let back = cam.belt_of(px, p[2]).unwrap();
            assert!((back[0] - p[0]).abs() < 1e-6 && (back[1] - p[1]).abs() < 1e-6, "{p:?}");
        }
    }

    /// Overhead with yaw 90°: x across, y along the travel; 0.5 mm a pixel at the surface,
    /// less at a part's top (closer to the camera).
    #[test]
    fn an_overhead_camera_sees_the_belt_at_its_scale() {
        let cam = CameraModel::overhead([150.0, 0.0], 800.0, 0.5, [1280, 1024]);
        let centre = cam.pixel_of([150.0, 0.0, 0.0]).unwrap();
        assert!((centre[0] - 639.5).abs() < 1e-9 && (centre[1] - 511.5).abs() < 1e-9);
        let down = cam.pixel_of([160.0, 0.0, 0.0]).unwrap();
        assert!((down[1] - centre[1] - 20.0).abs() < 1e-9, "10 mm along = 20 px down: {down:?}");
        let across = cam.pixel_of([150.0, 10.0, 0.0]).unwrap();
        assert!((across[0] - centre[0] - 20.0).abs() < 1e-9, "{across:?}");
        assert!((cam.mm_per_px(centre, 0.0) - 0.5).abs() < 1e-9);
        assert!((cam.mm_per_px(centre, 80.0) - 0.45).abs() < 1e-9);
        assert_eq!(cam.pixel_of([150.0, 0.0, 900.0]), None, "above the camera");
    }
}
