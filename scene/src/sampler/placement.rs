//! Resting objects on the table: stable orientations from the faces of the
//! object's bounding box (the object rests with its lowest vertex on z = 0),
//! and 2D footprint rectangles with a separating-axis overlap test.

use crate::ObjectModel;
use nalgebra::{UnitQuaternion, Vector2, Vector3};

/// One way an object can rest on the table (before the random yaw).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RestPose {
    /// Object → table rotation for this rest (no yaw).
    pub rotation: UnitQuaternion<f64>,
    /// Height of the object origin above the table top (metres).
    pub lift: f64,
    /// Footprint rectangle centre (x, y, metres) relative to the object origin, in the rest frame.
    pub footprint_centre: [f64; 2],
    /// Footprint half sizes (x, y, metres) in the rest frame.
    pub footprint_half: [f64; 2],
    /// Area (m²) of the bounding-box face it rests on: larger = more likely.
    pub face_area: f64,
    /// True for the face with outward normal −z (the object's natural upright rest).
    pub upright: bool,
    /// Height of the object's top above the table top in this rest (metres).
    pub height: f64,
}

/// The six bounding-box-face rests of a model. Degenerate (empty) meshes get
/// the identity rest with zero footprint.
pub fn rest_poses(model: &ObjectModel) -> Vec<RestPose> {
    let ext = model.bbox_max - model.bbox_min;
    let mut out = Vec::with_capacity(6);
    for axis in 0..3 {
        for sign in [-1.0f64, 1.0] {
            let mut n = Vector3::zeros();
            n[axis] = sign;
            let rotation = UnitQuaternion::rotation_between(&n, &-Vector3::z())
                .unwrap_or_else(|| UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI));
            let (o1, o2) = ((axis + 1) % 3, (axis + 2) % 3);
            let face_area = (ext[o1] * ext[o2]).abs();
            let (lift, centre, half, height) = footprint(model, &rotation);
            out.push(RestPose {
                rotation,
                lift,
                footprint_centre: centre,
                footprint_half: half,
                face_area,
                upright: axis == 2 && sign < 0.0,
                height,
            });
        }
    }
    out
}

/// Lift (−min z), the xy bounding rectangle (centre, half sizes) and the
/// height (max z − min z) of the rotated mesh vertices.
fn footprint(model: &ObjectModel, r: &UnitQuaternion<f64>) -> (f64, [f64; 2], [f64; 2], f64) {
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &model.mesh.positions {
        let q = r * Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64);
        if !q.iter().all(|c| c.is_finite()) {
            continue;
        }
        for i in 0..3 {
            lo[i] = lo[i].min(q[i]);
            hi[i] = hi[i].max(q[i]);
        }
    }
    if lo[0] > hi[0] {
        return (0.0, [0.0; 2], [0.0; 2], 0.0);
    }
    (
        -lo[2],
        [(lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0],
        [(hi[0] - lo[0]) / 2.0, (hi[1] - lo[1]) / 2.0],
        hi[2] - lo[2],
    )
}

/// An oriented rectangle on the table (metres, table frame).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    pub centre: Vector2<f64>,
    /// Unit axes.
    pub axes: [Vector2<f64>; 2],
    pub half: [f64; 2],
}

impl Footprint {
    /// The footprint of `rest` after a yaw (radians) about the table z axis
    /// and a translation of the object origin to `position` (xy).
    pub fn of(rest: &RestPose, yaw: f64, position: Vector2<f64>) -> Footprint {
        let (s, c) = yaw.sin_cos();
        let ax = Vector2::new(c, s);
        let ay = Vector2::new(-s, c);
        let centre = position + ax * rest.footprint_centre[0] + ay * rest.footprint_centre[1];
        Footprint { centre, axes: [ax, ay], half: rest.footprint_half }
    }

    /// Whether the two rectangles, each grown by `gap / 2`, overlap (separating axes).
    pub fn overlaps(&self, other: &Footprint, gap: f64) -> bool {
        let d = other.centre - self.centre;
        for axis in self.axes.iter().chain(other.axes.iter()) {
            let ra = self.half[0] * self.axes[0].dot(axis).abs() + self.half[1] * self.axes[1].dot(axis).abs();
            let rb = other.half[0] * other.axes[0].dot(axis).abs() + other.half[1] * other.axes[1].dot(axis).abs();
            if d.dot(axis).abs() >= ra + rb + gap {
                return false;
            }
        }
        true
    }

    /// Largest distance from the centre to a corner.
    pub fn radius(&self) -> f64 {
        (self.half[0].powi(2) + self.half[1].powi(2)).sqrt()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rect(cx: f64, cy: f64, yaw: f64, hx: f64, hy: f64) -> Footprint {
        let rest = RestPose {
            rotation: UnitQuaternion::identity(),
            lift: 0.0,
            footprint_centre: [0.0, 0.0],
            footprint_half: [hx, hy],
            face_area: 0.0,
            upright: true,
            height: 0.0,
        };
        Footprint::of(&rest, yaw, Vector2::new(cx, cy))
    }

    #[test]
    fn separating_axis_test_matches_geometry() {
        let a = rect(0.0, 0.0, 0.0, 0.05, 0.05);
        assert!(a.overlaps(&rect(0.09, 0.0, 0.0, 0.05, 0.05), 0.0));
        assert!(!a.overlaps(&rect(0.11, 0.0, 0.0, 0.05, 0.05), 0.0));
        assert!(a.overlaps(&rect(0.11, 0.0, 0.0, 0.05, 0.05), 0.02));
        // A 45° square whose corner reaches 0.0707 from its centre.
        let d = rect(0.125, 0.0, std::f64::consts::FRAC_PI_4, 0.05, 0.05);
        assert!(!a.overlaps(&d, 0.0));
        let d = rect(0.115, 0.0, std::f64::consts::FRAC_PI_4, 0.05, 0.05);
        assert!(a.overlaps(&d, 0.0));
        // Diagonal separation that only the rotated axes reveal.
        let e = rect(0.09, 0.09, std::f64::consts::FRAC_PI_4, 0.05, 0.01);
        assert!(!a.overlaps(&e, 0.0));
    }
}
