//! Tracking mode: an object posed with a good fit in the previous frame of
//! the same camera starts the refiner from that pose instead of running the
//! pose net; the tracked pose is kept when its fit to the observed points
//! stays good, and a full estimate runs when it does not, when the object was
//! not seen in the previous frame, and every `full_estimate_every` frames
//! (drift guard).
//!
//! The fit is the median distance from the object's observed points (moved
//! into the object frame by the pose) to the nearest model surface sample,
//! metres: a geometric check that does not depend on the network's own
//! confidence.

use nalgebra::{Matrix3, Vector3};
use ndarray::ArrayView2;

use crate::icp::model_cloud::ModelCloud;
use fusepose_scene::ObjectSet;

/// Tracking settings (the daemon's `[estimator.tracking]` keys).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackingConfig {
    /// A pose is trusted (kept, and tracked from next frame) when its fit is
    /// at most this, metres.
    pub max_fit_m: f64,
    /// A full estimate at least every this many frames per object (1 = never track).
    pub full_estimate_every: u32,
    /// Refiner iterations from the previous pose (the frame's deadline plan may lower them, never below 1).
    pub refine_iterations: usize,
}

impl Default for TrackingConfig {
    fn default() -> Self {
        Self { max_fit_m: 0.008, full_estimate_every: 5, refine_iterations: 2 }
    }
}

/// A pose in the network's f32 form: rotation matrix and translation (object → camera, metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Prior {
    pub rotation: Matrix3<f32>,
    pub translation: Vector3<f32>,
    pub confidence: f32,
}

/// One class's track.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Track {
    prior: Prior,
    /// Frames since the last full estimate of this object.
    since_full: u32,
    /// Frame counter value when last updated.
    frame: u64,
}

/// Per-camera tracks, one per class (an estimator serves one camera).
#[derive(Clone, Debug)]
pub struct Tracks {
    config: TrackingConfig,
    tracks: Vec<Option<Track>>,
    frame: u64,
}

/// How one object's pose was obtained, for [`Tracks::update`] and statistics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrackOutcome {
    /// Whether the tracked pose was kept (no pose net this frame).
    pub tracked: bool,
    /// Fit of the final pose, metres (NaN when not checked).
    pub fit_m: f64,
}

impl Tracks {
    pub fn new(config: TrackingConfig, num_classes: usize) -> Self {
        Self { config, tracks: vec![None; num_classes], frame: 0 }
    }

    pub fn config(&self) -> &TrackingConfig {
        &self.config
    }

    /// Starts a new frame: tracks not updated in the previous frame are dropped.
    pub fn begin_frame(&mut self) {
        self.frame += 1;
        let frame = self.frame;
        for t in self.tracks.iter_mut() {
            if t.is_some_and(|t| t.frame + 1 < frame) {
                *t = None;
            }
        }
    }

    /// The prior for class `class_id` (1-based) this frame, if it may be tracked:
    /// seen in the previous frame with a good fit, and no full estimate due.
    pub fn prior(&self, class_id: u16) -> Option<Prior> {
        let t = self.tracks.get((class_id as usize).checked_sub(1)?)?.as_ref()?;
        let fresh = t.frame + 1 == self.frame;
        (fresh && t.since_full + 1 < self.config.full_estimate_every).then_some(t.prior)
    }

    /// Records class `class_id`'s final pose of this frame.
    pub fn update(&mut self, class_id: u16, pose: Prior, outcome: TrackOutcome) {
        let Some(slot) = (class_id as usize).checked_sub(1).and_then(|i| self.tracks.get_mut(i)) else {
            return;
        };
        // Written so that a NaN fit (a degenerate solve) also drops the track.
        #[allow(clippy::neg_cmp_op_on_partial_ord)]
        if !(outcome.fit_m <= self.config.max_fit_m) {
            *slot = None;
            return;
        }
        let since_full = if outcome.tracked { slot.map_or(0, |t| t.since_full) + 1 } else { 0 };
        *slot = Some(Track { prior: pose, since_full, frame: self.frame });
    }

    /// Forgets every track (e.g. after a camera jump).
    pub fn clear(&mut self) {
        self.tracks.iter_mut().for_each(|t| *t = None);
    }
}

/// Model surfaces of every class, for the fit check (shared by the threads).
pub struct FitCheck {
    clouds: Vec<Option<ModelCloud>>,
}

impl FitCheck {
    pub fn new(objects: &ObjectSet) -> Self {
        let clouds = (1..=objects.len() as u16).map(|c| objects.by_class(c).and_then(ModelCloud::new)).collect();
        Self { clouds }
    }

    /// Median distance of `points` (camera frame, metres; rows of x, y, z) to
    /// the model of class index `k` (0-based) posed at (`rotation`, `translation`),
    /// metres; NaN without a model or points. Uses at most 64 points (evenly spaced).
    pub fn fit_m(&self, k: usize, points: ArrayView2<f32>, rotation: &Matrix3<f32>, translation: &Vector3<f32>) -> f64 {
        const MAX_CHECKED: usize = 64;
        let Some(Some(cloud)) = self.clouds.get(k) else {
            return f64::NAN;
        };
        let n = points.nrows();
        if n == 0 {
            return f64::NAN;
        }
        let step = n.div_ceil(MAX_CHECKED).max(1);
        let rt = rotation.transpose().cast::<f64>();
        let t = translation.cast::<f64>();
        let mut d = [0.0f64; MAX_CHECKED];
        let mut count = 0;
        for row in points.rows().into_iter().step_by(step).take(MAX_CHECKED) {
            let p = Vector3::new(row[0] as f64, row[1] as f64, row[2] as f64);
            d[count] = cloud.nearest(&(rt * (p - t))).1;
            count += 1;
        }
        let d = &mut d[..count];
        let mid = count / 2;
        *d.select_nth_unstable_by(mid, f64::total_cmp).1
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn prior(x: f32) -> Prior {
        Prior { rotation: Matrix3::identity(), translation: Vector3::new(x, 0.0, 0.5), confidence: 0.9 }
    }

    const GOOD: TrackOutcome = TrackOutcome { tracked: false, fit_m: 0.002 };

    #[test]
    fn tracks_only_fresh_good_fits_and_forces_periodic_full_estimates() {
        let config = TrackingConfig { full_estimate_every: 3, ..TrackingConfig::default() };
        let mut t = Tracks::new(config, 2);
        t.begin_frame();
        assert_eq!(t.prior(1), None, "nothing seen yet");
        t.update(1, prior(0.1), GOOD);
        t.update(2, prior(0.2), TrackOutcome { tracked: false, fit_m: 0.05 });
        t.begin_frame();
        assert_eq!(t.prior(1), Some(prior(0.1)));
        assert_eq!(t.prior(2), None, "bad fit is not tracked");
        t.update(1, prior(0.11), TrackOutcome { tracked: true, fit_m: 0.003 });
        t.begin_frame();
        assert_eq!(t.prior(1), Some(prior(0.11)));
        t.update(1, prior(0.12), TrackOutcome { tracked: true, fit_m: 0.003 });
        t.begin_frame();
        assert_eq!(t.prior(1), None, "two tracked frames in a row: a full estimate is due (every 3)");
        t.update(1, prior(0.13), GOOD);
        t.begin_frame();
        assert!(t.prior(1).is_some());
        // Not seen for a frame: dropped.
        t.begin_frame();
        assert_eq!(t.prior(1), None);
        assert_eq!(t.prior(0), None);
        assert_eq!(t.prior(9), None);
    }

    #[test]
    fn fit_is_small_for_the_true_pose_and_large_for_a_shifted_one() {
        let objects = fusepose_scene::builtin::builtin_objects();
        let check = FitCheck::new(&objects);
        let model = objects.by_class(1).unwrap();
        let t = Vector3::new(0.0f32, 0.0, 0.6);
        let pts: Vec<f32> =
            model.samples.iter().step_by(7).flat_map(|p| [p.x as f32, p.y as f32, p.z as f32 + 0.6]).collect();
        let pts = ndarray::Array2::from_shape_vec((pts.len() / 3, 3), pts).unwrap();
        let good = check.fit_m(0, pts.view(), &Matrix3::identity(), &t);
        let bad = check.fit_m(0, pts.view(), &Matrix3::identity(), &(t + Vector3::new(0.04, 0.04, 0.04)));
        assert!(good < 0.002, "{good}");
        assert!(bad > TrackingConfig::default().max_fit_m, "a pose 7 cm off is not kept: {bad}");
        assert!(check.fit_m(99, pts.view(), &Matrix3::identity(), &t).is_nan());
    }
}
