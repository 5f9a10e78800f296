//! Class alternates: a region the segmenter was unsure of is estimated as its
//! runner-up class too, and the depth image decides.
//!
//! Why: objects of one colour (the untextured YCB brick, can and drill all
//! render in the same grey) are told apart by shape, which the segmenter sees
//! poorly at its reduced resolution and verification sees directly. A second
//! class costs only that class's head and refiner ([`crate::net`] runs the
//! shared features once), and is the first work a late frame sheds.
//!
//! Flow: [`mark`] after [`Workspace::prepare`] sets
//! [`crate::Instance::alt_class_id`]; the estimator then writes two poses with
//! the same `instance_id`; after verification [`losers`] marks all but the
//! best-fitting pose of each instance.

use crate::seg::SegEngine;
use crate::{ObjectPose, Workspace};

/// The daemon's and `fusepose eval`'s default minimum runner-up probability
/// (0 = off). On since session 23: with the segmenter's cells regrouped by
/// depth ([`crate::seg::DepthRegions`]) it passed the rule it had missed by
/// 0.08 points before (docs/BENCHMARKS.md, "Session 23").
pub const DEFAULT_MIN_PROBABILITY: f32 = 0.05;

/// The verification fit an alternate class's pose needs to pass (a pose of
/// the segmenter's own class needs `VerifyConfig::min_fit`). A small model
/// (a 5 cm brick) fits some part of almost any region fairly well; on the
/// YCB tuning splits, wrong alternates passed with fits of 0.35–0.65, right
/// ones with 0.73–0.96 (docs/BENCHMARKS.md, session 22).
pub const MIN_FIT: f32 = 0.7;

/// Whether `pose` is its instance's alternate class (not the class the
/// instance was segmented as).
pub fn is_alternate(instances: &[crate::Instance], pose: &ObjectPose) -> bool {
    instances.get(pose.instance_id as usize).is_some_and(|i| i.class_id != pose.class_id)
}

/// Whether `pose` is an alternate ([`is_alternate`]) whose verification `fit`
/// is below [`MIN_FIT`]: such a pose fails.
pub fn fails_as_alternate(instances: &[crate::Instance], pose: &ObjectPose, fit: f32) -> bool {
    // A NaN fit (nothing judged) fails too.
    is_alternate(instances, pose) && (fit < MIN_FIT || fit.is_nan())
}

/// Sets each instance's [`crate::Instance::alt_class_id`] to the class other
/// than its own with the highest mean segmenter probability over its region,
/// when that mean is at least `min_probability`; else 0. `min_probability`
/// 0 (or below) turns alternates off. `means` is scratch (grown once to the
/// segmenter's class count). Returns how many instances got an alternate.
/// The segmenter must have made this frame's regions.
pub fn mark(ws: &mut Workspace, seg: &SegEngine, min_probability: f32, means: &mut Vec<f32>) -> usize {
    let classes = seg.config().num_classes + 1;
    means.resize(classes, 0.0);
    let mut marked = 0;
    for i in 0..ws.instances.len() {
        let inst = ws.instances[i];
        let mut alt = 0;
        if min_probability > 0.0
            && let Some(id) = ws.component_id(i)
            && seg.region_class_means(ws.component_ids(), id, inst.bbox, means) > 0
        {
            let max_class = (ws.config.num_classes as usize).min(classes - 1);
            let best =
                (1..=max_class).filter(|&c| c != inst.class_id as usize).max_by(|&a, &b| means[a].total_cmp(&means[b]));
            if let Some(c) = best.filter(|&c| means[c] >= min_probability) {
                alt = c as u16;
            }
        }
        ws.instances[i].alt_class_id = alt;
        marked += (alt != 0) as usize;
    }
    marked
}

/// Marks in `marks` (one per pose) every pose that another pose of the same
/// instance beats: a passed verification beats a failed one, then the higher
/// verification fit (NaN lowest), then the earlier pose (the segmenter's
/// class comes first). `verdict(i)` is pose `i`'s (passed, fit). Returns how
/// many were marked. No allocation once `marks` has grown.
pub fn losers(poses: &[ObjectPose], verdict: impl Fn(usize) -> (bool, f32), marks: &mut Vec<bool>) -> usize {
    marks.clear();
    marks.resize(poses.len(), false);
    let key = |i: usize| {
        let (passed, fit) = verdict(i);
        (passed, if fit.is_nan() { f32::NEG_INFINITY } else { fit })
    };
    let beats = |a: usize, b: usize| {
        let ((pa, fa), (pb, fb)) = (key(a), key(b));
        pa & !pb || (pa == pb && (fa > fb || (fa == fb && a < b)))
    };
    let mut n = 0;
    for (i, p) in poses.iter().enumerate() {
        let beaten = poses.iter().enumerate().any(|(j, q)| j != i && q.instance_id == p.instance_id && beats(j, i));
        marks[i] = beaten;
        n += beaten as usize;
    }
    n
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pose(instance_id: u16, class_id: u16) -> ObjectPose {
        ObjectPose {
            class_id,
            instance_id,
            rotation: nalgebra::UnitQuaternion::identity(),
            translation: nalgebra::Vector3::new(0.0, 0.0, 0.5),
            confidence: 0.5,
            mask_pixels: 100,
            bbox: [0, 0, 9, 9],
            iterations: 0,
        }
    }

    #[test]
    fn the_better_fit_of_one_instance_wins_and_other_instances_stay() {
        let poses = [pose(0, 1), pose(0, 3), pose(1, 2)];
        let mut marks = Vec::new();
        let fit = [0.4, 0.7, 0.1];
        assert_eq!(losers(&poses, |i| (true, fit[i]), &mut marks), 1);
        assert_eq!(marks, [true, false, false]);
    }

    #[test]
    fn a_passed_pose_beats_a_failed_one_with_a_higher_fit() {
        let poses = [pose(0, 1), pose(0, 3)];
        let mut marks = Vec::new();
        losers(&poses, |i| ([true, false][i], [0.3, 0.9][i]), &mut marks);
        assert_eq!(marks, [false, true]);
    }

    #[test]
    fn a_tie_keeps_the_segmenters_class_and_nan_fits_lose() {
        let poses = [pose(2, 1), pose(2, 4)];
        let mut marks = Vec::new();
        losers(&poses, |_| (false, f32::NAN), &mut marks);
        assert_eq!(marks, [false, true]);
        losers(&poses, |i| (true, [f32::NAN, 0.2][i]), &mut marks);
        assert_eq!(marks, [true, false]);
    }
}
