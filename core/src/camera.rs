//! Pinhole camera with radial-tangential (Brown–Conrady, OpenCV `k1 k2 p1 p2`) distortion.
//!
//! Pixel coordinates follow OpenCV: the centre of the top-left pixel is (0, 0).

use nalgebra::{Point2, Vector2, Vector3};

/// Lens distortion model.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum Distortion {
    /// Ideal pinhole.
    #[default]
    None,
    /// Radial-tangential with coefficients k1, k2, p1, p2.
    RadTan {
        /// Radial r².
        k1: f64,
        /// Radial r⁴.
        k2: f64,
        /// Tangential p1.
        p1: f64,
        /// Tangential p2.
        p2: f64,
    },
}

/// Intrinsics of one camera.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CameraModel {
    /// Image width, px.
    pub width: u32,
    /// Image height, px.
    pub height: u32,
    /// Focal length x, px.
    pub fx: f64,
    /// Focal length y, px.
    pub fy: f64,
    /// Principal point x, px.
    pub cx: f64,
    /// Principal point y, px.
    pub cy: f64,
    /// Lens distortion.
    pub distortion: Distortion,
}

impl CameraModel {
    /// Applies distortion to a normalized image point (x/z, y/z).
    pub fn distort(&self, n: &Vector2<f64>) -> Vector2<f64> {
        match self.distortion {
            Distortion::None => *n,
            Distortion::RadTan { k1, k2, p1, p2 } => {
                let (x, y) = (n.x, n.y);
                let r2 = x * x + y * y;
                let radial = 1.0 + k1 * r2 + k2 * r2 * r2;
                Vector2::new(
                    x * radial + 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x),
                    y * radial + p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y,
                )
            }
        }
    }

    /// Inverts [`Self::distort`] by Gauss–Newton (converges in a few steps for real lenses).
    pub fn undistort(&self, d: &Vector2<f64>) -> Vector2<f64> {
        let Distortion::RadTan { .. } = self.distortion else {
            return *d;
        };
        let mut n = *d;
        for _ in 0..20 {
            let f = self.distort(&n) - d;
            if f.norm_squared() < 1e-24 {
                break;
            }
            // Numerical Jacobian of distort: cheap and exact enough at 1e-7 steps.
            let h = 1e-7;
            let jx = (self.distort(&Vector2::new(n.x + h, n.y)) - self.distort(&n)) / h;
            let jy = (self.distort(&Vector2::new(n.x, n.y + h)) - self.distort(&n)) / h;
            let j = nalgebra::Matrix2::from_columns(&[jx, jy]);
            match j.try_inverse() {
                Some(ji) => n -= ji * f,
                None => break,
            }
        }
        n
    }

    /// Pixel → normalized undistorted image point (x/z, y/z).
    pub fn pixel_to_normalized(&self, px: &Point2<f64>) -> Vector2<f64> {
        let d = Vector2::new((px.x - self.cx) / self.fx, (px.y - self.cy) / self.fy);
        self.undistort(&d)
    }

    /// Normalized undistorted image point → distorted pixel.
    pub fn normalized_to_pixel(&self, n: &Vector2<f64>) -> Point2<f64> {
        let d = self.distort(n);
        Point2::new(self.fx * d.x + self.cx, self.fy * d.y + self.cy)
    }

    /// Projects a point in the camera frame to a pixel; `None` behind the camera.
    pub fn project(&self, p_cam: &Vector3<f64>) -> Option<Point2<f64>> {
        if p_cam.z <= 1e-9 {
            return None;
        }
        Some(self.normalized_to_pixel(&Vector2::new(p_cam.x / p_cam.z, p_cam.y / p_cam.z)))
    }

    /// The unit-depth ray (x, y, 1) in the camera frame through a pixel.
    pub fn ray(&self, px: &Point2<f64>) -> Vector3<f64> {
        let n = self.pixel_to_normalized(px);
        Vector3::new(n.x, n.y, 1.0)
    }

    /// Whether a pixel lies inside the image.
    pub fn contains(&self, px: &Point2<f64>) -> bool {
        px.x >= 0.0
            && px.y >= 0.0
            && px.x <= (self.width - 1) as f64
            && px.y <= (self.height - 1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn euroc_cam0() -> CameraModel {
        CameraModel {
            width: 752,
            height: 480,
            fx: 458.654,
            fy: 457.296,
            cx: 367.215,
            cy: 248.375,
            distortion: Distortion::RadTan {
                k1: -0.28340811,
                k2: 0.07395907,
                p1: 0.00019359,
                p2: 1.76187114e-05,
            },
        }
    }

    proptest! {
        #[test]
        fn undistort_inverts_distort(u in 0.0f64..752.0, v in 0.0f64..480.0) {
            let c = euroc_cam0();
            let px = Point2::new(u, v);
            let back = c.normalized_to_pixel(&c.pixel_to_normalized(&px));
            prop_assert!((back - px).norm() < 1e-6);
        }
    }

    #[test]
    fn project_centre() {
        let c = euroc_cam0();
        let px = c.project(&Vector3::new(0.0, 0.0, 5.0)).expect("in front");
        assert!((px.x - c.cx).abs() < 1e-12 && (px.y - c.cy).abs() < 1e-12);
        assert!(c.project(&Vector3::new(0.0, 0.0, -1.0)).is_none());
    }
}
