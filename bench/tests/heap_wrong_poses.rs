//! Diagnostic, not a check (`#[ignore]`): the poses the daemon's engine
//! publishes for a heap of six identical boxes (the e2e heap video, seed 7,
//! class labels, no deadline), each with its distance to the nearest true
//! copy and its verification terms, to study the poses that lie between
//! copies yet pass verification (docs/BENCHMARKS.md, session 31).
//!
//! `cargo test --release -p fusepose-bench --test heap_wrong_poses -- --ignored --nocapture`

use fusepose_bench::video::{self, Copies};
use fusepose_daemon::config::{EstimatorConfig, MaskSource};
use fusepose_daemon::engine::{PoseEngine, StageTimes, resolve};
use fusepose_scene::metrics::ObjectMetric;
use nalgebra::{Isometry3, Translation3};

#[test]
#[ignore]
fn heap_poses_against_their_nearest_copy() {
    let set = fusepose_scene::builtin::builtin_objects();
    let v = video::render_video_with(&set, 1, Copies::Heap, 48, 0.5, 7).unwrap();
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    let config = EstimatorConfig { weights, masks: MaskSource::Labels, ..EstimatorConfig::default() };
    let mut engine = PoseEngine::new(&resolve(&config).unwrap()).unwrap();
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
        println!(
            "{name}: {} poses, translation error mean {:.1} mm, fit mean {:.3} (p10 {:.3}), depth residual mean {:.1} mm",
            of.len(),
            1e3 * mean(|r| r.1),
            mean(|r| r.2 as f64),
            of.get(of.len() / 10).map_or(f32::NAN, |r| r.2),
            1e3 * mean(|r| r.3 as f64),
        );
    }
}
