//! How right the poses a consumer receives are: each message is scored
//! against the truth of its frame, the producer's video rendered again from
//! the same seed or loaded from the same BOP split (frame sequence → video
//! frame by [`Video::frame_at`]).
//! A received pose finds a true object of its class when its ADD-S error
//! (the surface distance, what a grasp on the object's shape needs) is below
//! a tenth of the object's diameter, each true object taken once, smallest
//! errors first; it is also counted as right by ADD(S) (the print's
//! orientation too, ADD for objects without symmetry) when that error is
//! within the same bound. A pose that finds no object is wrong: a ghost, a
//! pose between copies, or one far off. So the live path's accuracy, with
//! its deadlines, degradation and carried cuts, is measured where it runs.

use fusepose_client::WireObjectPose;
use fusepose_scene::metrics::ObjectMetric;
use fusepose_scene::{ObjectSet, Pose};
use nalgebra::{Isometry3, Quaternion, Translation3, UnitQuaternion, Vector3};

use crate::video::{Source, Video};

/// True objects at least this visible count as ones to find.
pub const MIN_VISIBLE: f64 = 0.1;
/// A pose finds its object within this share of the diameter (ADD-S; ADD(S) for "right").
pub const MAX_ERROR_OF_DIAMETER: f64 = 0.1;

/// Counts over the scored messages.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AccuracyCounts {
    pub messages: u64,
    /// True objects at least [`MIN_VISIBLE`] visible in the scored frames.
    pub visible: u64,
    /// Of them, those a received pose finds (ADD-S).
    pub found: u64,
    /// Of those, the ones whose pose is right by ADD(S) too.
    pub right: u64,
    /// Poses received.
    pub poses: u64,
    /// Received poses that find no true object: a ghost, a pose between
    /// copies, or one far off.
    pub wrong: u64,
    /// Received poses with `PoseFlags::CONFIRMED` (a pose of their class lay
    /// near them in the previous frame), and how many of those are wrong.
    #[serde(default)]
    pub confirmed: u64,
    #[serde(default)]
    pub wrong_confirmed: u64,
    /// Received poses near no true object of their class (ADD-S at or above
    /// the bound for each: `fusepose eval`'s stray poses; a second pose of
    /// a found object is wrong but not stray), and of them the confirmed ones.
    #[serde(default)]
    pub stray: u64,
    #[serde(default)]
    pub stray_confirmed: u64,
    /// A found true object whose pose, the last time one found it, had the
    /// same `instance_id` (tracking mode's stable ids), or another.
    #[serde(default)]
    pub id_kept: u64,
    #[serde(default)]
    pub id_switched: u64,
}

impl AccuracyCounts {
    /// Share of the visible true objects found, percent.
    pub fn found_pct(&self) -> f64 {
        100.0 * self.found as f64 / self.visible.max(1) as f64
    }

    /// Share of the visible true objects posed right by ADD(S), percent.
    pub fn right_pct(&self) -> f64 {
        100.0 * self.right as f64 / self.visible.max(1) as f64
    }

    /// Wrong poses per message.
    pub fn wrong_per_message(&self) -> f64 {
        self.wrong as f64 / self.messages.max(1) as f64
    }
}

/// The producer's video again, with what scoring needs.
pub struct Truths {
    video: Video,
    set: ObjectSet,
    metrics: Vec<ObjectMetric>,
}

impl Truths {
    /// The video of producer argument `source` ([`Source::parse_arg`]),
    /// `seed` and `frames`, as the producer renders or loads it.
    pub fn load(source: &str, seed: u64, frames: usize) -> anyhow::Result<Self> {
        let set = fusepose_scene::builtin::builtin_objects();
        let video = Source::parse_arg(source)?.load(&set, seed, frames)?;
        let metrics = set.objects.iter().map(ObjectMetric::for_model).collect::<Result<_, _>>()?;
        Ok(Self { video, set, metrics })
    }

    /// Scores the poses of the message for frame `sequence` into `counts`;
    /// `last_ids[j]`: the `instance_id` of the last pose that found true
    /// object `j` (the video's objects, in the messages' order).
    pub fn score(
        &self,
        sequence: u64,
        poses: &[WireObjectPose],
        counts: &mut AccuracyCounts,
        last_ids: &mut Vec<Option<u16>>,
    ) {
        let frame = self.video.frame_at(sequence as usize);
        counts.messages += 1;
        counts.poses += poses.len() as u64;
        counts.visible += frame.visible.iter().filter(|&&v| v >= MIN_VISIBLE).count() as u64;
        // Every (pose, true object) pair of one class within the bound, smallest error first.
        let mut pairs = Vec::new();
        for (i, p) in poses.iter().enumerate() {
            let Some(metric) = self.metrics.get((p.class_id as usize).wrapping_sub(1)) else { continue };
            let diameter = self.set.by_class(p.class_id).map_or(0.0, |o| o.diameter);
            let estimate = pose_of(p);
            for (j, (class_id, truth)) in frame.truth.iter().enumerate() {
                if *class_id != p.class_id {
                    continue;
                }
                let bound = MAX_ERROR_OF_DIAMETER * diameter;
                let e = metric.add_s(&estimate, truth);
                if e < bound {
                    pairs.push((e, i, j, metric.add_or_add_s(&estimate, truth) < bound));
                }
            }
        }
        let mut near = vec![false; poses.len()];
        pairs.iter().for_each(|&(_, i, _, _)| near[i] = true);
        counts.stray += near.iter().filter(|&&n| !n).count() as u64;
        counts.stray_confirmed += poses.iter().zip(&near).filter(|(p, n)| p.is_confirmed() && !**n).count() as u64;
        pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (mut pose_taken, mut truth_taken) = (vec![false; poses.len()], vec![false; frame.truth.len()]);
        for (_, i, j, right) in pairs {
            if !pose_taken[i] && !truth_taken[j] {
                (pose_taken[i], truth_taken[j]) = (true, true);
                if last_ids.len() <= j {
                    last_ids.resize(j + 1, None);
                }
                let id = poses[i].instance_id;
                match last_ids[j].replace(id) {
                    Some(last) if last == id => counts.id_kept += 1,
                    Some(_) => counts.id_switched += 1,
                    None => {}
                }
                let visible = frame.visible[j] >= MIN_VISIBLE;
                counts.found += visible as u64;
                counts.right += (visible && right) as u64;
            }
        }
        counts.wrong += pose_taken.iter().filter(|&&t| !t).count() as u64;
        counts.confirmed += poses.iter().filter(|p| p.is_confirmed()).count() as u64;
        counts.wrong_confirmed +=
            poses.iter().zip(&pose_taken).filter(|(p, t)| p.is_confirmed() && !**t).count() as u64;
    }
}

/// A wire pose (quaternion `[x, y, z, w]`, metres) as an object → camera pose.
fn pose_of(p: &WireObjectPose) -> Pose {
    let [x, y, z, w] = p.quaternion;
    let [tx, ty, tz] = p.translation_m;
    Isometry3::from_parts(
        Translation3::from(Vector3::new(tx, ty, tz)),
        UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z)),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wire(class_id: u16, pose: &Pose) -> WireObjectPose {
        let q = pose.rotation.quaternion();
        let t = pose.translation.vector;
        WireObjectPose {
            class_id,
            quaternion: [q.i, q.j, q.k, q.w],
            translation_m: [t.x, t.y, t.z],
            ..WireObjectPose::default()
        }
    }

    #[test]
    fn true_poses_are_found_and_a_shifted_or_second_pose_is_wrong() {
        let truths = Truths::load("3", 11, 2).unwrap();
        let frame = &truths.video.frames[0];
        let exact: Vec<WireObjectPose> = frame.truth.iter().map(|(c, p)| wire(*c, p)).collect();
        let mut counts = AccuracyCounts::default();
        truths.score(0, &exact, &mut counts, &mut Vec::new());
        let visible = frame.visible.iter().filter(|&&v| v >= MIN_VISIBLE).count() as u64;
        let all = AccuracyCounts {
            messages: 1,
            visible,
            found: visible,
            right: visible,
            poses: exact.len() as u64,
            wrong: 0,
            confirmed: 0,
            wrong_confirmed: 0,
            stray: 0,
            stray_confirmed: 0,
            id_kept: 0,
            id_switched: 0,
        };
        assert_eq!(counts, all);
        // The same objects found again: their ids kept, or one switched.
        let mut last_ids = Vec::new();
        let mut counts = AccuracyCounts::default();
        truths.score(0, &exact, &mut counts, &mut last_ids);
        let mut again = exact.clone();
        truths.score(0, &again, &mut counts, &mut last_ids);
        assert_eq!((counts.id_kept, counts.id_switched), (exact.len() as u64, 0));
        again[0].instance_id = 7;
        truths.score(0, &again, &mut counts, &mut last_ids);
        assert_eq!((counts.id_kept, counts.id_switched), (2 * exact.len() as u64 - 1, 1));
        // The first object 20 cm off, and the second posed twice: both extra poses are wrong.
        // The first and the extra one carry CONFIRMED, as does one right pose.
        let mut off = exact.clone();
        off[0].translation_m[0] += 0.2;
        off.push(exact[1]);
        for i in [0, 2, off.len() - 1] {
            off[i].flags |= fusepose_client::PoseFlags::CONFIRMED;
        }
        let mut counts = AccuracyCounts::default();
        truths.score(0, &off, &mut counts, &mut Vec::new());
        assert_eq!(counts.wrong, 2, "{counts:?}");
        assert_eq!((counts.confirmed, counts.wrong_confirmed), (3, 2), "{counts:?}");
        // The second pose of a found object is wrong, not stray: it lies on an object.
        assert_eq!((counts.stray, counts.stray_confirmed), (1, 1), "{counts:?}");
        assert_eq!(counts.found, visible - (frame.visible[0] >= MIN_VISIBLE) as u64);
        // A box turned half about its own z axis: the same shape (ADD-S finds
        // it), the print the other way (ADD of an asymmetric object does not).
        let b = frame.truth.iter().position(|(c, _)| matches!(c, 1 | 2)).expect("the scene holds a printed box");
        let mut flipped = exact.clone();
        let turned = frame.truth[b].1 * UnitQuaternion::from_scaled_axis(Vector3::z() * std::f64::consts::PI);
        flipped[b] = wire(frame.truth[b].0, &turned);
        let mut counts = AccuracyCounts::default();
        truths.score(0, &flipped, &mut counts, &mut Vec::new());
        let seen = (frame.visible[b] >= MIN_VISIBLE) as u64;
        assert_eq!((counts.found, counts.right, counts.wrong), (visible, visible - seen, 0), "{counts:?}");
        // Sequence 3 of a 2-frame video plays frame 1 (ping-pong).
        let mut counts = AccuracyCounts::default();
        let second: Vec<WireObjectPose> = truths.video.frames[1].truth.iter().map(|(c, p)| wire(*c, p)).collect();
        truths.score(3, &second, &mut counts, &mut Vec::new());
        assert_eq!(counts.wrong, 0);
    }

    /// Truths of a BOP split source: the split's true poses are all found
    /// and right at every step, each image held its steps; one 20 cm off is not.
    #[test]
    fn a_bop_split_source_scores_its_own_truth() {
        let root = std::env::temp_dir().join(format!("fusepose-bench-bop-truths-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        crate::video::write_test_split(&root, 2).unwrap();
        let truths = Truths::load(&format!("bop:2:{}", root.display()), 0, 0).unwrap();
        for step in 0..5 {
            let frame = truths.video.frame_at(step);
            let exact: Vec<WireObjectPose> = frame.truth.iter().map(|(c, p)| wire(*c, p)).collect();
            let mut counts = AccuracyCounts::default();
            truths.score(step as u64, &exact, &mut counts, &mut Vec::new());
            let visible = frame.visible.iter().filter(|&&v| v >= MIN_VISIBLE).count() as u64;
            assert!(visible > 0);
            assert_eq!((counts.found, counts.right, counts.wrong), (visible, visible, 0), "step {step}: {counts:?}");
            let mut off = exact.clone();
            off[0].translation_m[2] += 0.2;
            let mut counts = AccuracyCounts::default();
            truths.score(step as u64, &off, &mut counts, &mut Vec::new());
            assert_eq!(counts.wrong, 1, "step {step}: {counts:?}");
        }
        std::fs::remove_dir_all(&root).ok();
    }
}
