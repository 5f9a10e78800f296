//! The surface the objects stand on: a plane fitted to the frame's
//! background points.
//!
//! Objects on a table (or a bin's floor) stand above it; a point lying on it
//! is table, whatever a mask says. [`fit`] is RANSAC with a fixed generator
//! state (the same points, the same plane) over points the caller already
//! knows to be background, so an object's large flat face cannot win. The
//! objects stand on the plane, so a plane with many of their points under it
//! ([`share_below`]) is refused: the background the segmenter left can be a
//! few shadows and gaps when it gave the table an object's class.

use fusepose_scene::ObjectSet;
use nalgebra::Vector3;

use crate::verify::thinnest_extent;

/// RANSAC hypotheses per fit.
const TRIES: usize = 48;
/// Inlier distance: metres plus this share of the depth.
const TOL_M: f32 = 0.005;
const TOL_PER_M: f32 = 0.005;
/// A plane needs this share of the points as inliers.
const MIN_SHARE: f32 = 0.2;
/// Fewer points than this fit no plane.
const MIN_POINTS: usize = 16;

/// The floor reaches at most this share of an object's thinnest extent: a
/// part lying flat that is thinner than four floors (a circuit board, a
/// washer) keeps its points.
pub const THIN_SHARE: f32 = 0.25;

/// The support floor of each class (index = class id − 1): `floor`, or
/// [`THIN_SHARE`] of the object's thinnest extent when that is less.
pub fn class_floors(objects: &ObjectSet, floor: f32) -> Vec<f32> {
    objects
        .objects
        .iter()
        .map(|o| {
            let samples: Vec<[f32; 3]> = o.samples.iter().map(|p| [p.x as f32, p.y as f32, p.z as f32]).collect();
            floor.min(THIN_SHARE * thinnest_extent(&samples))
        })
        .collect()
}

/// `normal · p + offset` is p's height above the plane in metres, positive
/// on the camera's side (the camera is above the table).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupportPlane {
    pub normal: Vector3<f32>,
    pub offset: f32,
}

impl SupportPlane {
    pub fn height(&self, p: &Vector3<f32>) -> f32 {
        self.normal.dot(p) + self.offset
    }
}

/// A point lies below a plane when it is more than this far under it (metres
/// plus this share of its depth): depth noise and flying pixels at the
/// objects' feet stay within it.
const BELOW_M: f32 = 0.02;
const BELOW_PER_M: f32 = 0.01;

/// A plane with more than this share of the frame's object points below it
/// is not what they stand on: the background the segmenter left (a green
/// table taken for the green bowl leaves shadows and gaps) held a slope
/// through them, and every object "sank" under it (docs/BENCHMARKS.md,
/// session 43).
pub const MAX_BELOW_SHARE: f32 = 0.15;

/// Share of `points` lying below `plane` ([`BELOW_M`]); 0 for none.
pub fn share_below(plane: &SupportPlane, points: &[Vector3<f32>]) -> f32 {
    let below = points.iter().filter(|p| plane.height(p) < -(BELOW_M + BELOW_PER_M * p.z)).count();
    below as f32 / points.len().max(1) as f32
}

/// The plane through most of `points` (camera frame, metres, all with depth),
/// or `None` when fewer than [`MIN_SHARE`] of them lie on any one tried.
pub fn fit(points: &[Vector3<f32>]) -> Option<SupportPlane> {
    let m = points.len();
    if m < MIN_POINTS {
        return None;
    }
    let mut state = 0x9e37_79b9_7f4a_7c15u64 ^ m as u64;
    let mut next = |bound: usize| {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((state >> 33) as usize) % bound
    };
    // Inliers are counted on every other point: the plane is large.
    let stride = if m > 2000 { 2 } else { 1 };
    let mut best: Option<(SupportPlane, usize)> = None;
    for _ in 0..TRIES {
        let [a, b, c] = [next(m), next(m), next(m)].map(|i| points[i]);
        let nrm = (b - a).cross(&(c - a));
        let len = nrm.norm();
        if len.is_nan() || len <= 1e-9 {
            continue;
        }
        let mut normal = nrm / len;
        let mut offset = -normal.dot(&a);
        // The camera (origin) is above the plane.
        if offset < 0.0 {
            normal = -normal;
            offset = -offset;
        }
        let plane = SupportPlane { normal, offset };
        let inliers =
            points.iter().step_by(stride).filter(|p| plane.height(p).abs() <= TOL_M + TOL_PER_M * p.z).count();
        if best.is_none_or(|(_, b)| inliers > b) {
            best = Some((plane, inliers));
        }
    }
    let (plane, inliers) = best?;
    ((inliers * stride) as f32 >= MIN_SHARE * m as f32).then_some(plane)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn share_below_counts_points_under_the_plane_beyond_the_noise() {
        // The plane z = 1 m seen from above: height = 1 - z.
        let plane = SupportPlane { normal: Vector3::new(0.0, 0.0, -1.0), offset: 1.0 };
        let at = |z: f32| Vector3::new(0.0, 0.0, z);
        // 2 cm + 1 % of the depth under it is noise; 5 cm is below.
        let points = [at(0.9), at(1.0), at(1.025), at(1.05), at(1.05)];
        assert_eq!(share_below(&plane, &points), 0.4);
        assert_eq!(share_below(&plane, &[]), 0.0);
    }

    /// A table 1 m below a camera tilted 30° down, with 30 % of the points on a box 10 cm above it.
    fn table_and_box() -> Vec<Vector3<f32>> {
        let (s, c) = (30f32.to_radians().sin(), 30f32.to_radians().cos());
        let mut points = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                let (x, y) = (i as f32 * 0.02 - 0.4, j as f32 * 0.02 - 0.4);
                let h = if i < 12 { 0.1 } else { 0.0 };
                // Table coordinates (x, y, height) into the camera frame: y down, z forward.
                let (yt, zt) = (1.0 - h, y);
                points.push(Vector3::new(x, c * yt - s * zt, s * yt + c * zt + 1.0));
            }
        }
        points
    }

    #[test]
    fn the_plane_most_points_lie_on_wins_and_heights_are_metres_above_it() {
        let points = table_and_box();
        let plane = fit(&points).expect("a table");
        let heights: Vec<f32> = points.iter().map(|p| plane.height(p)).collect();
        assert!(heights[12 * 40..].iter().all(|h| h.abs() < 1e-3), "table points on the plane");
        assert!(heights[..12 * 40].iter().all(|h| (h - 0.1).abs() < 1e-3), "box top 10 cm above it");
        assert_eq!(fit(&points), Some(plane), "deterministic");
    }

    #[test]
    fn too_few_points_or_no_dominant_plane_fit_nothing() {
        assert_eq!(fit(&table_and_box()[..10]), None);
        // Points scattered through a cube: no plane holds a fifth of them.
        let scattered: Vec<Vector3<f32>> = (0..400)
            .map(|i| {
                let f = |k: u64| {
                    // splitmix64 of (point, coordinate): no lattice for a plane to find.
                    let mut x = (i as u64) << 2 | k;
                    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
                    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
                    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
                    ((x ^ (x >> 31)) % 1000) as f32 / 1000.0
                };
                Vector3::new(f(1), f(2), 1.0 + f(3))
            })
            .collect();
        assert_eq!(fit(&scattered), None);
    }
}
