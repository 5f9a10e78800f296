//! Surface normals of an object's surface samples, estimated from the
//! samples alone: the axis of least variance of each sample's nearest
//! neighbours (sign arbitrary). Verification uses them to weight a sample by
//! how much image it covers: a face seen edge-on holds as many area-uniform
//! samples as one seen face-on but projects to a sliver of pixels.

use crate::moments::Moments;

/// Neighbours (the sample itself included) each normal is fitted to: on
/// [`fusepose_scene::surface::SURFACE_SAMPLES`] samples a patch of about
/// 2 cm on a hand-sized object, small enough to keep a box's faces apart.
pub const NORMAL_NEIGHBOURS: usize = 10;

/// One unit normal per sample (object frame, sign arbitrary), fitted to its
/// `k` nearest samples; `[0, 0, 0]` where fewer than 3 samples exist.
/// Brute force, O(n²): done once per object when a verifier is built.
pub fn sample_normals(samples: &[[f32; 3]], k: usize) -> Vec<[f32; 3]> {
    let k = k.clamp(3, samples.len().max(3));
    let mut nearest: Vec<(f32, usize)> = Vec::with_capacity(samples.len());
    samples
        .iter()
        .map(|p| {
            nearest.clear();
            nearest.extend(samples.iter().enumerate().map(|(j, q)| {
                let d = [q[0] - p[0], q[1] - p[1], q[2] - p[2]];
                (d[0] * d[0] + d[1] * d[1] + d[2] * d[2], j)
            }));
            if nearest.len() < 3 {
                return [0.0; 3];
            }
            let k = k.min(nearest.len());
            nearest.select_nth_unstable_by(k - 1, |a, b| a.0.total_cmp(&b.0));
            let mut m = Moments::default();
            nearest[..k].iter().for_each(|&(_, j)| m.add(samples[j]));
            m.least_axis(3.0).map_or([0.0; 3], |(_, axis, _)| axis)
        })
        .collect()
}

/// `|n · r̂|` for a normal `n` (camera frame) at camera-frame point `x`: the
/// foreshortening of the surface there, 1 face-on, 0 edge-on (and 0 at the
/// camera centre or for a zero normal).
pub fn facing(n: [f32; 3], x: [f32; 3]) -> f32 {
    let r = (x[0] * x[0] + x[1] * x[1] + x[2] * x[2]).sqrt();
    if r <= 0.0 {
        return 0.0;
    }
    ((n[0] * x[0] + n[1] * x[1] + n[2] * x[2]) / r).abs().min(1.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples on the six faces of an axis-aligned box, on a grid per face.
    fn box_samples(half: [f32; 3], per_side: usize) -> (Vec<[f32; 3]>, Vec<usize>) {
        let (mut pts, mut axis_of) = (Vec::new(), Vec::new());
        for axis in 0..3 {
            let (a, b) = ((axis + 1) % 3, (axis + 2) % 3);
            for sign in [-1.0f32, 1.0] {
                for i in 0..per_side {
                    for j in 0..per_side {
                        let f = |t: usize, h: f32| (t as f32 + 0.5) / per_side as f32 * 2.0 * h - h;
                        let mut p = [0.0; 3];
                        p[axis] = sign * half[axis];
                        p[a] = f(i, half[a]);
                        p[b] = f(j, half[b]);
                        pts.push(p);
                        axis_of.push(axis);
                    }
                }
            }
        }
        (pts, axis_of)
    }

    #[test]
    fn box_face_samples_away_from_edges_get_their_face_normal() {
        let half = [0.05, 0.04, 0.1];
        let (pts, axis_of) = box_samples(half, 12);
        let normals = sample_normals(&pts, NORMAL_NEIGHBOURS);
        let mut checked = 0;
        for ((p, n), &axis) in pts.iter().zip(&normals).zip(&axis_of) {
            // 2 cm from the face's border, the neighbourhood is the face alone.
            let inner = (0..3).filter(|&i| i != axis).all(|i| p[i].abs() < half[i] - 0.02);
            if inner {
                assert!(n[axis].abs() > 0.99, "normal {n:?} at {p:?} is not along axis {axis}");
                checked += 1;
            }
        }
        assert!(checked > 100, "only {checked} inner samples checked");
    }

    #[test]
    fn facing_is_one_face_on_and_zero_edge_on() {
        assert!((facing([0.0, 0.0, 1.0], [0.0, 0.0, 0.8]) - 1.0).abs() < 1e-6);
        assert!((facing([0.0, 0.0, -1.0], [0.0, 0.0, 0.8]) - 1.0).abs() < 1e-6);
        assert!(facing([1.0, 0.0, 0.0], [0.0, 0.0, 0.8]).abs() < 1e-6);
        let oblique = facing([0.0, 0.0, 1.0], [0.8, 0.0, 0.8]);
        assert!((oblique - std::f32::consts::FRAC_1_SQRT_2).abs() < 1e-5);
        assert_eq!(facing([0.0, 0.0, 1.0], [0.0; 3]), 0.0);
    }
}
