//! The ICP baseline: model-to-depth registration per instance.
//!
//! Direction: **observed → model**. Each observed point (the visible side of
//! the object only) is matched to its nearest model surface sample through a
//! k-d tree built once per object at construction; matching the other way
//! would pull back-facing model points onto the visible surface. The loop
//! works on the camera → object transform and is inverted at the end.
//!
//! Per instance:
//! 1. **Initialisation**: the observed centroid pushed back along the viewing
//!    ray by half the model's mean radius (the visible surface lies in front
//!    of the object centre), combined with each of `rotation_hypotheses`
//!    near-uniform rotations ([`rotation_grid`]). Each hypothesis runs
//!    `hypothesis_iterations` quick point-to-plane steps on a subset of
//!    `hypothesis_points` observed points and is scored by the trimmed mean
//!    nearest-neighbour distance plus, when a depth image is at hand, a
//!    free-space penalty: the fraction of (a subset of) model points that
//!    project in front of the observed depth by more than
//!    `visibility_tolerance` (the model would hide what the camera sees),
//!    times `visibility_weight`. The penalty separates poses that explain the
//!    visible surface equally well (e.g. flips of a partial view). The best
//!    `refine_candidates` hypotheses each get `candidate_iterations` more
//!    steps on `candidate_points` observed points and are re-scored the
//!    same way; the best goes on to step 2.
//! 2. **Refinement**: point-to-plane ICP on all distinct observed points, up
//!    to `max_iterations`: correspondences trimmed to the best `trim_fraction`
//!    and rejected beyond `max_correspondence_distance`; each step solves the
//!    damped 6×6 normal equations (Cholesky, nalgebra, on the stack).
//! 3. **Score**: confidence = inlier fraction (nearest distance below
//!    `inlier_distance`) × exp(−rmse / `rmse_scale`), rmse over the kept
//!    correspondences.
//!
//! Allocation: the model trees and hypothesis list are built in
//! [`IcpEstimator::new`]; per-instance scratch buffers are sized on the first
//! call for the workspace's N and reused (grow only if N grows).

pub(crate) mod model_cloud;
pub mod rotation_grid;

use fusepose_scene::ObjectSet;
use nalgebra::{Matrix6, UnitQuaternion, Vector3, Vector6};

use crate::frame::FrameView;
use crate::poses::{ObjectPose, PoseSet};
use crate::workspace::Workspace;
use crate::{EstimateError, Estimator};
pub use model_cloud::{MIN_MODEL_SAMPLES, ModelCloud};

/// ICP settings; lengths in metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IcpConfig {
    /// Rotation hypotheses tried per instance (near-uniform over SO(3)).
    pub rotation_hypotheses: usize,
    /// Observed points used to score each hypothesis.
    pub hypothesis_points: usize,
    /// Point-to-plane steps run on each hypothesis before scoring.
    pub hypothesis_iterations: usize,
    /// Iteration cap of the final refinement.
    pub max_iterations: usize,
    /// Fraction of correspondences kept (the closest ones), in (0, 1].
    pub trim_fraction: f64,
    /// Correspondences farther than this are rejected in the refinement, metres.
    pub max_correspondence_distance: f64,
    /// An observed point closer than this to the model counts as an inlier, metres.
    pub inlier_distance: f64,
    /// Scale of the rmse term of the confidence, metres.
    pub rmse_scale: f64,
    /// Best hypotheses (1..=8) kept after scoring; each gets
    /// `candidate_iterations` steps on `candidate_points` observed points and
    /// is re-scored (with the free-space penalty); the best is refined fully.
    pub refine_candidates: usize,
    /// Steps run on each kept candidate.
    pub candidate_iterations: usize,
    /// Observed points used for the candidate steps.
    pub candidate_points: usize,
    /// Model points (a strided subset of at most this many) checked for
    /// free-space violations when scoring hypotheses against a depth image.
    pub visibility_points: usize,
    /// A model point in front of the observed depth by more than this is a
    /// free-space violation, metres.
    pub visibility_tolerance: f64,
    /// Hypothesis score penalty per unit violation fraction, metres.
    pub visibility_weight: f64,
    /// Refinement stops when a step rotates less than this (radians) ...
    pub converged_rotation: f64,
    /// ... and translates less than this, metres.
    pub converged_translation: f64,
}

impl Default for IcpConfig {
    fn default() -> Self {
        Self {
            rotation_hypotheses: 60,
            hypothesis_points: 64,
            hypothesis_iterations: 3,
            max_iterations: 30,
            trim_fraction: 0.8,
            max_correspondence_distance: 0.02,
            inlier_distance: 0.01,
            rmse_scale: 0.01,
            refine_candidates: 8,
            candidate_iterations: 30,
            candidate_points: 512,
            visibility_points: 256,
            visibility_tolerance: 0.01,
            visibility_weight: 0.05,
            converged_rotation: 5e-4,
            converged_translation: 5e-5,
        }
    }
}

/// Why an [`IcpEstimator`] could not be built.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum IcpError {
    #[error("object `{name}` has {samples} finite surface samples; ICP needs at least {MIN_MODEL_SAMPLES}")]
    TooFewSamples { name: String, samples: usize },
    #[error("invalid ICP config: {0}")]
    BadConfig(&'static str),
}

/// Result of registering one observed cloud.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct IcpFit {
    /// Rotation object → camera.
    pub rotation: UnitQuaternion<f64>,
    /// Translation object → camera, metres.
    pub translation: Vector3<f64>,
    /// RMS distance of the kept correspondences, metres.
    pub rmse: f64,
    /// Fraction of observed points within `inlier_distance` of the model.
    pub inlier_fraction: f64,
    /// inlier_fraction × exp(−rmse / rmse_scale), in [0, 1].
    pub confidence: f64,
    /// Refinement iterations run.
    pub iterations: usize,
}

/// The ICP baseline estimator.
pub struct IcpEstimator {
    config: IcpConfig,
    /// `models[class_id - 1]`.
    models: Vec<ModelCloud>,
    hypotheses: Vec<UnitQuaternion<f64>>,
    scratch: Scratch,
}

/// Per-instance buffers, reused across instances and frames.
#[derive(Default)]
struct Scratch {
    observed: Vec<Vector3<f64>>,
    distances: Vec<f64>,
    matches: Vec<u32>,
    selection: Vec<f64>,
}

impl Scratch {
    fn reserve(&mut self, n: usize) {
        for v in [&mut self.distances, &mut self.selection] {
            if v.capacity() < n {
                v.reserve(n - v.len());
            }
        }
        if self.observed.capacity() < n {
            self.observed.reserve(n - self.observed.len());
        }
        if self.matches.capacity() < n {
            self.matches.reserve(n - self.matches.len());
        }
    }
}

/// A camera → object rigid transform: q_obj = r · p_cam + t.
#[derive(Clone, Copy, Debug)]
struct CamToObj {
    r: UnitQuaternion<f64>,
    t: Vector3<f64>,
}

impl CamToObj {
    const IDENTITY: CamToObj = CamToObj {
        r: UnitQuaternion::new_unchecked(nalgebra::Quaternion::new(1.0, 0.0, 0.0, 0.0)),
        t: Vector3::new(0.0, 0.0, 0.0),
    };

    #[inline]
    fn apply(&self, p: &Vector3<f64>) -> Vector3<f64> {
        self.r * p + self.t
    }
}

/// Outcome of one Gauss–Newton step.
struct Step {
    rotation: f64,
    translation: f64,
    ok: bool,
}

impl IcpEstimator {
    /// Builds the per-object k-d trees and normals (allocates; call once).
    pub fn new(objects: &ObjectSet, config: IcpConfig) -> Result<Self, IcpError> {
        if config.rotation_hypotheses == 0 {
            return Err(IcpError::BadConfig("rotation_hypotheses must be >= 1"));
        }
        if !(config.trim_fraction > 0.0 && config.trim_fraction <= 1.0) {
            return Err(IcpError::BadConfig("trim_fraction must be in (0, 1]"));
        }
        for (v, what) in [
            (config.max_correspondence_distance, "max_correspondence_distance must be > 0"),
            (config.inlier_distance, "inlier_distance must be > 0"),
            (config.rmse_scale, "rmse_scale must be > 0"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(IcpError::BadConfig(what));
            }
        }
        let models = objects
            .objects
            .iter()
            .map(|m| {
                ModelCloud::new(m).ok_or_else(|| IcpError::TooFewSamples {
                    name: m.name.clone(),
                    samples: m.samples.iter().filter(|p| p.coords.iter().all(|x| x.is_finite())).count(),
                })
            })
            .collect::<Result<Vec<_>, _>>()?;
        Ok(Self {
            config,
            models,
            hypotheses: rotation_grid::super_fibonacci(config.rotation_hypotheses),
            scratch: Scratch::default(),
        })
    }

    pub fn config(&self) -> &IcpConfig {
        &self.config
    }

    /// Registers the model of `class_id` to `points` (camera frame, metres,
    /// the visible surface), without a depth image (no free-space check).
    /// `None` for an unknown class or fewer than 3 finite points.
    pub fn fit(&mut self, class_id: u16, points: &[[f32; 3]]) -> Option<IcpFit> {
        self.fit_with_depth(class_id, points, None)
    }

    /// As [`fit`](Self::fit), scoring hypotheses also against the frame's
    /// depth image (free-space violations); `frame` must be validated.
    pub fn fit_in_frame(&mut self, frame: &FrameView<'_>, class_id: u16, points: &[[f32; 3]]) -> Option<IcpFit> {
        self.fit_with_depth(class_id, points, Some(frame))
    }

    fn fit_with_depth(&mut self, class_id: u16, points: &[[f32; 3]], frame: Option<&FrameView<'_>>) -> Option<IcpFit> {
        let model = (class_id as usize).checked_sub(1).and_then(|i| self.models.get(i))?;
        let cfg = &self.config;
        let s = &mut self.scratch;
        s.reserve(points.len());
        s.observed.clear();
        s.observed.extend(
            points
                .iter()
                .filter(|p| p.iter().all(|x| x.is_finite()))
                .map(|p| Vector3::new(p[0] as f64, p[1] as f64, p[2] as f64)),
        );
        if s.observed.len() < 3 {
            return None;
        }
        let mut candidates = [(f64::MAX, CamToObj::IDENTITY); MAX_REFINE_CANDIDATES];
        let kept = cfg.refine_candidates.clamp(1, MAX_REFINE_CANDIDATES);
        best_hypotheses(model, cfg, &self.hypotheses, s, frame, &mut candidates[..kept]);
        // Step 2: a short refinement of each candidate on a subset, then the
        // full refinement of the best one only.
        let stride = s.observed.len().div_ceil(cfg.candidate_points.max(3)).max(1);
        let mut best: Option<(f64, CamToObj)> = None;
        for &(score, mut tf) in &candidates[..kept] {
            if score == f64::MAX {
                continue;
            }
            for _ in 0..cfg.candidate_iterations {
                let st = step(model, cfg, s, &mut tf, stride, cfg.max_correspondence_distance);
                if !st.ok || (st.rotation < cfg.converged_rotation && st.translation < cfg.converged_translation) {
                    break;
                }
            }
            let mut final_score = trimmed_mean_distance(model, cfg, s, &tf, stride);
            if let Some(frame) = frame {
                final_score += cfg.visibility_weight * free_space_violations(model, cfg, frame, &tf);
            }
            if best.is_none_or(|(b, _)| final_score < b) {
                best = Some((final_score, tf));
            }
        }
        best.map(|(_, tf)| refine(model, cfg, s, tf).0)
    }
}

impl Estimator for IcpEstimator {
    fn name(&self) -> &str {
        "icp"
    }

    /// One pose per instance whose class has a model and at least 3 points;
    /// an instance of a class the estimator does not know fails the frame
    /// with [`EstimateError::UnknownClass`] before any work.
    fn estimate(&mut self, frame: &FrameView<'_>, ws: &mut Workspace, out: &mut PoseSet) -> Result<(), EstimateError> {
        out.clear();
        if let Some(bad) = ws.instances.iter().find(|i| i.class_id == 0 || i.class_id as usize > self.models.len()) {
            return Err(EstimateError::UnknownClass(bad.class_id));
        }
        let n = ws.config.num_points;
        for (k, inst) in ws.instances.iter().enumerate() {
            let points = ws.instance_points(k);
            let points = &points[..inst.distinct_points(n).min(points.len())];
            let Some(fit) = self.fit_in_frame(frame, inst.class_id, points) else { continue };
            out.push(ObjectPose {
                class_id: inst.class_id,
                instance_id: k as u16,
                rotation: fit.rotation,
                translation: fit.translation,
                confidence: fit.confidence as f32,
                mask_pixels: inst.pixels,
                bbox: inst.bbox,
                iterations: fit.iterations.min(u16::MAX as usize) as u16,
            });
        }
        Ok(())
    }
}

/// Most hypotheses refined per instance.
pub const MAX_REFINE_CANDIDATES: usize = 8;

/// Tries every rotation hypothesis; leaves the best `best.len()` camera →
/// object transforms in `best`, lowest score first (unused slots keep f64::MAX).
fn best_hypotheses(
    model: &ModelCloud,
    cfg: &IcpConfig,
    hypotheses: &[UnitQuaternion<f64>],
    s: &mut Scratch,
    frame: Option<&FrameView<'_>>,
    best: &mut [(f64, CamToObj)],
) {
    let count = s.observed.len();
    let centroid = s.observed.iter().sum::<Vector3<f64>>() / count as f64;
    let view = if centroid.norm() > 1e-9 { centroid.normalize() } else { Vector3::z() };
    let centre_cam = centroid + view * (0.5 * model.mean_radius);
    let stride = count.div_ceil(cfg.hypothesis_points.max(3)).max(1);
    for rot in hypotheses {
        // Object → camera: p_cam = rot · (q − centre) + centre_cam; invert.
        let r = rot.inverse();
        let mut tf = CamToObj { r, t: model.centre - r * centre_cam };
        for _ in 0..cfg.hypothesis_iterations {
            if !step(model, cfg, s, &mut tf, stride, f64::INFINITY).ok {
                break;
            }
        }
        let mut score = trimmed_mean_distance(model, cfg, s, &tf, stride);
        if let Some(frame) = frame {
            score += cfg.visibility_weight * free_space_violations(model, cfg, frame, &tf);
        }
        // Insert into the sorted top list.
        if let Some(at) = best.iter().position(|(b, _)| score < *b) {
            best[at..].rotate_right(1);
            best[at] = (score, tf);
        }
    }
}

/// Full point-to-plane refinement from `tf`, then scoring.
fn refine(model: &ModelCloud, cfg: &IcpConfig, s: &mut Scratch, mut tf: CamToObj) -> (IcpFit, CamToObj) {
    let mut iterations = 0;
    for _ in 0..cfg.max_iterations {
        let st = step(model, cfg, s, &mut tf, 1, cfg.max_correspondence_distance);
        iterations += 1;
        if !st.ok || (st.rotation < cfg.converged_rotation && st.translation < cfg.converged_translation) {
            break;
        }
    }
    // Final residuals.
    let count = s.observed.len();
    s.distances.clear();
    for p in &s.observed {
        s.distances.push(model.nearest(&tf.apply(p)).1);
    }
    let inliers = s.distances.iter().filter(|&&d| d < cfg.inlier_distance).count();
    let threshold =
        trim_threshold(&s.distances, &mut s.selection, cfg.trim_fraction).min(cfg.max_correspondence_distance);
    let (sum_sq, kept) =
        s.distances.iter().filter(|&&d| d <= threshold).fold((0.0, 0usize), |(acc, k), d| (acc + d * d, k + 1));
    let rmse = if kept > 0 { (sum_sq / kept as f64).sqrt() } else { f64::INFINITY };
    let inlier_fraction = inliers as f64 / count as f64;
    let confidence = (inlier_fraction * (-rmse / cfg.rmse_scale).exp()).clamp(0.0, 1.0);
    let rotation = tf.r.inverse();
    (IcpFit { rotation, translation: -(rotation * tf.t), rmse, inlier_fraction, confidence, iterations }, tf)
}

/// One damped point-to-plane Gauss–Newton step over every `stride`-th
/// observed point; correspondences trimmed and rejected beyond `max_distance`.
fn step(
    model: &ModelCloud,
    cfg: &IcpConfig,
    s: &mut Scratch,
    tf: &mut CamToObj,
    stride: usize,
    max_distance: f64,
) -> Step {
    s.distances.clear();
    s.matches.clear();
    for p in s.observed.iter().step_by(stride) {
        let (j, d) = model.nearest(&tf.apply(p));
        s.distances.push(d);
        s.matches.push(j as u32);
    }
    let threshold = trim_threshold(&s.distances, &mut s.selection, cfg.trim_fraction).min(max_distance);
    let mut a = Matrix6::<f64>::zeros();
    let mut b = Vector6::<f64>::zeros();
    let mut used = 0usize;
    for (k, p) in s.observed.iter().step_by(stride).enumerate() {
        if s.distances[k] > threshold {
            continue;
        }
        let j = s.matches[k] as usize;
        let q = tf.apply(p);
        let n = model.normals[j];
        let residual = (q - model.points[j]).dot(&n);
        let c = q.cross(&n);
        let jac = Vector6::new(c.x, c.y, c.z, n.x, n.y, n.z);
        a += jac * jac.transpose();
        b += jac * residual;
        used += 1;
    }
    if used < 6 {
        return Step { rotation: 0.0, translation: 0.0, ok: false };
    }
    // Levenberg damping keeps flat or symmetric views solvable.
    let damping = 1e-9 + 1e-6 * a.trace() / 6.0;
    for i in 0..6 {
        a[(i, i)] += damping;
    }
    let Some(chol) = a.cholesky() else {
        return Step { rotation: 0.0, translation: 0.0, ok: false };
    };
    let x = chol.solve(&(-b));
    let mut omega = Vector3::new(x[0], x[1], x[2]);
    let mut delta = Vector3::new(x[3], x[4], x[5]);
    if !(omega.iter().chain(delta.iter()).all(|v| v.is_finite())) {
        return Step { rotation: 0.0, translation: 0.0, ok: false };
    }
    // Cap a single step: the linearisation only holds for small motions.
    const MAX_STEP_ROTATION: f64 = 0.3;
    const MAX_STEP_TRANSLATION: f64 = 0.05;
    if omega.norm() > MAX_STEP_ROTATION {
        omega *= MAX_STEP_ROTATION / omega.norm();
    }
    if delta.norm() > MAX_STEP_TRANSLATION {
        delta *= MAX_STEP_TRANSLATION / delta.norm();
    }
    let dr = UnitQuaternion::from_scaled_axis(omega);
    tf.r = dr * tf.r;
    tf.t = dr * tf.t + delta;
    Step { rotation: omega.norm(), translation: delta.norm(), ok: true }
}

/// Fraction of (a strided subset of) model points that, placed by `tf`,
/// project into the image in front of a valid observed depth by more than
/// `visibility_tolerance`. 0 when no model point projects onto valid depth.
fn free_space_violations(model: &ModelCloud, cfg: &IcpConfig, frame: &FrameView<'_>, tf: &CamToObj) -> f64 {
    let k = &frame.intrinsics;
    let (w, h) = (frame.width(), frame.height());
    let stride = model.points.len().div_ceil(cfg.visibility_points.max(1)).max(1);
    // Object → camera: p = r⁻¹ (q − t).
    let inv_r = tf.r.inverse();
    let (mut seen, mut violations) = (0usize, 0usize);
    for q in model.points.iter().step_by(stride) {
        let p = inv_r * (q - tf.t);
        if p.z <= 1e-6 {
            continue;
        }
        let u = (k.fx * p.x / p.z + k.cx).round();
        let v = (k.fy * p.y / p.z + k.cy).round();
        if !(u >= 0.0 && v >= 0.0 && u < w as f64 && v < h as f64) {
            continue;
        }
        let Some(z) = frame.depth.metres(v as usize * w + u as usize) else { continue };
        seen += 1;
        if p.z < z as f64 - cfg.visibility_tolerance {
            violations += 1;
        }
    }
    if seen == 0 { 0.0 } else { violations as f64 / seen as f64 }
}

/// Mean of the closest `trim_fraction` nearest-neighbour distances over every
/// `stride`-th observed point.
fn trimmed_mean_distance(model: &ModelCloud, cfg: &IcpConfig, s: &mut Scratch, tf: &CamToObj, stride: usize) -> f64 {
    s.distances.clear();
    for p in s.observed.iter().step_by(stride) {
        s.distances.push(model.nearest(&tf.apply(p)).1);
    }
    let threshold = trim_threshold(&s.distances, &mut s.selection, cfg.trim_fraction);
    let (sum, kept) =
        s.distances.iter().filter(|&&d| d <= threshold).fold((0.0, 0usize), |(acc, k), d| (acc + d, k + 1));
    if kept == 0 { f64::MAX } else { sum / kept as f64 }
}

/// The distance below which `fraction` of `distances` lie (selection, no sort).
fn trim_threshold(distances: &[f64], selection: &mut Vec<f64>, fraction: f64) -> f64 {
    if distances.is_empty() {
        return 0.0;
    }
    selection.clear();
    selection.extend_from_slice(distances);
    let k = ((distances.len() as f64 * fraction).ceil() as usize).clamp(1, distances.len()) - 1;
    let (_, kth, _) = selection.select_nth_unstable_by(k, f64::total_cmp);
    *kth
}
