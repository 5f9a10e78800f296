//! Diagnostics, not checks (`#[ignore]`), of the daemon's engine in
//! process on a heap of six identical boxes (the e2e heap video, seed 7,
//! class labels; docs/BENCHMARKS.md, session 31):
//! - the poses it publishes without a deadline, each against its nearest
//!   true copy with its verification terms: the poses that lie between
//!   copies yet pass verification;
//! - its frames against a 40.5 ms deadline: how many end late.
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
            let est = Isometry3::from_parts(Translation3::from(p.translation), p.rotation);
            let (m, d) = (&metrics[p.class_id as usize - 1], set.by_class(p.class_id).unwrap().diameter);
            let nearest = f
                .truth
                .iter()
                .filter(|(c, _)| *c == p.class_id)
                .map(|(_, t)| (m.add_s(&est, t) / d, (t.translation.vector - est.translation.vector).norm()))
                .min_by(|a, b| a.0.total_cmp(&b.0));
            if let Some((e, dt)) = nearest {
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
