//! Appearance check: the pose whose print matches the image, among the
//! estimate and its turns by the object's *near-symmetries*.
//!
//! A box turned by 180°, a can or mug turned about its axis, fits the depth
//! almost as well as the right pose; only the print tells them apart, and the
//! pose net sometimes gets it wrong (docs/BENCHMARKS.md, rotation-error
//! table). At load, each object without declared symmetries gets its turns:
//! rotations about its principal axes (multiples of `step_deg`, and those
//! composed with a half turn about another principal axis) that map its
//! surface samples onto themselves within `max_shape_error` of the diameter
//! (the turn's centre is fitted too). Per instance, each candidate (the
//! estimate and its turns) projects coloured surface samples that face the
//! camera into the frame, keeps those whose depth agrees, and scores the
//! normalised cross-correlation between model albedo and observed linear RGB.
//! A turn replaces the estimate only if it shows about as much of the object
//! as the estimate does and beats its score by `min_gain`.
//!
//! Allocation-free per frame: everything is sized at load.
//!
//! Status: experimental, off by default (`NetOptions::appearance`,
//! `fusepose eval --appearance on`). With the shipped weights it changed
//! ADD(S) AUC by +0.36 on a tuning split and −0.36 on the held-out test split
//! (docs/BENCHMARKS.md): the blurred prints of the built-in objects separate
//! the right pose from its turns too weakly (correlations 0.93 vs 0.92 for a
//! cracker box turned by 180°).

use fusepose_scene::appearance::{AppearanceSample, sample_appearance, srgb_to_linear};
use fusepose_scene::{ObjectModel, ObjectSet};
use kiddo::{KdTree, SquaredEuclidean};
use nalgebra::{Matrix3, Rotation3, SymmetricEigen, Unit, Vector3};

use crate::frame::{ColorFormat, FrameView};

/// Tuning of the appearance check.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AppearanceConfig {
    /// Coloured samples projected per candidate.
    pub samples: usize,
    /// Angle step of the turns about a principal axis, degrees.
    pub step_deg: f64,
    /// A turn is a near-symmetry when its surface mismatch (trimmed mean
    /// distance, turned sample to nearest sample) is below this fraction of
    /// the diameter.
    pub max_shape_error: f64,
    /// At most this many turns per object (the best-fitting ones).
    pub max_turns: usize,
    /// A sample counts as seen when the measured depth at its pixel is within
    /// this distance of its own depth, metres.
    pub depth_tolerance_m: f32,
    /// Candidates seeing fewer samples are not scored.
    pub min_seen: usize,
    /// A turn must see at least this fraction of the estimate's seen samples.
    pub min_seen_ratio: f32,
    /// A turn must beat the estimate's correlation by this much…
    pub min_gain: f32,
    /// …and leave at most this fraction of the estimate's mismatch (1 − correlation).
    pub max_residual_ratio: f32,
    /// Both sides are compared blurred over about this radius, metres: the
    /// estimate is a few millimetres off, fine print would only add noise.
    pub blur_m: f32,
}

impl Default for AppearanceConfig {
    fn default() -> Self {
        Self {
            samples: 600,
            step_deg: 15.0,
            max_shape_error: 0.005,
            max_turns: 48,
            depth_tolerance_m: 0.015,
            min_seen: 24,
            min_seen_ratio: 0.7,
            min_gain: 0.15,
            max_residual_ratio: 1.0,
            blur_m: 0.005,
        }
    }
}

/// A near-symmetry in the object frame: `p ↦ rotation·p + shift`.
#[derive(Clone, Copy, Debug)]
pub struct Turn {
    pub rotation: Matrix3<f32>,
    pub shift: Vector3<f32>,
    /// Surface mismatch, metres.
    pub shape_error_m: f64,
}

struct ObjectAppearance {
    samples: Vec<AppearanceSample>,
    turns: Vec<Turn>,
}

/// What [`AppearanceCheck::choose`] decided for one instance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Choice {
    pub rotation: Matrix3<f32>,
    pub translation: Vector3<f32>,
    /// Index of the chosen turn (None: the estimate was kept).
    pub turn: Option<usize>,
    /// Correlation of the estimate and of the chosen candidate (NaN: too little seen).
    pub estimate_score: f32,
    pub chosen_score: f32,
}

/// Per-object turns and coloured samples, built once at load.
pub struct AppearanceCheck {
    config: AppearanceConfig,
    /// Index = class id − 1; None for symmetric objects or those without turns.
    objects: Vec<Option<ObjectAppearance>>,
    srgb: [f32; 256],
}

/// Seed of the coloured samples (fixed: the check is deterministic).
const SAMPLE_SEED: u64 = 0xa99e_a2a0;

impl AppearanceCheck {
    pub fn new(objects: &ObjectSet, config: AppearanceConfig) -> Self {
        let objects = objects
            .objects
            .iter()
            .map(|m| {
                if m.symmetry.is_symmetric() {
                    return None;
                }
                let turns = near_symmetries(m, &config);
                if turns.is_empty() {
                    return None;
                }
                let samples = blurred_samples(m, &config)?;
                Some(ObjectAppearance { samples, turns })
            })
            .collect();
        Self {
            config,
            objects,
            srgb: std::array::from_fn(|i| srgb_to_linear(i as u8)),
        }
    }

    pub fn config(&self) -> &AppearanceConfig {
        &self.config
    }

    /// The turns of class index `k` (class id − 1); empty when it has none.
    pub fn turns(&self, k: usize) -> &[Turn] {
        self.objects.get(k).and_then(|o| o.as_ref()).map_or(&[], |o| &o.turns)
    }

    /// Picks between the estimate `(rotation, translation)` (object → camera)
    /// of class index `k` and its turns, by the print seen in `frame`.
    pub fn choose(&self, k: usize, frame: &FrameView<'_>, rotation: &Matrix3<f32>, translation: &Vector3<f32>) -> Choice {
        let keep = Choice {
            rotation: *rotation,
            translation: *translation,
            turn: None,
            estimate_score: f32::NAN,
            chosen_score: f32::NAN,
        };
        let Some(obj) = self.objects.get(k).and_then(|o| o.as_ref()) else {
            return keep;
        };
        let (seen0, score0) = self.score(obj, frame, rotation, translation);
        let mut best = Choice { estimate_score: score0, chosen_score: score0, ..keep };
        if seen0 < self.config.min_seen {
            return best;
        }
        let min_seen = (self.config.min_seen_ratio * seen0 as f32).max(self.config.min_seen as f32) as usize;
        for (i, turn) in obj.turns.iter().enumerate() {
            let r = rotation * turn.rotation;
            let t = rotation * turn.shift + translation;
            let (seen, score) = self.score(obj, frame, &r, &t);
            if seen >= min_seen && score > best.chosen_score {
                best = Choice { rotation: r, translation: t, turn: Some(i), estimate_score: score0, chosen_score: score };
            }
        }
        let convincing = best.chosen_score - score0 >= self.config.min_gain
            && 1.0 - best.chosen_score <= self.config.max_residual_ratio * (1.0 - score0);
        if best.turn.is_some() && !convincing {
            return Choice { estimate_score: score0, chosen_score: score0, ..keep };
        }
        best
    }

    /// (samples seen, correlation of albedo and observed colour over them).
    fn score(&self, obj: &ObjectAppearance, frame: &FrameView<'_>, r: &Matrix3<f32>, t: &Vector3<f32>) -> (usize, f32) {
        let k = &frame.intrinsics;
        let (fx, fy, cx, cy) = (k.fx as f32, k.fy as f32, k.cx as f32, k.cy as f32);
        let (w, h) = (frame.width(), frame.height());
        let (ri, bi) = match frame.color_format {
            ColorFormat::Rgb8 => (0, 2),
            ColorFormat::Bgr8 => (2, 0),
        };
        // Per shading bin (the camera-frame normal's dominant axis and sign:
        // surfaces facing alike are lit alike), sums over the 3 channels of
        // the seen samples: n, Σo, Σm, Σo², Σm², Σo·m.
        let mut bins = [[0f64; 6]; 6];
        let mut n = 0usize;
        let tol = self.config.depth_tolerance_m;
        for s in &obj.samples {
            let p = r * s.position.coords + t;
            let nc = r * s.normal;
            // Facing the camera, not grazing (grazing samples sit on the
            // silhouette, where the blur mixes in the background).
            if p.z <= 0.0 || nc.dot(&p) >= -0.2 * p.norm() {
                continue;
            }
            let (u, v) = (fx * p.x / p.z + cx, fy * p.y / p.z + cy);
            if !(u >= 0.0 && v >= 0.0 && (u as usize) < w && (v as usize) < h) {
                continue;
            }
            let (x, y) = (u as usize, v as usize);
            match frame.depth.metres(y * w + x) {
                Some(z) if (z - p.z).abs() <= tol => {}
                _ => continue,
            }
            // Mean of a 3 x 3 stencil spanning ± blur_m at the sample's
            // depth, over the stencil pixels on the same surface.
            let step = ((fx * self.config.blur_m / p.z) as usize).min(64);
            let (mut o, mut count) = ([0f32; 3], 0u32);
            for sy in [y.saturating_sub(step), y, (y + step).min(h - 1)] {
                for sx in [x.saturating_sub(step), x, (x + step).min(w - 1)] {
                    let i = sy * w + sx;
                    if !frame.depth.metres(i).is_some_and(|z| (z - p.z).abs() <= tol) {
                        continue;
                    }
                    let Some(c) = frame.color.get(i * 3..i * 3 + 3) else { continue };
                    o[0] += self.srgb[c[ri] as usize];
                    o[1] += self.srgb[c[1] as usize];
                    o[2] += self.srgb[c[bi] as usize];
                    count += 1;
                }
            }
            let o = o.map(|x| x / count.max(1) as f32);
            let axis = nc.iamax();
            let b = &mut bins[2 * axis + (nc[axis] > 0.0) as usize];
            b[0] += 1.0;
            for (m, o) in s.albedo.iter().zip(o) {
                let (m, o) = (*m as f64, o as f64);
                b[1] += o;
                b[2] += m;
                b[3] += o * o;
                b[4] += m * m;
                b[5] += o * m;
            }
            n += 1;
        }
        if n < self.config.min_seen {
            return (n, f32::NAN);
        }
        // Each bin's colours divided by its mean brightness (observed and
        // model alike; both means become 1), then one correlation over all.
        let (mut count, mut soo, mut smm, mut som) = (0.0, 0.0, 0.0, 0.0);
        for b in &bins {
            let c = 3.0 * b[0];
            let (go, gm) = (b[1] / c.max(1.0), b[2] / c.max(1.0));
            if b[0] < 1.0 || go < 1e-3 || gm < 1e-3 {
                continue;
            }
            count += c;
            soo += b[3] / (go * go);
            smm += b[4] / (gm * gm);
            som += b[5] / (go * gm);
        }
        let (vo, vm, cov) = (soo - count, smm - count, som - count);
        let score = if vm > 1e-9 && vo > 1e-9 { cov / (vm * vo).sqrt() } else { 0.0 };
        (n, score as f32)
    }
}

/// `config.samples` coloured samples whose albedo is the mean over the
/// surface within `blur_m` (same-facing surface only: no blending across edges).
fn blurred_samples(model: &ObjectModel, config: &AppearanceConfig) -> Option<Vec<AppearanceSample>> {
    let mut samples = sample_appearance(&model.mesh, config.samples, SAMPLE_SEED).ok()?;
    let dense = sample_appearance(&model.mesh, 30_000, SAMPLE_SEED ^ 2).ok()?;
    let mut tree: KdTree<f32, 3> = KdTree::new();
    for (i, d) in dense.iter().enumerate() {
        tree.add(&[d.position.x, d.position.y, d.position.z], i as u64);
    }
    let r2 = config.blur_m * config.blur_m;
    for s in &mut samples {
        let (mut sum, mut n) = ([0f32; 3], 0);
        for nb in tree.within_unsorted::<SquaredEuclidean>(&[s.position.x, s.position.y, s.position.z], r2) {
            let d = &dense[nb.item as usize];
            if d.normal.dot(&s.normal) > 0.7 {
                for (a, b) in sum.iter_mut().zip(d.albedo) {
                    *a += b;
                }
                n += 1;
            }
        }
        if n > 0 {
            s.albedo = sum.map(|a| a / n as f32);
        }
    }
    Some(samples)
}

/// Principal axes of the samples (columns), largest spread first.
fn principal_axes(points: &[Vector3<f64>]) -> Matrix3<f64> {
    let c = points.iter().sum::<Vector3<f64>>() / points.len() as f64;
    let cov = points.iter().map(|p| (p - c) * (p - c).transpose()).sum::<Matrix3<f64>>() / points.len() as f64;
    let eig = SymmetricEigen::new(cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    Matrix3::from_columns(&order.map(|i| eig.eigenvectors.column(i).into_owned()))
}

/// Candidate rotations: turns about each principal axis, alone and after a half
/// turn about another principal axis (the symmetries of boxes and cylinders).
fn candidate_rotations(axes: &Matrix3<f64>, step_deg: f64) -> Vec<Rotation3<f64>> {
    let steps = (360.0 / step_deg).round().max(2.0) as usize;
    let axis = |i: usize| Unit::new_normalize(axes.column(i).into_owned());
    let mut out: Vec<Rotation3<f64>> = Vec::new();
    let mut push = |r: Rotation3<f64>| {
        if r.angle() > 1e-3 && out.iter().all(|o| o.angle_to(&r) > 1e-3) {
            out.push(r);
        }
    };
    for i in 0..3 {
        for j in 1..steps {
            let about = Rotation3::from_axis_angle(&axis(i), std::f64::consts::TAU * j as f64 / steps as f64);
            push(about);
            for f in (0..3).filter(|&f| f != i) {
                push(about * Rotation3::from_axis_angle(&axis(f), std::f64::consts::PI));
            }
        }
    }
    out
}

/// The object's near-symmetries, best-fitting first (see the module docs).
pub fn near_symmetries(model: &ObjectModel, config: &AppearanceConfig) -> Vec<Turn> {
    // Turned "probe" samples are matched against a dense, independent
    // "reference" sampling, so even the identity has a gap (the sampling
    // spacing); a turn's shape error is its gap above that. The gap is a
    // trimmed mean (best 90 %): a small part that does not map onto itself
    // (a mug's handle) leaves the turn to the print.
    let Ok(dense) = fusepose_scene::surface::sample_surface(&model.mesh, 8000, SAMPLE_SEED ^ 1) else {
        return Vec::new();
    };
    let reference: Vec<Vector3<f64>> = dense.iter().map(|p| p.coords).collect();
    let stride = (model.samples.len() / 300).max(1);
    let probe: Vec<Vector3<f64>> = model.samples.iter().step_by(stride).map(|p| p.coords).collect();
    if probe.len() < 8 || !(model.diameter > 0.0) {
        return Vec::new();
    }
    let mut tree: KdTree<f64, 3> = KdTree::new();
    for (i, p) in reference.iter().enumerate() {
        tree.add(&[p.x, p.y, p.z], i as u64);
    }
    let keep = probe.len() * 9 / 10;
    let mut gaps = vec![(0.0, Vector3::zeros()); probe.len()];
    // Trimmed mean gap of the turned probe, and the mean pull of the kept pairs.
    let mut gap = |rot: &Rotation3<f64>, shift: &Vector3<f64>| {
        for (p, g) in probe.iter().zip(gaps.iter_mut()) {
            let q = rot * p + shift;
            let nn = tree.nearest_one::<SquaredEuclidean>(&[q.x, q.y, q.z]);
            *g = (nn.distance.sqrt(), reference[nn.item as usize] - q);
        }
        gaps.select_nth_unstable_by(keep, |a, b| a.0.total_cmp(&b.0));
        let kept = &gaps[..keep];
        let n = keep as f64;
        (kept.iter().map(|g| g.0).sum::<f64>() / n, kept.iter().map(|g| g.1).sum::<Vector3<f64>>() / n)
    };
    let baseline = gap(&Rotation3::identity(), &Vector3::zeros()).0;
    let centroid = probe.iter().sum::<Vector3<f64>>() / probe.len() as f64;
    let centres = [centroid, (model.bbox_min.coords + model.bbox_max.coords) / 2.0, Vector3::zeros()];
    let limit = config.max_shape_error * model.diameter;
    let mut turns: Vec<Turn> = Vec::new();
    let mut starts = candidate_rotations(&principal_axes(&probe), config.step_deg);
    starts.extend(candidate_rotations(&Matrix3::identity(), config.step_deg));
    for rot in starts {
        // About the best of three centres, then let the shift settle.
        let (mut err, mut shift, mut pull) = (f64::INFINITY, Vector3::zeros(), Vector3::zeros());
        for c in centres {
            let s = c - rot * c;
            let (g, p) = gap(&rot, &s);
            if g < err {
                (err, shift, pull) = (g, s, p);
            }
        }
        if err - baseline > 3.0 * limit {
            continue;
        }
        for _ in 0..3 {
            shift += pull;
            (err, pull) = gap(&rot, &shift);
        }
        let err = (err - baseline).max(0.0);
        if err > limit || turns.iter().any(|t| Rotation3::from_matrix_unchecked(t.rotation.cast::<f64>()).angle_to(&rot) < 2f64.to_radians()) {
            continue;
        }
        turns.push(Turn { rotation: rot.matrix().cast::<f32>(), shift: shift.cast::<f32>(), shape_error_m: err });
    }
    turns.sort_by(|a, b| a.shape_error_m.total_cmp(&b.shape_error_m));
    turns.truncate(config.max_turns);
    turns
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_scene::builtin::builtin_objects;

    #[test]
    fn boxes_and_cans_get_their_turns_and_symmetric_objects_none() {
        let set = builtin_objects();
        let check = AppearanceCheck::new(&set, AppearanceConfig::default());
        let count = |name: &str| check.turns(set.class_of(name).unwrap() as usize - 1).len();
        // A box with three distinct sides: exactly its three half turns.
        assert_eq!(count("cracker_box"), 3);
        assert_eq!(count("sugar_box"), 3);
        // A closed cylinder: 23 turns about the axis, 24+ flipped (about any
        // horizontal axis), capped at `max_turns`.
        assert!(count("tomato_soup_can") >= 40, "{}", count("tomato_soup_can"));
        assert!(count("coffee_can") >= 40);
        // The mug turns about its axis (its handle is a small part of it), the
        // flattened mustard bottle by a half turn about its axis.
        let about_z = |name: &str| {
            check.turns(set.class_of(name).unwrap() as usize - 1).iter().filter(|t| (t.rotation[(2, 2)] - 1.0).abs() < 1e-3).count()
        };
        assert!(about_z("mug") >= 4, "{}", about_z("mug"));
        assert!(about_z("mustard_bottle") >= 1);
        // Declared symmetric: the check leaves them alone.
        assert_eq!(count("bowl"), 0);
        assert_eq!(count("wood_block"), 0);
    }
}
