//! Class alternates (`fusepose_estimator::alternates`) on a rendered frame
//! with the shipped weights: a region's alternate pose is exactly the pose
//! the region gets when labelled as that class (the fused features are
//! shared, only that class's head and refiner run); verification against
//! the depth image then keeps the class whose model the depth supports; and
//! the segmenter's per-class means over a region pick the runner-up class.
//! Skips (with a message) when models/builtin.safetensors is absent.

use fusepose_estimator::alternates::{self, MIN_FIT};
use fusepose_estimator::net::{NetEstimator, NetOptions};
use fusepose_estimator::seg::SegEngine;
use fusepose_estimator::verify::{Verifier, VerifyConfig};
use fusepose_estimator::{ColorFormat, DepthPlane, Estimator, FrameView, LabelPlane, ObjectPose, PoseSet, Workspace};
use fusepose_scene::Intrinsics;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};

fn shipped() -> Option<std::path::PathBuf> {
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    if weights.exists() {
        Some(weights)
    } else {
        eprintln!("SKIPPED: {} is missing", weights.display());
        None
    }
}

/// A rendered frame of three built-in objects (class labels).
fn rendered() -> RenderTarget {
    let set = fusepose_scene::builtin::builtin_objects();
    let k = Intrinsics::YCB_VIDEO;
    let cfg = SamplerConfig { min_objects: 3, max_objects: 3, ..SamplerConfig::default() };
    let scene = sample_scene(&set, &cfg, 11).unwrap();
    let mut target = RenderTarget::for_intrinsics(&k);
    render_view_labelled(&scene, &set, 0, &k, &NoiseConfig::default(), LabelKind::Class, &mut target).unwrap();
    target
}

fn frame<'a>(target: &'a RenderTarget, labels: &'a [u16]) -> FrameView<'a> {
    FrameView {
        intrinsics: Intrinsics::YCB_VIDEO,
        color_format: ColorFormat::Rgb8,
        color: target.rgb(),
        depth: DepthPlane::U16 { data: target.depth_u16(), scale: 1e-4 },
        labels: Some(LabelPlane::U16(labels)),
    }
}

fn angle_between(a: &ObjectPose, b: &ObjectPose) -> f64 {
    a.rotation.angle_to(&b.rotation)
}

#[test]
fn an_alternate_is_the_regions_pose_as_that_class_and_the_depth_picks_the_true_class() {
    let Some(weights) = shipped() else { return };
    let set = fusepose_scene::builtin::builtin_objects();
    let options = NetOptions { refine_iterations: Some(2), threads: 1, ..NetOptions::default() };
    let mut net = NetEstimator::load(&weights, &set, options).unwrap();
    let target = rendered();
    let frame = frame(&target, target.labels());
    let mut ws = Workspace::new(net.workspace_config(8)).unwrap();
    assert!(ws.prepare(&frame, 1).unwrap() >= 2);
    let mut out = PoseSet::with_capacity(16);
    net.estimate(&frame, &mut ws, &mut out).unwrap();
    let truth = out.as_slice()[0];
    let true_class = ws.instances[0].class_id;
    assert_eq!(truth.class_id, true_class);
    // The region's pixels (looked up by the segmented class, so before relabelling).
    let region = ws.component_id(0).unwrap();

    // The region mislabelled as another class, with its true class as the alternate.
    let k = set.len() as u16;
    let mut verifier = Verifier::new(&set, VerifyConfig::default());
    for wrong in (1..=k).filter(|&c| c != true_class) {
        ws.instances[0].class_id = wrong;
        ws.instances[0].alt_class_id = true_class;
        net.estimate(&frame, &mut ws, &mut out).unwrap();
        let of_region: Vec<ObjectPose> = out.as_slice().iter().copied().filter(|p| p.instance_id == 0).collect();
        assert_eq!(of_region.len(), 2, "{wrong}: the segmenter's class, then the alternate");
        let (primary, alternate) = (of_region[0], of_region[1]);
        assert_eq!((primary.class_id, alternate.class_id), (wrong, true_class));
        assert!(angle_between(&alternate, &truth) < 1e-5, "{wrong}: {alternate:?} vs {truth:?}");
        assert!((alternate.translation - truth.translation).norm() < 1e-6, "{wrong}");
        assert_eq!(alternate.iterations, 2);

        // Verification: the true class's model is what the depth supports.
        let mask = ws.mask_ref(region, primary.bbox);
        let verdicts = [verifier.verify(&frame, mask, &primary), verifier.verify(&frame, mask, &alternate)];
        assert!(verdicts[1].passed && verdicts[1].fit >= MIN_FIT, "{wrong}: {:?}", verdicts[1]);
        assert!(!alternates::fails_as_alternate(&ws.instances, &alternate, verdicts[1].fit));
        let mut marks = Vec::new();
        let n = alternates::losers(&of_region, |i| verdicts[i].class_score(), &mut marks);
        assert_eq!((n, marks.as_slice()), (1, &[true, false][..]), "{wrong}: {verdicts:?}");
    }

    // Without an alternate, one pose per region again.
    ws.instances[0].class_id = true_class;
    ws.instances[0].alt_class_id = 0;
    net.estimate(&frame, &mut ws, &mut out).unwrap();
    assert_eq!(out.as_slice().iter().filter(|p| p.instance_id == 0).count(), 1);
    // An alternate class the network does not have is refused by name.
    ws.instances[0].alt_class_id = k + 1;
    let err = net.estimate(&frame, &mut ws, &mut out).unwrap_err();
    assert!(err.to_string().contains(&(k + 1).to_string()), "{err}");
}

#[test]
fn the_segmenters_class_means_pick_the_runner_up_above_the_threshold() {
    let Some(weights) = shipped() else { return };
    let set = fusepose_scene::builtin::builtin_objects();
    let file = fusepose_estimator::seg::SegFile::read(&weights).unwrap();
    let mut seg = SegEngine::new(&file).unwrap();
    let target = rendered();
    let mut labels = vec![0u16; target.labels().len()];
    seg.segment(&frame(&target, target.labels()), &mut labels).unwrap();
    let net = NetEstimator::load(&weights, &set, NetOptions { threads: 1, ..NetOptions::default() }).unwrap();
    let mut ws = Workspace::new(net.workspace_config(8)).unwrap();
    let seg_frame = frame(&target, &labels);
    let found = ws.prepare(&seg_frame, 1).unwrap();
    assert!(found >= 2, "the segmenter finds the objects");

    let mut means = vec![0.0; set.len() + 1];
    for i in 0..found {
        let inst = ws.instances[i];
        let id = ws.component_id(i).unwrap();
        assert!(seg.region_class_means(ws.component_ids(), id, inst.bbox, &mut means) > 0);
        let total: f32 = means.iter().sum();
        assert!((total - 1.0).abs() < 1e-3, "means sum to one: {means:?}");
        // The mean of a class never exceeds its peak over the same cells.
        for c in 1..=set.len() as u16 {
            let peak = seg.region_probability(ws.component_ids(), id, c, inst.bbox);
            assert!(means[c as usize] <= peak + 1e-5, "class {c}: mean {} > peak {peak}", means[c as usize]);
        }
    }
    // A wrong-sized buffer reads nothing.
    let id = ws.component_id(0).unwrap();
    assert_eq!(seg.region_class_means(ws.component_ids(), id, ws.instances[0].bbox, &mut [0.0; 2]), 0);

    // Any runner-up clears a tiny threshold (and is never the region's own
    // class); none clears certainty itself; 0 is off.
    let mut scratch = Vec::new();
    assert_eq!(alternates::mark(&mut ws, &seg, 1e-9, &mut scratch), found);
    assert!(ws.instances.iter().all(|i| i.alt_class_id != 0 && i.alt_class_id != i.class_id));
    for off in [1.0, 0.0] {
        assert_eq!(alternates::mark(&mut ws, &seg, off, &mut scratch), 0);
        assert!(ws.instances.iter().all(|i| i.alt_class_id == 0));
    }
}
