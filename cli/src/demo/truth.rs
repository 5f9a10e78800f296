//! Ground truth of the demo camera's frames, recomputed by the consumer.
//!
//! `fusepose camera --synthetic` renders frame `n` from a scene sampled with a
//! seed and a view fixed by `n` ([`crate::camera::synthetic_frame_of`]); the
//! sampler is deterministic, so the consumer samples the same scene and knows
//! every object's true pose without a side channel. Frames are re-rendered
//! only for the few overlay images.

use std::collections::HashMap;

use anyhow::anyhow;
use fusepose_client::WireObjectPose;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, Scene, render_view_labelled, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet, Pose};
use nalgebra::{Quaternion, Translation3, UnitQuaternion};

use crate::camera::{synthetic_frame_of, synthetic_sampler};

/// One object in a frame: class id and true pose (object → camera, metres).
#[derive(Clone, Copy, Debug)]
pub struct TrueObject {
    pub class_id: u16,
    pub pose: Pose,
}

/// Scenes of the synthetic camera, sampled on demand and kept while in use.
pub struct SyntheticTruth {
    objects: ObjectSet,
    sampler: SamplerConfig,
    first_seed: u64,
    views_per_scene: usize,
    preload: usize,
    scenes: HashMap<u64, Scene>,
}

impl SyntheticTruth {
    /// The truth of a camera started with `--seed first_seed --views-per-scene
    /// views_per_scene --preload preload`.
    pub fn new(objects: ObjectSet, first_seed: u64, views_per_scene: usize, preload: usize) -> Self {
        let sampler = synthetic_sampler(views_per_scene);
        Self { objects, sampler, first_seed, views_per_scene, preload, scenes: HashMap::new() }
    }

    pub fn objects(&self) -> &ObjectSet {
        &self.objects
    }

    fn scene(&mut self, sequence: u64) -> anyhow::Result<(&Scene, usize)> {
        let (seed, view) = synthetic_frame_of(self.first_seed, self.views_per_scene, self.preload, sequence);
        if !self.scenes.contains_key(&seed) {
            // Frames arrive in order: older scenes are not needed again (a
            // preloaded loop holds only a few scenes: keep them all).
            if self.preload == 0 {
                self.scenes.retain(|s, _| *s > seed);
            }
            let scene = sample_scene(&self.objects, &self.sampler, seed).map_err(|e| anyhow!("scene {seed}: {e}"))?;
            self.scenes.insert(seed, scene);
        }
        Ok((&self.scenes[&seed], view))
    }

    /// Every object of frame `sequence` with its true pose (visible or not).
    pub fn frame(&mut self, sequence: u64) -> anyhow::Result<Vec<TrueObject>> {
        let (scene, view) = self.scene(sequence)?;
        let poses = scene.object_poses(view).ok_or_else(|| anyhow!("frame {sequence}: view {view} missing"))?;
        Ok(scene.objects.iter().zip(poses).map(|(o, pose)| TrueObject { class_id: o.class_id, pose }).collect())
    }

    /// Renders frame `sequence` exactly as the camera did (RGB and class-id labels).
    pub fn render(&mut self, sequence: u64, k: &Intrinsics) -> anyhow::Result<RenderTarget> {
        let mut target = RenderTarget::for_intrinsics(k);
        let (seed, view) = synthetic_frame_of(self.first_seed, self.views_per_scene, self.preload, sequence);
        self.scene(sequence)?;
        let scene = &self.scenes[&seed];
        render_view_labelled(scene, &self.objects, view, k, &NoiseConfig::default(), LabelKind::Class, &mut target)
            .map_err(|e| anyhow!("rendering frame {sequence}: {e}"))?;
        Ok(target)
    }
}

/// The pose a wire message carries, or `None` when it is not finite.
pub fn wire_pose(o: &WireObjectPose) -> Option<Pose> {
    let [x, y, z, w] = o.quaternion;
    let t = o.translation_m;
    if !o.quaternion.iter().chain(&t).all(|v| v.is_finite()) {
        return None;
    }
    let q = Quaternion::new(w, x, y, z);
    if q.norm() < 1e-6 {
        return None;
    }
    Some(Pose::from_parts(Translation3::new(t[0], t[1], t[2]), UnitQuaternion::from_quaternion(q)))
}

/// The true object an estimate of `class_id` at `estimate` refers to: the
/// instance of that class nearest in translation (classes rarely repeat).
pub fn match_truth<'a>(truth: &'a [TrueObject], class_id: u16, estimate: &Pose) -> Option<&'a TrueObject> {
    truth.iter().filter(|t| t.class_id == class_id).min_by(|a, b| {
        let da = (a.pose.translation.vector - estimate.translation.vector).norm();
        let db = (b.pose.translation.vector - estimate.translation.vector).norm();
        da.total_cmp(&db)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wire_pose_reads_xyzw_and_metres() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        // 90 degrees about z, stored [x, y, z, w].
        let o = WireObjectPose { quaternion: [0.0, 0.0, h, h], translation_m: [0.1, -0.2, 0.9], ..Default::default() };
        let p = wire_pose(&o).unwrap();
        let x_axis = p * nalgebra::Point3::new(1.0, 0.0, 0.0);
        assert!((x_axis - nalgebra::Point3::new(0.1, 0.8, 0.9)).norm() < 1e-12, "{x_axis}");
        assert!(wire_pose(&WireObjectPose { translation_m: [f64::NAN, 0.0, 1.0], ..o }).is_none());
        assert!(wire_pose(&WireObjectPose { quaternion: [0.0; 4], ..o }).is_none());
    }

    #[test]
    fn truth_follows_the_camera_frame_order() {
        let set = fusepose_scene::builtin::builtin_objects();
        let mut truth = SyntheticTruth::new(set.clone(), 42, 3, 0);
        // Frame 4 is scene 43, view 1.
        let scene = sample_scene(&set, &synthetic_sampler(3), 43).unwrap();
        let want = scene.object_poses(1).unwrap();
        let got = truth.frame(4).unwrap();
        assert_eq!(got.len(), want.len());
        for (g, w) in got.iter().zip(&want) {
            assert!((g.pose.translation.vector - w.translation.vector).norm() < 1e-12);
        }
        let first = truth.frame(0).unwrap();
        assert_ne!(first[0].pose.translation.vector, got[0].pose.translation.vector);
        // With 5 frames preloaded, frame 9 repeats frame 4.
        let mut looped = SyntheticTruth::new(set.clone(), 42, 3, 5);
        let again = looped.frame(9).unwrap();
        assert_eq!(again[0].pose.translation.vector, got[0].pose.translation.vector);
    }
}
