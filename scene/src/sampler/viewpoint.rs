//! Camera placement: look-at poses and random viewpoints on a hemisphere
//! above the table (table frame: z up, metres).

use crate::Pose;
use nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use rand::Rng;

/// The table → camera pose of a camera at `eye` looking at `target` (table
/// frame), with the image "up" as close to +z as possible, then rolled by
/// `roll` radians about the optical axis. `None` when eye == target or the
/// view direction is vertical.
pub fn look_at(eye: Point3<f64>, target: Point3<f64>, roll: f64) -> Option<Pose> {
    let f = (target - eye).try_normalize(1e-12)?;
    // Camera optical frame: x right, y down, z forward.
    let x = f.cross(&Vector3::z()).try_normalize(1e-9)?;
    let y = f.cross(&x);
    let table_from_cam_rot = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, f]));
    let rolled = table_from_cam_rot * Rotation3::from_axis_angle(&Vector3::z_axis(), roll);
    let table_from_cam =
        Pose::from_parts(Translation3::from(eye.coords), UnitQuaternion::from_rotation_matrix(&rolled));
    Some(table_from_cam.inverse())
}

/// Uniform in [a, b) (or a when the range is empty).
fn uniform<R: Rng + ?Sized>(rng: &mut R, (a, b): (f64, f64)) -> f64 {
    if b > a { rng.random_range(a..b) } else { a }
}

/// Ranges a random viewpoint is drawn from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewRanges {
    /// Distance from the look-at point (metres).
    pub distance_m: (f64, f64),
    /// Elevation above the table plane (degrees).
    pub elevation_deg: (f64, f64),
    /// Roll about the optical axis: uniform in ±this (degrees).
    pub max_roll_deg: f64,
}

/// A random camera (table → camera) looking at `target`: azimuth uniform,
/// elevation, distance and roll uniform in their ranges.
pub fn random_view(rng: &mut impl Rng, r: &ViewRanges, target: Point3<f64>) -> Pose {
    loop {
        let azimuth = rng.random_range(0.0..std::f64::consts::TAU);
        let elevation = uniform(rng, r.elevation_deg).to_radians();
        let distance = uniform(rng, r.distance_m);
        let roll = uniform(rng, (-r.max_roll_deg, r.max_roll_deg)).to_radians();
        let dir = Vector3::new(elevation.cos() * azimuth.cos(), elevation.cos() * azimuth.sin(), elevation.sin());
        if let Some(p) = look_at(target + dir * distance, target, roll) {
            return p;
        }
        // Exactly vertical or zero distance: draw again (ranges validated upstream).
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn look_at_puts_target_on_the_optical_axis_with_up_up() {
        let eye = Point3::new(0.6, -0.3, 0.5);
        let target = Point3::new(0.05, 0.02, 0.0);
        let cam_from_table = look_at(eye, target, 0.0).unwrap();
        let t = cam_from_table * target;
        assert!(t.x.abs() < 1e-12 && t.y.abs() < 1e-12);
        assert!((t.z - (target - eye).norm()).abs() < 1e-12);
        // A point above the target appears above it in the image (smaller y).
        let above = cam_from_table * Point3::new(target.x, target.y, 0.2);
        assert!(above.y < 0.0);
        assert!(look_at(Point3::new(0.0, 0.0, 1.0), Point3::origin(), 0.0).is_none());
    }
}
