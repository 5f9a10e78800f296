//! Pinhole camera intrinsics in the camera optical frame (x right, y down, z forward).

use serde::{Deserialize, Serialize};

/// Pinhole intrinsics in pixels. Pixel centres sit at integer coordinates:
/// pixel (u, v) images the ray through ((u - cx) / fx, (v - cy) / fy, 1).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Intrinsics {
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub width: u32,
    pub height: u32,
}

impl Intrinsics {
    /// The YCB-Video camera (its first intrinsic matrix), 640x480.
    pub const YCB_VIDEO: Intrinsics =
        Intrinsics { fx: 1066.778, fy: 1067.487, cx: 312.9869, cy: 241.3109, width: 640, height: 480 };

    /// Projects a camera-frame point (metres) to pixel coordinates; `None` behind the camera.
    pub fn project(&self, p: &nalgebra::Point3<f64>) -> Option<(f64, f64)> {
        if p.z <= 0.0 {
            return None;
        }
        Some((self.fx * p.x / p.z + self.cx, self.fy * p.y / p.z + self.cy))
    }

    /// Back-projects pixel (u, v) at depth z (metres) into the camera frame.
    pub fn back_project(&self, u: f64, v: f64, z: f64) -> nalgebra::Point3<f64> {
        nalgebra::Point3::new((u - self.cx) * z / self.fx, (v - self.cy) * z / self.fy, z)
    }

    /// Row-major 3x3 camera matrix K.
    pub fn matrix(&self) -> [f64; 9] {
        [self.fx, 0.0, self.cx, 0.0, self.fy, self.cy, 0.0, 0.0, 1.0]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn project_then_back_project_round_trips() {
        let k = Intrinsics::YCB_VIDEO;
        let p = nalgebra::Point3::new(0.05, -0.02, 0.8);
        let (u, v) = k.project(&p).unwrap();
        let q = k.back_project(u, v, 0.8);
        assert!((p - q).norm() < 1e-12);
    }
}
