//! Duplicate poses: two poses of one class whose centres are closer than two
//! solid copies of that object can be. A segmenter that cuts one object into
//! two instances (or a region that straddles an object's parts) yields two
//! poses of the same physical object; the weaker one is a grasp at an object
//! that is already taken, counted as a ghost by the evaluation.
//!
//! Two non-interpenetrating copies of an object keep their centres at least
//! about its smallest bounding-box side apart (a box lying on a box, two cans
//! side by side), so a pose closer than a fraction of that side to a
//! better-scored pose of its class is dropped. Scores are the caller's:
//! the depth-verification fit when verifying, else the network's confidence.

use fusepose_scene::ObjectSet;

use crate::poses::PoseSet;

/// Per-class minimum centre distance for [`suppress`]: `factor` × each
/// object's smallest bounding-box side, metres; empty (never suppress) when
/// `factor` is not positive.
pub fn separations(objects: &ObjectSet, factor: f32) -> Vec<f32> {
    if factor.is_nan() || factor <= 0.0 {
        return Vec::new();
    }
    objects.objects.iter().map(|o| ((o.bbox_max - o.bbox_min).min() * factor as f64) as f32).collect()
}

/// Marks in `dropped` (resized to the pose count; no allocation within its
/// capacity) each pose that has a better-scored pose of its class (ties: the
/// earlier one wins) within `separation[class - 1]` metres, removes them from
/// `poses` and returns how many. `scores[i]` ranks pose `i`; NaN ranks lowest.
/// Classes beyond `separation` are never suppressed.
pub fn suppress(poses: &mut PoseSet, separation: &[f32], scores: &[f32], dropped: &mut Vec<bool>) -> usize {
    let all = poses.as_slice();
    debug_assert_eq!(scores.len(), all.len());
    let score = |i: usize| scores.get(i).copied().filter(|s| !s.is_nan()).unwrap_or(f32::NEG_INFINITY);
    dropped.clear();
    dropped.resize(all.len(), false);
    for (i, p) in all.iter().enumerate() {
        let Some(&min) = separation.get(p.class_id as usize - 1) else { continue };
        let min2 = (min as f64) * (min as f64);
        dropped[i] = all.iter().enumerate().any(|(j, q)| {
            j != i
                && q.class_id == p.class_id
                && (q.translation - p.translation).norm_squared() < min2
                && (score(j) > score(i) || (score(j) == score(i) && j < i))
        });
    }
    poses.remove_marked(dropped)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::poses::ObjectPose;
    use nalgebra::{UnitQuaternion, Vector3};

    fn pose(class_id: u16, x: f64) -> ObjectPose {
        ObjectPose {
            class_id,
            instance_id: 0,
            rotation: UnitQuaternion::identity(),
            translation: Vector3::new(x, 0.0, 0.8),
            confidence: 0.5,
            mask_pixels: 100,
            bbox: [0; 4],
            iterations: 0,
        }
    }

    #[test]
    fn the_weaker_of_two_close_poses_of_a_class_goes_and_neighbours_stay() {
        let mut set = PoseSet::with_capacity(8);
        // Class 1: two poses 1 cm apart (one object cut in two) and one 6 cm away
        // (a second copy, touching); class 2 at the same place as class 1.
        for p in [pose(1, 0.0), pose(1, 0.01), pose(1, 0.07), pose(2, 0.005)] {
            set.push(p);
        }
        let mut dropped = Vec::with_capacity(8);
        let n = suppress(&mut set, &[0.03, 0.03], &[0.4, 0.9, 0.5, 0.1], &mut dropped);
        assert_eq!(n, 1);
        assert_eq!(dropped, vec![true, false, false, false]);
        let xs: Vec<(u16, f64)> = set.as_slice().iter().map(|p| (p.class_id, p.translation.x)).collect();
        assert_eq!(xs, vec![(1, 0.01), (1, 0.07), (2, 0.005)]);
        // Equal scores: the earlier pose wins; NaN loses to any score.
        let mut set = PoseSet::with_capacity(4);
        set.push(pose(1, 0.0));
        set.push(pose(1, 0.0));
        assert_eq!(suppress(&mut set, &[0.03], &[0.5, 0.5], &mut dropped), 1);
        assert_eq!(dropped, vec![false, true]);
        let mut set = PoseSet::with_capacity(4);
        set.push(pose(1, 0.0));
        set.push(pose(1, 0.0));
        assert_eq!(suppress(&mut set, &[0.03], &[f32::NAN, 0.1], &mut dropped), 1);
        assert_eq!(dropped, vec![true, false]);
    }

    #[test]
    fn separations_follow_the_smallest_side_and_zero_turns_it_off() {
        let set = fusepose_scene::builtin::builtin_objects();
        let s = separations(&set, 0.5);
        assert_eq!(s.len(), set.len());
        for (o, s) in set.objects.iter().zip(&s) {
            let side = (o.bbox_max - o.bbox_min).min();
            assert!((*s as f64 - 0.5 * side).abs() < 1e-6 && side > 0.01, "{}: {s}", o.name);
        }
        assert!(separations(&set, 0.0).is_empty());
        let mut poses = PoseSet::with_capacity(2);
        poses.push(pose(1, 0.0));
        poses.push(pose(1, 0.0));
        assert_eq!(suppress(&mut poses, &[], &[0.1, 0.2], &mut Vec::new()), 0);
        assert_eq!(poses.len(), 2);
    }
}
