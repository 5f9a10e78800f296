//! Per-estimate pose errors: ADD, ADD-S and ADD(S), in metres.
//!
//! - ADD: the mean distance between each model point under the estimated pose
//!   and the same point under the true pose.
//! - ADD-S: for each model point under the estimated pose, the distance to the
//!   nearest model point under the true pose, averaged (the YCB_Video_toolbox
//!   `adi` direction). Nearest neighbours come from a k-d tree (kiddo).
//! - ADD(S): ADD for asymmetric objects, ADD-S for symmetric ones
//!   (`Symmetry::is_symmetric`).
//!
//! The k-d tree is built once per object over the points in the object frame:
//! because rigid motions preserve distances, the nearest true-pose point to
//! `T_est * x` is found by querying `T_true⁻¹ * T_est * x` in the object frame.

use kiddo::{ImmutableKdTree, SquaredEuclidean};
use nalgebra::Point3;

use super::MetricsError;
use crate::{ObjectModel, Pose};

/// The three errors of one estimate against its ground truth (metres).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PoseErrors {
    /// ADD, metres.
    pub add: f64,
    /// ADD-S, metres.
    pub add_s: f64,
    /// ADD(S): `add_s` for a symmetric object, `add` otherwise, metres.
    pub add_or_add_s: f64,
}

/// One object's model points plus a k-d tree over them, ready to score many
/// estimates of that object.
pub struct ObjectMetric {
    points: Vec<Point3<f64>>,
    tree: ImmutableKdTree<f64, 3>,
    symmetric: bool,
}

impl std::fmt::Debug for ObjectMetric {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ObjectMetric").field("points", &self.points.len()).field("symmetric", &self.symmetric).finish()
    }
}

impl ObjectMetric {
    /// Prepares the metric for model `points` (object frame, metres).
    /// `symmetric` selects ADD-S for ADD(S).
    pub fn new(points: &[Point3<f64>], symmetric: bool) -> Result<Self, MetricsError> {
        if points.is_empty() {
            return Err(MetricsError::NoPoints);
        }
        if let Some(index) = points.iter().position(|p| !p.coords.iter().all(|c| c.is_finite())) {
            return Err(MetricsError::NonFinitePoint { index });
        }
        let coords: Vec<[f64; 3]> = points.iter().map(|p| [p.x, p.y, p.z]).collect();
        Ok(Self { points: points.to_vec(), tree: ImmutableKdTree::new_from_slice(&coords), symmetric })
    }

    /// Prepares the metric for a model: its `samples`, symmetric per its `symmetry`.
    pub fn for_model(model: &ObjectModel) -> Result<Self, MetricsError> {
        Self::new(&model.samples, model.symmetry.is_symmetric())
    }

    /// Whether ADD(S) uses ADD-S for this object.
    pub fn is_symmetric(&self) -> bool {
        self.symmetric
    }

    /// The model points (object frame, metres).
    pub fn points(&self) -> &[Point3<f64>] {
        &self.points
    }

    /// ADD in metres.
    pub fn add(&self, estimate: &Pose, truth: &Pose) -> f64 {
        let sum: f64 = self.points.iter().map(|p| (estimate * p - truth * p).norm()).sum();
        sum / self.points.len() as f64
    }

    /// ADD-S in metres.
    pub fn add_s(&self, estimate: &Pose, truth: &Pose) -> f64 {
        let relative = truth.inverse() * estimate;
        let sum: f64 = self
            .points
            .iter()
            .map(|p| {
                let q = relative * p;
                let nearest = self.tree.nearest_one::<SquaredEuclidean>(&[q.x, q.y, q.z]);
                nearest.distance.max(0.0).sqrt()
            })
            .sum();
        sum / self.points.len() as f64
    }

    /// ADD(S) in metres: ADD-S for a symmetric object, ADD otherwise.
    pub fn add_or_add_s(&self, estimate: &Pose, truth: &Pose) -> f64 {
        if self.symmetric { self.add_s(estimate, truth) } else { self.add(estimate, truth) }
    }

    /// All three errors of one estimate.
    pub fn errors(&self, estimate: &Pose, truth: &Pose) -> PoseErrors {
        let add = self.add(estimate, truth);
        let add_s = self.add_s(estimate, truth);
        PoseErrors { add, add_s, add_or_add_s: if self.symmetric { add_s } else { add } }
    }
}

/// ADD in metres of `estimate` against `truth` over model `points` (object frame, metres).
pub fn add(points: &[Point3<f64>], estimate: &Pose, truth: &Pose) -> Result<f64, MetricsError> {
    if points.is_empty() {
        return Err(MetricsError::NoPoints);
    }
    let sum: f64 = points.iter().map(|p| (estimate * p - truth * p).norm()).sum();
    Ok(sum / points.len() as f64)
}

/// ADD-S in metres over model `points`; builds a k-d tree per call, so prefer
/// [`ObjectMetric`] to score many estimates of one object.
pub fn add_s(points: &[Point3<f64>], estimate: &Pose, truth: &Pose) -> Result<f64, MetricsError> {
    Ok(ObjectMetric::new(points, true)?.add_s(estimate, truth))
}

#[cfg(test)]
mod tests {
    use super::*;
    use nalgebra::{Translation3, UnitQuaternion, Vector3};

    /// Points on the side of a cylinder of radius 0.05 m, height 0.1 m, axis z:
    /// `rings` heights × `per_ring` angles.
    fn cylinder(rings: usize, per_ring: usize) -> Vec<Point3<f64>> {
        let mut out = Vec::new();
        for r in 0..rings {
            let z = -0.05 + 0.1 * r as f64 / (rings - 1) as f64;
            for a in 0..per_ring {
                let phi = std::f64::consts::TAU * a as f64 / per_ring as f64;
                out.push(Point3::new(0.05 * phi.cos(), 0.05 * phi.sin(), z));
            }
        }
        out
    }

    fn brute_add_s(points: &[Point3<f64>], est: &Pose, truth: &Pose) -> f64 {
        let sum: f64 = points
            .iter()
            .map(|p| {
                let e = est * p;
                points.iter().map(|q| (e - truth * q).norm()).fold(f64::INFINITY, f64::min)
            })
            .sum();
        sum / points.len() as f64
    }

    #[test]
    fn one_centimetre_translation_gives_add_of_one_centimetre() {
        let points = cylinder(5, 16);
        let truth = Pose::from_parts(
            Translation3::new(0.1, -0.2, 0.8),
            UnitQuaternion::from_axis_angle(&Vector3::x_axis(), 0.3),
        );
        let estimate = Pose::from_parts(Translation3::new(0.11, -0.2, 0.8), truth.rotation);
        let metric = ObjectMetric::new(&points, false).unwrap();
        assert!((metric.add(&estimate, &truth) - 0.01).abs() < 1e-12);
        assert!((add(&points, &estimate, &truth).unwrap() - 0.01).abs() < 1e-12);
        // A pure translation moves every point by 1 cm; the nearest point can be
        // closer, never farther.
        assert!(metric.add_s(&estimate, &truth) <= 0.01 + 1e-12);
    }

    #[test]
    fn identical_poses_give_zero_errors() {
        let points = cylinder(3, 8);
        let pose = Pose::from_parts(Translation3::new(0.0, 0.0, 1.0), UnitQuaternion::identity());
        let e = ObjectMetric::new(&points, true).unwrap().errors(&pose, &pose);
        assert_eq!(e.add, 0.0);
        assert_eq!(e.add_s, 0.0);
        assert_eq!(e.add_or_add_s, 0.0);
    }

    #[test]
    fn rotating_a_cylinder_about_its_axis_gives_small_add_s_but_large_add() {
        // 2° between neighbouring samples on a 5 cm radius: chord 1.75 mm.
        let points = cylinder(11, 180);
        let truth = Pose::from_parts(Translation3::new(0.0, 0.0, 0.7), UnitQuaternion::identity());
        // Rotate by 1° + 90°: each rotated point sits half-way between two
        // samples, 0.87 mm from the nearest.
        let angle = 91f64.to_radians();
        let estimate = Pose::from_parts(truth.translation, UnitQuaternion::from_axis_angle(&Vector3::z_axis(), angle));
        let metric = ObjectMetric::new(&points, true).unwrap();
        let add_s = metric.add_s(&estimate, &truth);
        let add = metric.add(&estimate, &truth);
        let half_chord = 2.0 * 0.05 * (0.5f64.to_radians()).sin();
        assert!((add_s - half_chord).abs() < 1e-9, "add_s {add_s}");
        assert!(add_s < 0.001);
        // ADD: every point moves along a chord of angle 91°: 2 r sin(45.5°).
        let chord = 2.0 * 0.05 * (angle / 2.0).sin();
        assert!((add - chord).abs() < 1e-12, "add {add}");
        assert_eq!(metric.add_or_add_s(&estimate, &truth), add_s);
        let asym = ObjectMetric::new(&points, false).unwrap();
        assert_eq!(asym.add_or_add_s(&estimate, &truth), add);
    }

    #[test]
    fn kd_tree_add_s_matches_brute_force() {
        let points = cylinder(7, 40);
        let truth =
            Pose::from_parts(Translation3::new(0.02, 0.01, 0.6), UnitQuaternion::from_euler_angles(0.2, -0.1, 0.7));
        let estimate =
            Pose::from_parts(Translation3::new(0.025, 0.0, 0.61), UnitQuaternion::from_euler_angles(0.5, 0.3, -0.2));
        let fast = add_s(&points, &estimate, &truth).unwrap();
        let slow = brute_add_s(&points, &estimate, &truth);
        assert!((fast - slow).abs() < 1e-12, "{fast} vs {slow}");
    }

    #[test]
    fn kd_tree_add_s_matches_brute_force_on_random_clouds() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(42);
        for _ in 0..5 {
            let points: Vec<Point3<f64>> = (0..1500)
                .map(|_| {
                    Point3::new(
                        rng.random_range(-0.1..0.1),
                        rng.random_range(-0.05..0.05),
                        rng.random_range(-0.02..0.02),
                    )
                })
                .collect();
            let mut pose = || {
                Pose::from_parts(
                    Translation3::new(
                        rng.random_range(-0.1..0.1),
                        rng.random_range(-0.1..0.1),
                        rng.random_range(0.5..1.0),
                    ),
                    UnitQuaternion::from_euler_angles(
                        rng.random_range(-3.0..3.0),
                        rng.random_range(-1.5..1.5),
                        rng.random_range(-3.0..3.0),
                    ),
                )
            };
            let (truth, estimate) = (pose(), pose());
            let fast = ObjectMetric::new(&points, true).unwrap().add_s(&estimate, &truth);
            let slow = brute_add_s(&points, &estimate, &truth);
            assert!((fast - slow).abs() < 1e-12, "{fast} vs {slow}");
        }
    }

    #[test]
    fn many_duplicate_points_are_fine() {
        // Far more identical points than a k-d tree bucket holds.
        let mut points = vec![Point3::new(0.0, 0.0, 0.0); 200];
        points.push(Point3::new(0.1, 0.0, 0.0));
        let metric = ObjectMetric::new(&points, true).unwrap();
        let truth = Pose::identity();
        let estimate = Pose::from_parts(Translation3::new(0.0, 0.003, 0.0), UnitQuaternion::identity());
        assert!((metric.add_s(&estimate, &truth) - 0.003).abs() < 1e-12);
    }

    #[test]
    fn tiny_point_sets_work() {
        // One point: ADD-S is the distance between its two images.
        let one = [Point3::new(0.01, 0.02, 0.03)];
        let est = Pose::from_parts(Translation3::new(0.0, 0.0, 0.004), UnitQuaternion::identity());
        let m = ObjectMetric::new(&one, true).unwrap();
        assert!((m.add_s(&est, &Pose::identity()) - 0.004).abs() < 1e-15);
        // Two points 0.1 m apart, estimate swaps them (180° about z through
        // their midpoint): ADD = 0.1, ADD-S = 0.
        let two = [Point3::new(-0.05, 0.0, 0.0), Point3::new(0.05, 0.0, 0.0)];
        let swap = Pose::from_parts(
            Translation3::identity(),
            UnitQuaternion::from_axis_angle(&Vector3::z_axis(), std::f64::consts::PI),
        );
        let m = ObjectMetric::new(&two, true).unwrap();
        assert!((m.add(&swap, &Pose::identity()) - 0.1).abs() < 1e-12);
        assert!(m.add_s(&swap, &Pose::identity()) < 1e-12);
    }

    #[test]
    fn empty_or_non_finite_points_are_errors() {
        assert!(matches!(ObjectMetric::new(&[], false), Err(MetricsError::NoPoints)));
        assert!(matches!(add(&[], &Pose::identity(), &Pose::identity()), Err(MetricsError::NoPoints)));
        let bad = [Point3::new(0.0, 0.0, 0.0), Point3::new(f64::NAN, 0.0, 0.0)];
        assert!(matches!(ObjectMetric::new(&bad, false), Err(MetricsError::NonFinitePoint { index: 1 })));
    }
}
