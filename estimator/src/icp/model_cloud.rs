//! One object's ICP target: surface samples, their normals and a k-d tree.
//!
//! Built once per object at [`super::IcpEstimator`] construction from
//! [`ObjectModel::samples`] (object frame, metres). Normals come from PCA of
//! each sample's nearest neighbours (unsigned: point-to-plane does not need
//! the sign). Queries never allocate.

use fusepose_scene::ObjectModel;
use kiddo::SquaredEuclidean;
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use nalgebra::{Matrix3, Point3, Vector3};

/// Neighbours used for each sample's PCA normal.
const NORMAL_NEIGHBOURS: usize = 12;

/// Fewest samples an object needs for ICP.
pub const MIN_MODEL_SAMPLES: usize = 16;

/// Surface samples of one object with normals and a nearest-neighbour index.
pub struct ModelCloud {
    pub points: Vec<Vector3<f64>>,
    pub normals: Vec<Vector3<f64>>,
    /// Bounding-box centre, object frame, metres.
    pub centre: Vector3<f64>,
    /// Mean distance of the samples from `centre`, metres.
    pub mean_radius: f64,
    tree: ImmutableKdTree<f32, u32, 3, 32>,
}

impl ModelCloud {
    /// `None` when the model has fewer than [`MIN_MODEL_SAMPLES`] finite samples.
    pub fn new(model: &ObjectModel) -> Option<Self> {
        let points: Vec<Vector3<f64>> =
            model.samples.iter().map(|p| p.coords).filter(|p| p.iter().all(|x| x.is_finite())).collect();
        if points.len() < MIN_MODEL_SAMPLES {
            return None;
        }
        let flat: Vec<[f32; 3]> = points.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
        let tree = ImmutableKdTree::<f32, u32, 3, 32>::new_from_slice(&flat);
        let k = std::num::NonZero::new(NORMAL_NEIGHBOURS.min(points.len())).unwrap_or(std::num::NonZero::<usize>::MIN);
        let normals = flat
            .iter()
            .map(|q| {
                let neighbours = tree.nearest_n::<SquaredEuclidean>(q, k);
                let idx: Vec<usize> = neighbours.iter().map(|n| n.item as usize).collect();
                pca_normal(&points, &idx)
            })
            .collect();
        let (lo, hi) = points
            .iter()
            .fold((Vector3::repeat(f64::MAX), Vector3::repeat(f64::MIN)), |(lo, hi), p| (lo.inf(p), hi.sup(p)));
        let centre = (lo + hi) / 2.0;
        let mean_radius = points.iter().map(|p| (p - centre).norm()).sum::<f64>() / points.len() as f64;
        Some(Self { points, normals, centre, mean_radius, tree })
    }

    /// Nearest sample to `q` (object frame): (index, distance in metres).
    #[inline]
    pub fn nearest(&self, q: &Vector3<f64>) -> (usize, f64) {
        let n = self.tree.nearest_one::<SquaredEuclidean>(&[q.x as f32, q.y as f32, q.z as f32]);
        (n.item as usize, (n.distance as f64).sqrt())
    }

    /// Samples as points (for tests and debugging).
    pub fn point(&self, i: usize) -> Point3<f64> {
        Point3::from(self.points[i])
    }
}

/// Unit normal of the best-fit plane through `points[idx]` (smallest
/// covariance eigenvector); +z when degenerate.
fn pca_normal(points: &[Vector3<f64>], idx: &[usize]) -> Vector3<f64> {
    if idx.len() < 3 {
        return Vector3::z();
    }
    let mean = idx.iter().map(|&i| points[i]).sum::<Vector3<f64>>() / idx.len() as f64;
    let cov = idx.iter().fold(Matrix3::zeros(), |acc, &i| {
        let d = points[i] - mean;
        acc + d * d.transpose()
    });
    let eig = cov.symmetric_eigen();
    let smallest = eig.eigenvalues.imin();
    let n = eig.eigenvectors.column(smallest).into_owned();
    if n.norm() > 0.0 && n.iter().all(|x| x.is_finite()) { n.normalize() } else { Vector3::z() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_scene::{Mesh, Symmetry};

    #[test]
    fn plane_samples_get_plane_normals_and_nearest_works() {
        let samples: Vec<Point3<f64>> =
            (0..400).map(|i| Point3::new((i % 20) as f64 * 0.005, (i / 20) as f64 * 0.005, 0.0)).collect();
        let model = ObjectModel {
            name: "plate".into(),
            mesh: Mesh::default(),
            symmetry: Symmetry::None,
            samples,
            diameter: 0.13,
            bbox_min: Point3::origin(),
            bbox_max: Point3::new(0.095, 0.095, 0.0),
            shadow_mesh: None,
        };
        let cloud = ModelCloud::new(&model).unwrap();
        assert!(cloud.normals.iter().all(|n| n.z.abs() > 0.999));
        let (i, d) = cloud.nearest(&Vector3::new(0.0101, 0.0049, 0.002));
        assert_eq!(cloud.point(i), Point3::new(0.01, 0.005, 0.0));
        assert!((d - (0.0001f64.powi(2) + 0.0001f64.powi(2) + 0.002f64.powi(2)).sqrt()).abs() < 1e-6);
    }

    #[test]
    fn too_few_samples_is_none() {
        let model = ObjectModel {
            name: "dot".into(),
            mesh: Mesh::default(),
            symmetry: Symmetry::None,
            samples: vec![Point3::origin(); 3],
            diameter: 0.0,
            bbox_min: Point3::origin(),
            bbox_max: Point3::origin(),
            shadow_mesh: None,
        };
        assert!(ModelCloud::new(&model).is_none());
    }
}
