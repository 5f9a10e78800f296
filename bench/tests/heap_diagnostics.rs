//! Diagnostics, not checks (`#[ignore]`), of the daemon's engine in
//! process on a heap of six identical boxes (the e2e heap video, seed 7,
//! class labels; docs/BENCHMARKS.md, session 31):
//! - the poses it publishes without a deadline, each against its nearest
//!   true copy with its verification terms: the poses that lie between
//!   copies yet pass verification;
//! - its frames against a 40.5 ms deadline: how many end late;
//! - how many of its poses a pose of the previous frames confirms (the
//!   daemon's `CONFIRMED` flag), found and stray ones apart, also on pairs
//!   and one-of-each videos and with the segmenter (session 32).
//!
//! `cargo test --release -p fusepose-bench --test heap_diagnostics -- --ignored --nocapture`

use std::time::{Duration, Instant};

use fusepose_bench::video::{self, Copies, Video};
use fusepose_daemon::config::{EstimatorConfig, MaskSource};
use fusepose_daemon::engine::{PoseEngine, StageTimes, resolve};
use fusepose_scene::metrics::ObjectMetric;
use nalgebra::{Isometry3, Translation3};

/// The heap video and an engine with the daemon's defaults on class labels.
fn heap_and_engine() -> (fusepose_scene::ObjectSet, Video, PoseEngine) {
    let set = fusepose_scene::builtin::builtin_objects();
    let v = video::render_video_with(&set, 1, Copies::Heap, 48, 0.5, 7).unwrap();
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    let config = EstimatorConfig { weights, masks: MaskSource::Labels, ..EstimatorConfig::default() };
    let engine = PoseEngine::new(&resolve(&config).unwrap()).unwrap();
    (set, v, engine)
}

/// (ADD-S / diameter, translation error m) of `p` to the nearest true object of its class.
fn nearest_copy(
    set: &fusepose_scene::ObjectSet,
    metrics: &[ObjectMetric],
    truth: &[(u16, fusepose_scene::Pose)],
    p: &fusepose_estimator::ObjectPose,
) -> Option<(f64, f64)> {
    let est = Isometry3::from_parts(Translation3::from(p.translation), p.rotation);
    let (m, d) = (&metrics[p.class_id as usize - 1], set.by_class(p.class_id)?.diameter);
    truth
        .iter()
        .filter(|(c, _)| *c == p.class_id)
        .map(|(_, t)| (m.add_s(&est, t) / d, (t.translation.vector - est.translation.vector).norm()))
        .min_by(|a, b| a.0.total_cmp(&b.0))
}

#[test]
#[ignore]
fn heap_frames_against_the_deadline() {
    let (_, v, mut engine) = heap_and_engine();
    let (frames, mut late) = (240, 0);
    for i in 0..frames {
        let f = &v.frames[video::ping_pong(i, v.frames.len())];
        let start = Instant::now();
        engine.set_deadline(Some(start + Duration::from_micros(40_500)));
        let mut times: StageTimes = Default::default();
        engine.run(&f.view(v.intrinsics), i as u64, &mut times).unwrap();
        late += (start.elapsed() > Duration::from_micros(41_700)) as usize;
    }
    println!("{late} of {frames} frames ended past 41.7 ms (deadline set at 40.5 ms)");
}

#[test]
#[ignore]
fn heap_poses_against_their_nearest_copy() {
    let (set, v, mut engine) = heap_and_engine();
    let metrics: Vec<ObjectMetric> = set.objects.iter().map(|o| ObjectMetric::for_model(o).unwrap()).collect();
    // (ADD-S / diameter to the nearest copy, translation error m, fit, depth residual m)
    let mut rows = Vec::new();
    for i in (0..v.frames.len()).step_by(2) {
        let f = &v.frames[i];
        let mut times: StageTimes = Default::default();
        engine.set_deadline(None);
        engine.run(&f.view(v.intrinsics), i as u64, &mut times).unwrap();
        for (p, ver) in engine.poses().iter().zip(engine.verdicts()) {
            if let Some((e, dt)) = nearest_copy(&set, &metrics, &f.truth, p) {
                rows.push((e, dt, ver.fit, ver.depth_residual_m));
            }
        }
    }
    for (name, wrong) in [("found (ADD-S < 0.1 d)", false), ("wrong", true)] {
        let mut of: Vec<_> = rows.iter().filter(|r| (r.0 >= 0.1) == wrong).collect();
        of.sort_by(|a, b| a.2.total_cmp(&b.2));
        let n = of.len().max(1) as f64;
        let mean = |k: fn(&&(f64, f64, f32, f32)) -> f64| of.iter().map(k).sum::<f64>() / n;
        let (near, far) = of.iter().fold((f64::INFINITY, 0.0f64), |(a, b), r| (a.min(r.1), b.max(r.1)));
        println!(
            "{name}: {} poses, translation error mean {:.1} mm ({:.1}–{:.1}), fit mean {:.3} (p10 {:.3}, {} below 0.5), depth residual mean {:.1} mm",
            of.len(),
            1e3 * mean(|r| r.1),
            1e3 * near,
            1e3 * far,
            mean(|r| r.2 as f64),
            of.get(of.len() / 10).map_or(f32::NAN, |r| r.2),
            of.iter().filter(|r| r.2 < 0.5).count(),
            1e3 * mean(|r| r.3 as f64),
        );
    }
}

/// Per published pose: (class id, translation in the camera of each later
/// frame it is carried into, stray?) for the confirmation diagnostic.
struct Published {
    class_id: u16,
    translation: nalgebra::Vector3<f64>,
    stray: bool,
}

#[test]
#[ignore]
fn poses_confirmed_by_earlier_frames() {
    let set = fusepose_scene::builtin::builtin_objects();
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    let metrics: Vec<ObjectMetric> = set.objects.iter().map(|o| ObjectMetric::for_model(o).unwrap()).collect();
    let cases = [
        ("heap of six, class labels", 1, Copies::Heap, MaskSource::Labels),
        ("heap of six, segmenter", 1, Copies::Heap, MaskSource::Net),
        ("two pairs, class labels", 2, Copies::Pair, MaskSource::Labels),
        ("five objects, segmenter", 5, Copies::None, MaskSource::Net),
    ];
    for (name, objects, copies, masks) in cases {
        let config = EstimatorConfig { weights: weights.clone(), masks, ..EstimatorConfig::default() };
        let v = video::render_video_with(&set, objects, copies, 48, 0.5, 7).unwrap();
        let mut engine = PoseEngine::new(&resolve(&config).unwrap()).unwrap();
        // Each frame's poses in that frame's camera.
        let mut frames: Vec<Vec<Published>> = Vec::new();
        for (i, f) in v.frames.iter().enumerate() {
            let mut times: StageTimes = Default::default();
            engine.set_deadline(None);
            engine.run(&f.view(v.intrinsics), i as u64, &mut times).unwrap();
            frames.push(
                engine
                    .poses()
                    .iter()
                    .map(|p| {
                        let near = nearest_copy(&set, &metrics, &f.truth, p).map_or(f64::INFINITY, |n| n.0);
                        Published { class_id: p.class_id, translation: p.translation, stray: near >= 0.1 }
                    })
                    .collect(),
            );
        }
        // The scene is static and the camera orbits: earlier poses are carried
        // into a frame's camera by the truth's own motion (as a fixed camera
        // would see them).
        for (gate, back) in [(0.01, 1), (0.01, 3), (0.02, 1)] {
            let mut table = [[0usize; 2]; 2]; // [stray][confirmed]
            for i in back..frames.len() {
                for p in &frames[i] {
                    let confirmed = (1..=back).any(|k| {
                        let motion = v.frames[i].truth[0].1 * v.frames[i - k].truth[0].1.inverse();
                        frames[i - k].iter().any(|q| {
                            let t = motion.transform_point(&q.translation.into()).coords;
                            q.class_id == p.class_id && (t - p.translation).norm() < gate
                        })
                    });
                    table[p.stray as usize][confirmed as usize] += 1;
                }
            }
            println!(
                "{name}, a pose of the last {back} frame(s) within {:.0} mm: found {} of {} confirmed, stray {} of {}",
                gate * 1e3,
                table[0][1],
                table[0][0] + table[0][1],
                table[1][1],
                table[1][0] + table[1][1]
            );
        }
    }
}
