//! The estimator's output: one pose per object instance of a frame.

use nalgebra::{UnitQuaternion, Vector3};

/// One object's estimated pose in the camera optical frame (x right, y down, z forward).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ObjectPose {
    /// Class id (1-based index into the object set; 0 never appears here).
    pub class_id: u16,
    /// Instance index within the frame (order of [`crate::Workspace`] instances).
    pub instance_id: u16,
    /// Rotation object → camera.
    pub rotation: UnitQuaternion<f64>,
    /// Translation object → camera, metres.
    pub translation: Vector3<f64>,
    /// Estimator-specific confidence in [0, 1]; higher is better.
    pub confidence: f32,
    /// Pixels in the instance mask.
    pub mask_pixels: u32,
    /// Bounding box in pixels: [u_min, v_min, u_max, v_max] inclusive.
    pub bbox: [u16; 4],
    /// Iterations used (ICP iterations, or refiner iterations for the network).
    pub iterations: u16,
}

/// Removes item `i` of `items` where `dropped[i]` (items beyond `dropped`
/// stay) and returns how many went: keeps per-pose data (scores, verdicts)
/// in step with [`PoseSet::remove_marked`]. No allocation.
pub fn remove_marked<T>(items: &mut Vec<T>, dropped: &[bool]) -> usize {
    let mut it = dropped.iter();
    items.retain(|_| !it.next().copied().unwrap_or(false));
    dropped.iter().filter(|&&d| d).count()
}

/// Pairwise suppression shared by the physical checks: for every two poses
/// `(i, j)`, `shares` gives how much of `i` the other claims and how much of
/// `j` (None: not judged). Where either exceeds `max_share`, the pose claimed
/// more is marked in `dropped` (resized to the pose count; equal within 0.1:
/// the lower `scores`, NaN lowest); with `skip_dropped` a marked pose is not
/// compared again. Removes the marked poses and returns how many. `max_share`
/// ≥ 1 (or NaN) never drops. No allocation within `dropped`'s capacity.
pub fn drop_pairwise(
    poses: &mut PoseSet,
    max_share: f32,
    scores: &[f32],
    dropped: &mut Vec<bool>,
    skip_dropped: bool,
    mut shares: impl FnMut(&ObjectPose, &ObjectPose) -> Option<(f32, f32)>,
) -> usize {
    let all = poses.as_slice();
    dropped.clear();
    dropped.resize(all.len(), false);
    if max_share.is_nan() || max_share >= 1.0 || all.len() < 2 {
        return 0;
    }
    let score = |i: usize| scores.get(i).copied().filter(|s| !s.is_nan()).unwrap_or(f32::NEG_INFINITY);
    for i in 0..all.len() {
        for j in i + 1..all.len() {
            if skip_dropped && (dropped[i] || dropped[j]) {
                continue;
            }
            let Some((of_i, of_j)) = shares(&all[i], &all[j]) else { continue };
            if of_i.max(of_j) <= max_share {
                continue;
            }
            let loser = if (of_i - of_j).abs() > 0.1 {
                if of_i > of_j { i } else { j }
            } else if score(j) < score(i) {
                j
            } else {
                i
            };
            dropped[loser] = true;
        }
    }
    poses.remove_marked(dropped)
}

/// The poses of one frame; capacity fixed at construction so filling it never allocates.
#[derive(Clone, Debug)]
pub struct PoseSet {
    poses: Vec<ObjectPose>,
    capacity: usize,
}

impl PoseSet {
    pub fn with_capacity(capacity: usize) -> Self {
        Self { poses: Vec::with_capacity(capacity), capacity }
    }

    pub fn clear(&mut self) {
        self.poses.clear();
    }

    /// Adds a pose; returns false (and drops it) when the set is full.
    pub fn push(&mut self, pose: ObjectPose) -> bool {
        if self.poses.len() >= self.capacity {
            return false;
        }
        self.poses.push(pose);
        true
    }

    /// Drops the poses whose confidence is below `min` (NaN counts as below);
    /// returns how many were dropped. No allocation.
    pub fn retain_confident(&mut self, min: f32) -> usize {
        let before = self.poses.len();
        if min > 0.0 {
            self.poses.retain(|p| p.confidence >= min);
        }
        before - self.poses.len()
    }

    /// Keeps the poses for which `keep` is true, visiting them in order once each. No allocation.
    pub fn retain(&mut self, keep: impl FnMut(&ObjectPose) -> bool) {
        self.poses.retain(keep);
    }

    /// Removes pose `i` where `dropped[i]` (poses beyond `dropped` stay) and
    /// returns how many went. No allocation.
    pub fn remove_marked(&mut self, dropped: &[bool]) -> usize {
        remove_marked(&mut self.poses, dropped)
    }

    /// Sorts the poses by `key` (unstable: give equal poses distinct keys). No allocation.
    pub fn sort_unstable_by_key<K: Ord>(&mut self, key: impl FnMut(&ObjectPose) -> K) {
        self.poses.sort_unstable_by_key(key);
    }

    pub fn as_slice(&self) -> &[ObjectPose] {
        &self.poses
    }

    /// Replaces pose `i` (nothing when there is none). No allocation.
    pub fn replace(&mut self, i: usize, pose: ObjectPose) {
        if let Some(p) = self.poses.get_mut(i) {
            *p = pose;
        }
    }

    pub fn len(&self) -> usize {
        self.poses.len()
    }

    pub fn is_empty(&self) -> bool {
        self.poses.is_empty()
    }

    pub fn capacity(&self) -> usize {
        self.capacity
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(class_id: u16, confidence: f32) -> ObjectPose {
        ObjectPose {
            class_id,
            instance_id: 0,
            rotation: UnitQuaternion::identity(),
            translation: Vector3::new(0.0, 0.0, 0.5),
            confidence,
            mask_pixels: 100,
            bbox: [0, 0, 9, 9],
            iterations: 0,
        }
    }

    #[test]
    fn retain_confident_drops_low_and_nan_confidence_in_order() {
        let mut set = PoseSet::with_capacity(4);
        for (c, conf) in [(1, 0.5), (2, 0.01), (3, f32::NAN), (4, 0.05)] {
            assert!(set.push(pose(c, conf)));
        }
        assert_eq!(set.retain_confident(0.0), 0, "0 keeps everything, NaN included");
        assert_eq!(set.retain_confident(0.05), 2);
        let kept: Vec<u16> = set.as_slice().iter().map(|p| p.class_id).collect();
        assert_eq!(kept, [1, 4]);
        assert_eq!(set.capacity(), 4);
    }
}
