//! Held-out validation through the inference engine: the same code path the
//! daemon runs (weights written to a file, read back by
//! `fusepose_estimator::net`), scored with `scene::metrics` — ADD-S AUC,
//! ADD(S) AUC and ADD-S < 2 cm, for the pose net alone and after refinement.
//!
//! Validation scenes use seeds from [`VAL_SEED_BASE`], disjoint from training
//! seeds, and no augmentation.

use std::collections::BTreeMap;
use std::time::Instant;

use fusepose_estimator::net::engine::{quat_matrix, unit_quat};
use fusepose_estimator::net::{Engine, Scratch, WeightFile};
use fusepose_scene::metrics::{ADD_S_THRESHOLD_2CM, ObjectMetric, accuracy_below_percent, vocap_auc_percent};
use fusepose_scene::render::RenderTarget;
use fusepose_scene::{Intrinsics, ObjectSet, Pose};
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};
use ndarray::{Array1, Array2};

use crate::data::{DataConfig, Sample, Source, bop_frame_samples, bop_indices, frame_samples, workspace};

/// First scene seed of the validation split (training seeds stay far below).
pub const VAL_SEED_BASE: u64 = 0x7a11_0000_0000;

/// The validation split: rendered scenes `VAL_SEED_BASE..+frames`, or the BOP
/// dataset's held-out frames (index % 10 == 0); at most `max_samples` instances.
pub fn validation_set(
    set: &ObjectSet,
    source: &Source,
    num_points: usize,
    crop_size: usize,
    frames: usize,
    max_samples: usize,
) -> anyhow::Result<Vec<Sample>> {
    let cfg = DataConfig::unaugmented(num_points, crop_size);
    let mut ws = workspace(set, &cfg)?;
    let mut target = RenderTarget::for_intrinsics(&Intrinsics::YCB_VIDEO);
    let mut out = Vec::new();
    let frames: Vec<u64> = match source {
        Source::Rendered => (0..frames as u64).map(|i| VAL_SEED_BASE + i).collect(),
        Source::Bop(ds) => bop_indices(ds, true).into_iter().take(frames).map(|i| i as u64).collect(),
    };
    for f in frames {
        out.extend(match source {
            Source::Rendered => frame_samples(set, &cfg, f, &mut ws, &mut target, None)?,
            Source::Bop(ds) => bop_frame_samples(ds, f as usize, &cfg, VAL_SEED_BASE + f, &mut ws)?,
        });
        if out.len() >= max_samples {
            out.truncate(max_samples);
            break;
        }
    }
    Ok(out)
}

/// Validation results (metrics in percent) and engine timing.
#[derive(Clone, Debug, Default)]
pub struct Validation {
    pub metrics: BTreeMap<String, f64>,
    pub samples: usize,
    /// Engine milliseconds per object (colour + pose net + refiner iterations), single thread.
    pub engine_ms_per_object: f64,
}

/// Scores a weight file on `samples` with `refine_iters` refiner iterations.
pub fn validate(
    file: &WeightFile,
    set: &ObjectSet,
    samples: &[Sample],
    refine_iters: usize,
) -> anyhow::Result<Validation> {
    let engine = Engine::new(file)?;
    let c = &engine.config;
    let n = samples.first().map_or(c.num_points, |s| s.choose.len());
    let mut sc = Scratch::new(c, n, c.crop_size);
    let metrics: Vec<ObjectMetric> = set
        .objects
        .iter()
        .map(ObjectMetric::for_model)
        .collect::<Result<_, _>>()
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let (mut p_adds, mut p_add, mut r_adds, mut r_add) = (vec![], vec![], vec![], vec![]);
    let mut secs = 0.0;
    for s in samples {
        let pts = Array2::from_shape_vec((n, 3), s.points.clone())?;
        let ch = Array1::from_vec(s.choose.clone());
        let t0 = Instant::now();
        engine.set_inputs(&mut sc, s.crop.iter(), pts.view(), ch.view());
        engine.color(&mut sc);
        let best = engine.pose(&mut sc, s.class);
        let q = [sc.quat[[best, 0]], sc.quat[[best, 1]], sc.quat[[best, 2]], sc.quat[[best, 3]]];
        let mut rot = quat_matrix(q);
        let mut t = Vector3::new(sc.trans[[best, 0]], sc.trans[[best, 1]], sc.trans[[best, 2]]);
        let pose_est: Pose = Isometry3::from_parts(Translation3::from(t.cast::<f64>()), unit_quat(q));
        engine.refine_color(&mut sc);
        for _ in 0..refine_iters {
            (rot, t) = engine.refine(&mut sc, s.class, &rot, &t);
        }
        secs += t0.elapsed().as_secs_f64();
        let refined: Pose =
            Isometry3::from_parts(Translation3::from(t.cast::<f64>()), UnitQuaternion::from_matrix(&rot.cast::<f64>()));
        let m = &metrics[s.class];
        let e = m.errors(&pose_est, &s.pose);
        p_adds.push(e.add_s);
        p_add.push(e.add_or_add_s);
        let e = m.errors(&refined, &s.pose);
        r_adds.push(e.add_s);
        r_add.push(e.add_or_add_s);
    }
    let mut out = BTreeMap::new();
    for (stage, adds, add) in [("pose", &p_adds, &p_add), ("refined", &r_adds, &r_add)] {
        out.insert(format!("{stage}.add_s_auc"), vocap_auc_percent(adds));
        out.insert(format!("{stage}.add_or_add_s_auc"), vocap_auc_percent(add));
        out.insert(format!("{stage}.add_s_lt2cm"), accuracy_below_percent(adds, ADD_S_THRESHOLD_2CM));
        let mut sorted = adds.clone();
        sorted.sort_by(f64::total_cmp);
        if !sorted.is_empty() {
            out.insert(format!("{stage}.add_s_median_mm"), sorted[sorted.len() / 2] * 1000.0);
        }
    }
    Ok(Validation {
        metrics: out,
        samples: samples.len(),
        engine_ms_per_object: secs * 1000.0 / samples.len().max(1) as f64,
    })
}

/// One line per stage for logs and the progress bar.
pub fn summary(v: &Validation) -> String {
    let g = |k: &str| v.metrics.get(k).copied().unwrap_or(f64::NAN);
    format!(
        "val n={} | pose: ADD-S AUC {:.1} ADD(S) AUC {:.1} <2cm {:.1}% med {:.1} mm | refined: ADD-S AUC {:.1} ADD(S) AUC {:.1} <2cm {:.1}% med {:.1} mm | engine {:.2} ms/obj",
        v.samples,
        g("pose.add_s_auc"),
        g("pose.add_or_add_s_auc"),
        g("pose.add_s_lt2cm"),
        g("pose.add_s_median_mm"),
        g("refined.add_s_auc"),
        g("refined.add_or_add_s_auc"),
        g("refined.add_s_lt2cm"),
        g("refined.add_s_median_mm"),
        v.engine_ms_per_object
    )
}
