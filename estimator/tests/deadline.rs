//! Deadline-aware network estimation on a rendered frame with the shipped
//! weights: without a deadline every object gets the full refiner; with a
//! deadline that cannot be met the frame degrades (no refiner, fewer points,
//! one instance) and says so, and frame after frame the instances take turns
//! (the largest is not the only one ever posed); a generous deadline gives the
//! full plan back.
//! Skips (with a message) when models/builtin.safetensors is absent.

use std::time::{Duration, Instant};

use fusepose_estimator::net::{NetEstimator, NetOptions};
use fusepose_estimator::{ColorFormat, DepthPlane, Estimator, FrameView, LabelPlane, PoseSet, Workspace};
use fusepose_scene::Intrinsics;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};

#[test]
fn refiner_iterations_and_points_follow_the_deadline() {
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    if !weights.exists() {
        eprintln!("SKIPPED: {} is missing", weights.display());
        return;
    }
    let set = fusepose_scene::builtin::builtin_objects();
    let options = NetOptions { refine_iterations: Some(2), threads: 1, ..NetOptions::default() };
    let mut net = NetEstimator::load(&weights, &set, options).unwrap();
    let k = Intrinsics::YCB_VIDEO;
    let cfg = SamplerConfig { min_objects: 3, max_objects: 3, ..SamplerConfig::default() };
    let scene = sample_scene(&set, &cfg, 11).unwrap();
    let mut target = RenderTarget::for_intrinsics(&k);
    render_view_labelled(&scene, &set, 0, &k, &NoiseConfig::default(), LabelKind::Class, &mut target).unwrap();
    let frame = FrameView {
        intrinsics: k,
        color_format: ColorFormat::Rgb8,
        color: target.rgb(),
        depth: DepthPlane::U16 { data: target.depth_u16(), scale: 1e-4 },
        labels: Some(LabelPlane::U16(target.labels())),
    };
    let mut ws = Workspace::new(net.workspace_config(8)).unwrap();
    let found = ws.prepare(&frame, 1).unwrap();
    assert!(found >= 2, "the scene shows several objects");
    let mut out = PoseSet::with_capacity(8);
    let full_points = net.workspace_config(8).num_points;

    // No deadline: the full refiner for every object (this also teaches the costs).
    net.estimate(&frame, &mut ws, &mut out).unwrap();
    assert!(out.as_slice().iter().all(|p| p.iterations == 2), "{:?}", out.as_slice());
    assert!(!net.degraded());

    // A deadline already (almost) over: no refiner, a quarter of the points,
    // one instance, flagged: the largest first, then each other one in turn.
    let mut posed = Vec::new();
    for frame_no in 0..found {
        net.set_deadline(Some(Instant::now() + Duration::from_micros(10)));
        net.estimate(&frame, &mut ws, &mut out).unwrap();
        assert_eq!(out.len(), 1, "only one instance is paid for");
        assert_eq!(net.last_shed(), found - 1);
        assert!(out.as_slice().iter().all(|p| p.iterations == 0), "{:?}", out.as_slice());
        assert!(net.degraded());
        assert_eq!(net.last_plan().points, full_points.div_ceil(4));
        assert!(out.as_slice().iter().all(|p| p.translation.iter().all(|v| v.is_finite()) && p.translation.z > 0.0));
        let p = out.as_slice()[0];
        assert_eq!(p.class_id, ws.instances[usize::from(p.instance_id)].class_id);
        if frame_no == 0 {
            assert_eq!(p.instance_id, 0, "the largest goes first");
        }
        // The classes shed are those of the instances left without a pose.
        for (i, inst) in ws.instances.iter().enumerate() {
            let copies_posed = ws
                .instances
                .iter()
                .enumerate()
                .all(|(j, o)| o.class_id != inst.class_id || j == usize::from(p.instance_id));
            assert_eq!(net.shed_class(inst.class_id), !copies_posed, "instance {i} of class {}", inst.class_id);
        }
        posed.push(p.instance_id);
    }
    posed.sort_unstable();
    posed.dedup();
    assert_eq!(posed.len(), found, "in {found} late frames every instance had its turn: {posed:?}");

    // Plenty of time: full again.
    net.set_deadline(Some(Instant::now() + Duration::from_secs(10)));
    net.estimate(&frame, &mut ws, &mut out).unwrap();
    assert!(out.as_slice().iter().all(|p| p.iterations == 2));
    assert!(!net.degraded());
    assert_eq!(net.last_plan().points, full_points);
    assert_eq!(net.last_shed(), 0);
    assert!(ws.instances.iter().all(|i| !net.shed_class(i.class_id)), "nothing shed, no class shed");
    let c = net.counters();
    let found = found as u64;
    assert_eq!((c.objects, c.degraded_frames, c.reduced_point_objects), (3 * found, found, found));
    assert_eq!(c.shed_objects, found * (found - 1));
}
