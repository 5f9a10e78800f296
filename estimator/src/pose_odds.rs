//! The odds that a verified pose is right: a logistic model over a pose's
//! verification terms, fitted per weight file on rendered frames whose truth
//! is known, so that one number says how far the depth image supports the
//! pose.
//!
//! The hand-set terms of [`crate::verify::VerifyConfig`] each judge one thing
//! against a fixed threshold; a ghost that passes them all still sits near
//! several of them at once (a small region, little of its depth-agreeing
//! surface in its mask, a segmenter less sure of it, a lower confidence). The
//! model weighs them together. Fitted on own-renderer frames only, it cut
//! ghost poses on path-traced images it never saw at no loss of accuracy
//! (docs/BENCHMARKS.md, session 43).
//!
//! A sample's label is 0 when its pose was matched to no object or lies 0.1
//! diameters (ADD-S) or more from every object of its class, else 1 when it
//! is within 2 cm ADD-S of the object it was matched to; poses in between
//! are left out. `fusepose eval --odds-samples` writes the samples, `fusepose train
//! --stage odds` fits the model ([`PoseOdds::fit`]) and stores it in the
//! weight file under [`KEY_POSE_ODDS`]; [`verify_on_region`] computes each
//! pose's odds ([`Verification::odds`]) when the verifier holds a model, and
//! [`VerifyConfig::min_odds`] fails passed poses below it.
//!
//! [`verify_on_region`]: crate::verify::verify_on_region
//! [`Verification::odds`]: crate::verify::Verification::odds
//! [`VerifyConfig::min_odds`]: crate::verify::VerifyConfig::min_odds

use std::collections::HashMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::poses::ObjectPose;
use crate::verify::Verification;

/// Metadata key of the model in a weight file (JSON of [`PoseOdds`]).
pub const KEY_POSE_ODDS: &str = "fusepose.verify.odds";

/// How many terms the model reads.
pub const FEATURE_COUNT: usize = 16;

/// The terms, in the model's order (also the sample file's column names).
pub const FEATURES: [&str; FEATURE_COUNT] = [
    "ln_region_pixels",
    "z_m",
    "inlier_fraction",
    "mask_coverage",
    "behind_fraction",
    "off_plane",
    "depth_support",
    "plane_continuation",
    "depth_continuity",
    "mask_agreement",
    "fit",
    "residual_x20",
    "region_probability",
    "confidence",
    "below_support",
    "residual_missing",
];

/// A missing depth residual counts as this (metres), and larger ones are
/// clamped to it: a residual of 10 cm already says the pose is off.
const RESIDUAL_CAP_M: f32 = 0.1;

/// The terms of `v` (a verdict of `pose`) in [`FEATURES`] order. Terms not
/// judged take the value that says nothing against the pose: no segmenter
/// certainty (a producer's instance plane) reads as 1, no support plane as 0.
pub fn features(v: &Verification, pose: &ObjectPose) -> [f32; FEATURE_COUNT] {
    let or = |x: f32, d: f32| if x.is_finite() { x } else { d };
    let residual = or(v.depth_residual_m, RESIDUAL_CAP_M).min(RESIDUAL_CAP_M);
    [
        (pose.mask_pixels.max(1) as f32).ln(),
        pose.translation.z as f32,
        v.inlier_fraction,
        v.mask_coverage,
        v.behind_fraction,
        v.off_plane,
        v.depth_support,
        v.plane_continuation,
        v.depth_continuity,
        v.mask_agreement,
        v.fit,
        residual / RESIDUAL_CAP_M * 2.0,
        or(v.region_probability, 1.0),
        or(pose.confidence, 0.0),
        or(v.below_support, 0.0),
        f32::from(!v.depth_residual_m.is_finite()),
    ]
}

/// A fitted model: standardisation, weights and bias, and what it was fitted on.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PoseOdds {
    /// [`FEATURES`], as fitted (checked on load).
    pub features: Vec<String>,
    pub mean: Vec<f32>,
    /// Standard deviation per term (positive).
    pub scale: Vec<f32>,
    pub weights: Vec<f32>,
    pub bias: f32,
    /// Samples fitted on, and how many of them were right.
    pub samples: usize,
    pub positives: usize,
    /// Where the samples came from (free text, for the record).
    pub source: String,
}

/// Why a model or its samples cannot be used.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum PoseOddsError {
    #[error(
        "pose odds model: {what} has {got} values, expected {FEATURE_COUNT} (one per term: {}); refit it with `fusepose train --stage odds`",
        FEATURES.join(", ")
    )]
    Length { what: &'static str, got: usize },
    #[error(
        "pose odds model: term {index} is {got:?}, expected {expected:?}: it was fitted on other terms; refit it with `fusepose train --stage odds`"
    )]
    Feature { index: usize, got: String, expected: &'static str },
    #[error(
        "pose odds model: {what} is not finite (or a scale is not positive); refit it with `fusepose train --stage odds`"
    )]
    NotFinite { what: &'static str },
    #[error("pose odds samples: {reason}")]
    Samples { reason: String },
    #[error("pose odds model in {path}: {reason}")]
    File { path: String, reason: String },
}

/// Gradient steps of [`PoseOdds::fit`] (full batch, on standardised terms).
pub const FIT_STEPS: usize = 400;
/// Step size of [`PoseOdds::fit`].
pub const FIT_RATE: f64 = 0.5;
/// L2 penalty on the weights (not the bias) of [`PoseOdds::fit`].
pub const FIT_L2: f64 = 1e-3;

impl PoseOdds {
    /// Fits the model to `samples` (terms, whether the pose was right) by
    /// logistic regression: terms standardised, [`FIT_STEPS`] full-batch
    /// gradient steps of [`FIT_RATE`] from zero, [`FIT_L2`] on the weights.
    /// Deterministic: the same samples give the same model.
    pub fn fit(samples: &[([f32; FEATURE_COUNT], bool)], source: &str) -> Result<Self, PoseOddsError> {
        let positives = samples.iter().filter(|s| s.1).count();
        if positives == 0 || positives == samples.len() {
            return Err(PoseOddsError::Samples {
                reason: format!(
                    "{} samples, {positives} of them right: a fit needs right and wrong poses both \
                     (evaluate on more frames, with the segmenter's masks)",
                    samples.len()
                ),
            });
        }
        if let Some(i) = samples.iter().position(|(x, _)| x.iter().any(|v| !v.is_finite())) {
            return Err(PoseOddsError::Samples { reason: format!("sample {i} has a term that is not finite") });
        }
        let n = samples.len() as f64;
        let mut mean = [0.0f64; FEATURE_COUNT];
        for (x, _) in samples {
            for (m, &v) in mean.iter_mut().zip(x) {
                *m += v as f64 / n;
            }
        }
        let mut scale = [0.0f64; FEATURE_COUNT];
        for (x, _) in samples {
            for ((s, &v), m) in scale.iter_mut().zip(x).zip(&mean) {
                *s += (v as f64 - m).powi(2) / n;
            }
        }
        let scale = scale.map(|s| s.sqrt().max(1e-6));
        let z: Vec<[f64; FEATURE_COUNT]> =
            samples.iter().map(|(x, _)| std::array::from_fn(|i| (x[i] as f64 - mean[i]) / scale[i])).collect();
        let (mut w, mut b) = ([0.0f64; FEATURE_COUNT], 0.0f64);
        for _ in 0..FIT_STEPS {
            let (mut gw, mut gb) = ([0.0f64; FEATURE_COUNT], 0.0f64);
            for (x, (_, y)) in z.iter().zip(samples) {
                let s = b + x.iter().zip(&w).map(|(a, c)| a * c).sum::<f64>();
                let e = sigmoid(s) - f64::from(u8::from(*y));
                for (g, a) in gw.iter_mut().zip(x) {
                    *g += e * a;
                }
                gb += e;
            }
            for (wi, g) in w.iter_mut().zip(&gw) {
                *wi -= FIT_RATE * (g / n + FIT_L2 * *wi);
            }
            b -= FIT_RATE * gb / n;
        }
        let model = Self {
            features: FEATURES.iter().map(|s| s.to_string()).collect(),
            mean: mean.iter().map(|&v| v as f32).collect(),
            scale: scale.iter().map(|&v| v as f32).collect(),
            weights: w.iter().map(|&v| v as f32).collect(),
            bias: b as f32,
            samples: samples.len(),
            positives,
            source: source.to_owned(),
        };
        model.validate()?;
        Ok(model)
    }

    /// [`PoseOdds::fit`] with the terms at the indices `left_out` weighted 0
    /// (mean 0, scale 1): the model then ignores them, e.g. the terms a
    /// colour cast moves.
    pub fn fit_without(
        samples: &[([f32; FEATURE_COUNT], bool)],
        left_out: &[usize],
        source: &str,
    ) -> Result<Self, PoseOddsError> {
        let blanked: Vec<_> = samples
            .iter()
            .map(|&(mut x, y)| {
                for &i in left_out.iter().filter(|&&i| i < FEATURE_COUNT) {
                    x[i] = 0.0;
                }
                (x, y)
            })
            .collect();
        let mut model = Self::fit(&blanked, source)?;
        for &i in left_out.iter().filter(|&&i| i < FEATURE_COUNT) {
            (model.mean[i], model.scale[i], model.weights[i]) = (0.0, 1.0, 0.0);
        }
        Ok(model)
    }

    /// Checks the lengths, the term names and that every number is finite.
    pub fn validate(&self) -> Result<(), PoseOddsError> {
        for (what, got) in [
            ("features", self.features.len()),
            ("mean", self.mean.len()),
            ("scale", self.scale.len()),
            ("weights", self.weights.len()),
        ] {
            if got != FEATURE_COUNT {
                return Err(PoseOddsError::Length { what, got });
            }
        }
        if let Some((index, got)) = self.features.iter().enumerate().find(|(i, f)| f.as_str() != FEATURES[*i]) {
            return Err(PoseOddsError::Feature { index, got: got.clone(), expected: FEATURES[index] });
        }
        for (what, ok) in [
            ("mean", self.mean.iter().all(|v| v.is_finite())),
            ("scale", self.scale.iter().all(|v| v.is_finite() && *v > 0.0)),
            ("weights", self.weights.iter().all(|v| v.is_finite())),
            ("bias", self.bias.is_finite()),
        ] {
            if !ok {
                return Err(PoseOddsError::NotFinite { what });
            }
        }
        Ok(())
    }

    /// The model's probability that a pose with terms `x` is right.
    pub fn probability_of(&self, x: &[f32; FEATURE_COUNT]) -> f32 {
        let terms = x.iter().zip(&self.mean).zip(&self.scale).zip(&self.weights);
        let s = terms.fold(self.bias as f64, |s, (((&v, &m), &d), &w)| s + w as f64 * (v - m) as f64 / d as f64);
        sigmoid(s) as f32
    }

    /// The probability that `pose`, with verdict `v`, is right.
    pub fn probability(&self, v: &Verification, pose: &ObjectPose) -> f32 {
        self.probability_of(&features(v, pose))
    }

    /// The model recorded in a weight file's `metadata`; None when it has none.
    pub fn from_metadata(metadata: &HashMap<String, String>, path: &Path) -> Result<Option<Self>, PoseOddsError> {
        let Some(json) = metadata.get(KEY_POSE_ODDS) else { return Ok(None) };
        let file = |reason: String| PoseOddsError::File { path: path.display().to_string(), reason };
        let model: Self = serde_json::from_str(json).map_err(|e| file(format!("{KEY_POSE_ODDS}: {e}")))?;
        model.validate()?;
        Ok(Some(model))
    }

    /// The model recorded in the weight file at `path`; None when it has none.
    pub fn read(path: &Path) -> Result<Option<Self>, PoseOddsError> {
        let file = |reason: String| PoseOddsError::File { path: path.display().to_string(), reason };
        let bytes = std::fs::read(path).map_err(|e| file(e.to_string()))?;
        let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).map_err(|e| file(e.to_string()))?;
        Self::from_metadata(&header.metadata().clone().unwrap_or_default(), path)
    }

    /// Writes this model into the weight file at `path` (tensors and other
    /// metadata unchanged), through a temporary file renamed over it.
    pub fn store(&self, path: &Path) -> Result<(), PoseOddsError> {
        self.validate()?;
        let file = |reason: String| PoseOddsError::File { path: path.display().to_string(), reason };
        let bytes = std::fs::read(path).map_err(|e| file(e.to_string()))?;
        let json = serde_json::to_string(self).map_err(|e| file(e.to_string()))?;
        let out = crate::seg::file::with_metadata(&bytes, KEY_POSE_ODDS, json).map_err(|e| file(e.to_string()))?;
        let tmp = path.with_extension("odds.tmp");
        std::fs::write(&tmp, out).map_err(|e| file(e.to_string()))?;
        std::fs::rename(&tmp, path).map_err(|e| file(e.to_string()))
    }
}

fn sigmoid(s: f64) -> f64 {
    1.0 / (1.0 + (-s.clamp(-40.0, 40.0)).exp())
}

/// The sample file's header line: the terms, then `right` (1 or 0).
pub fn samples_header() -> String {
    format!("{},right", FEATURES.join(","))
}

/// One sample as a line of the sample file (no newline).
pub fn sample_line(x: &[f32; FEATURE_COUNT], right: bool) -> String {
    let mut line: String = x.iter().map(|v| format!("{v},")).collect();
    line.push(if right { '1' } else { '0' });
    line
}

/// Parses a sample file (a header naming [`FEATURES`] then `right`, one line
/// per sample), naming the line of any fault.
pub fn parse_samples(text: &str, name: &str) -> Result<Vec<([f32; FEATURE_COUNT], bool)>, PoseOddsError> {
    let bad = |line: usize, reason: String| PoseOddsError::Samples { reason: format!("{name}:{line}: {reason}") };
    let mut lines = text.lines().enumerate();
    match lines.next() {
        Some((_, h)) if h.trim() == samples_header() => {}
        other => {
            return Err(bad(
                1,
                format!(
                    "header {:?}, expected {:?} (write it with `fusepose eval --odds-samples`)",
                    other.map_or("", |(_, h)| h),
                    samples_header()
                ),
            ));
        }
    }
    let mut out = Vec::new();
    for (i, line) in lines.filter(|(_, l)| !l.trim().is_empty()) {
        let cols: Vec<&str> = line.trim().split(',').collect();
        if cols.len() != FEATURE_COUNT + 1 {
            return Err(bad(i + 1, format!("{} columns, expected {}", cols.len(), FEATURE_COUNT + 1)));
        }
        let mut x = [0.0f32; FEATURE_COUNT];
        for (k, (v, c)) in x.iter_mut().zip(&cols).enumerate() {
            *v = c.parse().map_err(|_| bad(i + 1, format!("{}: {c:?} is not a number", FEATURES[k])))?;
        }
        let right = match cols[FEATURE_COUNT] {
            "1" => true,
            "0" => false,
            c => return Err(bad(i + 1, format!("right: {c:?}, expected 1 or 0"))),
        };
        out.push((x, right));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    /// Samples of a known logistic model on two informative terms (the rest noise).
    fn synthetic(n: usize, seed: u64) -> Vec<([f32; FEATURE_COUNT], bool)> {
        let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let x: [f32; FEATURE_COUNT] = std::array::from_fn(|_| rng.random::<f32>());
                let s = 6.0 * (x[9] - 0.5) - 4.0 * (x[14] - 0.5);
                let p = 1.0 / (1.0 + (-s as f64).exp());
                (x, rng.random::<f64>() < p)
            })
            .collect()
    }

    #[test]
    fn fit_recovers_a_known_model() {
        let model = PoseOdds::fit(&synthetic(4000, 1), "synthetic").unwrap();
        // Weights on standardised terms: the true ones are 6 and -4 per unit,
        // × the uniform's standard deviation (0.289): 1.73 and -1.15.
        let w = &model.weights;
        assert!((w[9] - 1.73).abs() < 0.35 && (w[14] + 1.15).abs() < 0.35, "{w:?}");
        assert!(w.iter().enumerate().filter(|(i, _)| *i != 9 && *i != 14).all(|(_, v)| v.abs() < 0.2), "{w:?}");
        // Probabilities follow the true model.
        let mut x = [0.5f32; FEATURE_COUNT];
        assert!((model.probability_of(&x) - 0.5).abs() < 0.08);
        x[9] = 0.9;
        assert!(model.probability_of(&x) > 0.8);
        x[9] = 0.1;
        assert!(model.probability_of(&x) < 0.2);
        // Deterministic.
        assert_eq!(model, PoseOdds::fit(&synthetic(4000, 1), "synthetic").unwrap());
    }

    #[test]
    fn terms_left_out_weigh_nothing() {
        let model = PoseOdds::fit_without(&synthetic(2000, 7), &[9], "synthetic").unwrap();
        assert_eq!((model.weights[9], model.mean[9], model.scale[9]), (0.0, 0.0, 1.0));
        assert!(model.weights[14] < -0.5, "{:?}", model.weights);
        let mut x = [0.5f32; FEATURE_COUNT];
        let p = model.probability_of(&x);
        x[9] = 100.0;
        assert_eq!(model.probability_of(&x), p);
    }

    #[test]
    fn fit_refuses_one_sided_or_broken_samples() {
        let all_right: Vec<_> = synthetic(50, 2).into_iter().map(|(x, _)| (x, true)).collect();
        assert!(matches!(PoseOdds::fit(&all_right, "x"), Err(PoseOddsError::Samples { .. })));
        let mut nan = synthetic(50, 3);
        nan[7].0[2] = f32::NAN;
        let e = PoseOdds::fit(&nan, "x").unwrap_err().to_string();
        assert!(e.contains("sample 7"), "{e}");
    }

    #[test]
    fn validation_names_what_is_wrong() {
        let good = PoseOdds::fit(&synthetic(500, 4), "x").unwrap();
        let short = PoseOdds { weights: vec![0.0; 3], ..good.clone() };
        assert_eq!(short.validate(), Err(PoseOddsError::Length { what: "weights", got: 3 }));
        let mut renamed = good.clone();
        renamed.features[2] = "inliers".into();
        let e = renamed.validate().unwrap_err();
        assert!(e.to_string().contains("\"inliers\"") && e.to_string().contains("inlier_fraction"), "{e}");
        let zero_scale = PoseOdds { scale: vec![0.0; FEATURE_COUNT], ..good };
        assert_eq!(zero_scale.validate(), Err(PoseOddsError::NotFinite { what: "scale" }));
    }

    #[test]
    fn sample_lines_round_trip_and_faults_name_their_line() {
        let samples = synthetic(20, 5);
        let mut text = samples_header() + "\n";
        for (x, y) in &samples {
            text += &(sample_line(x, *y) + "\n");
        }
        assert_eq!(parse_samples(&text, "s.csv").unwrap(), samples);
        let broken = text.replacen(",1\n", ",2\n", 1).replacen(",0\n", ",2\n", 1);
        let e = parse_samples(&broken, "s.csv").unwrap_err().to_string();
        assert!(e.starts_with("pose odds samples: s.csv:") && e.contains("expected 1 or 0"), "{e}");
        let e = parse_samples("a,b\n", "t.csv").unwrap_err().to_string();
        assert!(e.contains("t.csv:1") && e.contains("--odds-samples"), "{e}");
    }

    #[test]
    fn a_model_stored_in_a_weight_file_reads_back_and_leaves_the_tensors() {
        let dir = std::env::temp_dir().join(format!("fusepose-odds-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("w.safetensors");
        let data: Vec<u8> = [1.0f32, 2.0, 3.0].iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = safetensors::tensor::TensorView::new(safetensors::Dtype::F32, vec![3], &data).unwrap();
        let meta = HashMap::from([("fusepose.format".to_string(), "test".to_string())]);
        std::fs::write(&path, safetensors::serialize([("t", view)], Some(meta)).unwrap()).unwrap();
        assert_eq!(PoseOdds::read(&path).unwrap(), None);
        let model = PoseOdds::fit(&synthetic(300, 6), "synthetic").unwrap();
        model.store(&path).unwrap();
        assert_eq!(PoseOdds::read(&path).unwrap(), Some(model));
        let bytes = std::fs::read(&path).unwrap();
        let st = safetensors::SafeTensors::deserialize(&bytes).unwrap();
        assert_eq!(st.tensor("t").unwrap().data(), &data[..]);
        let (_, header) = safetensors::SafeTensors::read_metadata(&bytes).unwrap();
        assert_eq!(header.metadata().as_ref().unwrap()["fusepose.format"], "test");
        // A record fitted on other terms is refused with the fix.
        let mut other = PoseOdds::read(&path).unwrap().unwrap();
        other.features.swap(0, 1);
        let meta = HashMap::from([(KEY_POSE_ODDS.to_string(), serde_json::to_string(&other).unwrap())]);
        let e = PoseOdds::from_metadata(&meta, &path).unwrap_err().to_string();
        assert!(e.contains("--stage odds"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn missing_terms_read_as_saying_nothing_against_the_pose() {
        let pose = ObjectPose {
            class_id: 1,
            instance_id: 0,
            rotation: nalgebra::UnitQuaternion::identity(),
            translation: nalgebra::Vector3::new(0.0, 0.0, 0.8),
            confidence: f32::NAN,
            mask_pixels: 0,
            bbox: [0; 4],
            iterations: 0,
        };
        let v = Verification {
            depth_residual_m: f32::NAN,
            region_probability: f32::NAN,
            below_support: f32::NAN,
            ..Verification::default()
        };
        let x = features(&v, &pose);
        assert_eq!(x[0], 0.0); // ln 1
        assert_eq!(x[11], 2.0); // the residual cap
        assert_eq!(x[12], 1.0); // no segmenter: sure
        assert_eq!(x[13], 0.0);
        assert_eq!(x[14], 0.0);
        assert_eq!(x[15], 1.0);
        let v = Verification { depth_residual_m: 0.004, ..v };
        let x = features(&v, &pose);
        assert!((x[11] - 0.08).abs() < 1e-6 && x[15] == 0.0);
    }
}
