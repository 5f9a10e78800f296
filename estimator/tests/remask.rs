//! Second masks for failed poses (`fusepose_estimator::remask`): an object
//! whose region holds only part of it gets a pose off by centimetres that
//! fails verification; the pixels inside that pose's grown box make a mask
//! that holds the object, and its estimate replaces the failed pose. A
//! ghost region on the table gets no second mask; instance planes are the
//! producer's and are left alone. A pose that passed but that the network
//! doubted is replaced only by one it is surer of. A pose that failed on its
//! region's area (a speck) gets no second mask.

mod common;

use common::{PoseEach, l_block, left_part, object_set, painted, partial, render};
use fusepose_estimator::remask::{Remask, RemaskConfig, RemaskStats};
use fusepose_estimator::verify::{Verification, Verifier, VerifyConfig};
use fusepose_estimator::workspace::DEFAULT_SUPPORT_FLOOR_M;
use fusepose_estimator::{Estimator, FrameView, LabelPlane, PoseSet, Workspace, WorkspaceConfig};
use fusepose_scene::Pose;
use nalgebra::{Translation3, UnitQuaternion, Vector3};

fn truth() -> Pose {
    Pose::from_parts(Translation3::new(0.0, 0.0, 0.5), UnitQuaternion::from_scaled_axis(Vector3::z() * 0.2))
}

struct Outcome {
    before: Vec<Verification>,
    poses: PoseSet,
    verdicts: Vec<Verification>,
    stats: RemaskStats,
    ws: Workspace,
}

/// Prepares, estimates and verifies `view`, then gives the failed poses a second mask.
/// `support_floor_m`: the workspace's (the daemon's default is
/// [`DEFAULT_SUPPORT_FLOOR_M`]).
fn second_mask(view: &FrameView<'_>, estimator: &mut dyn Estimator, support_floor_m: f32) -> Outcome {
    second_mask_with(view, estimator, support_floor_m, RemaskConfig::DEFAULT)
}

fn second_mask_with(
    view: &FrameView<'_>,
    estimator: &mut dyn Estimator,
    support_floor_m: f32,
    config: RemaskConfig,
) -> Outcome {
    let objects = object_set(&[l_block()]);
    let ws_config = WorkspaceConfig { num_classes: 1, support_floor_m, ..Default::default() };
    let mut ws = Workspace::new(ws_config).unwrap();
    let mut poses = PoseSet::with_capacity(ws_config.max_instances);
    ws.prepare(view, 7).unwrap();
    estimator.estimate(view, &mut ws, &mut poses).unwrap();
    let mut verifier = Verifier::new(&objects, VerifyConfig::default());
    let mut verdicts: Vec<Verification> = poses
        .as_slice()
        .iter()
        .map(|p| verifier.verify(view, ws.mask_ref(ws.component_id(p.instance_id as usize).unwrap(), p.bbox), p))
        .collect();
    let before = verdicts.clone();
    let mut remask = Remask::new(&objects, ws_config, config).unwrap();
    let stats = remask.run(view, &ws, &mut poses, &mut verdicts, estimator, &mut verifier, None, 7).unwrap();
    Outcome { before, poses, verdicts, stats, ws }
}

#[test]
fn an_object_found_in_part_is_posed_from_its_second_mask() {
    let (frame, object_pixels) = left_part(painted(render(&[(1, &l_block(), truth())])));
    let out = second_mask(&frame.view(), &mut partial(truth(), object_pixels), DEFAULT_SUPPORT_FLOOR_M);
    assert_eq!(out.before.len(), 1);
    assert!(!out.before[0].passed, "the pose from part of the object fails: {:?}", out.before[0]);
    assert_eq!((out.stats.tried, out.stats.kept), (1, 1), "{:?} {:?}", out.stats, out.before[0]);
    assert!(out.verdicts[0].passed, "the replacing pose passed on the segmenter's region: {:?}", out.verdicts[0]);
    let p = out.poses.as_slice()[0];
    let error = (p.translation - truth().translation.vector).norm();
    assert!(error < 1e-6, "the second mask's pose is the truth, {error} m off");
    // The pose keeps its region: the published mask is still the segmenter's.
    let inst = out.ws.instances[p.instance_id as usize];
    assert_eq!((p.bbox, p.mask_pixels), (inst.bbox, inst.pixels));
}

#[test]
fn a_ghost_on_the_table_is_not_made_real_by_its_second_mask() {
    // No object: a patch of the background plane labelled as the block. With
    // the support floor on, the workspace drops such a region before any
    // pose; off, it gets a pose and a second mask of table pixels, whose
    // pose is judged on the region, as the first was.
    let mut frame = render(&[]);
    let w = frame.intrinsics.width as usize;
    for (p, l) in frame.labels.iter_mut().enumerate() {
        let (u, v) = (p % w, p / w);
        if (40..80).contains(&u) && (150..190).contains(&v) {
            *l = 1;
        }
    }
    let out = second_mask(
        &frame.view(),
        &mut PoseEach(|_: &fusepose_estimator::Instance, points: &[[f32; 3]]| {
            Pose::from_parts(common::centroid(points).into(), UnitQuaternion::identity())
        }),
        0.0,
    );
    assert_eq!(out.before.len(), 1);
    assert!(!out.before[0].passed, "a block's pose on a flat patch fails: {:?}", out.before[0]);
    assert_eq!((out.stats.tried, out.stats.kept), (1, 0), "{:?}", out.stats);
    assert!(out.stats.estimates > 0, "the table pixels were estimated");
    assert!(!out.verdicts[0].passed);
    assert_eq!(out.verdicts[0].fit, out.before[0].fit, "the failed pose keeps its verdict");
}

#[test]
fn an_instance_plane_is_left_to_its_producer() {
    let (frame, object_pixels) = left_part(painted(render(&[(1, &l_block(), truth())])));
    let ids: Vec<u16> = frame.labels.iter().map(|&l| l as u16).collect();
    let classes = [0u16, 1];
    let view = FrameView { labels: Some(LabelPlane::Instances { ids: &ids, classes: &classes }), ..frame.view() };
    let out = second_mask(&view, &mut partial(truth(), object_pixels), DEFAULT_SUPPORT_FLOOR_M);
    assert!(!out.before[0].passed);
    assert_eq!(out.stats, RemaskStats::default(), "instance planes are not looked at");
    assert!(!out.verdicts[0].passed);
}

/// Poses an instance whose mask holds at least 70 % of the object's
/// `object_pixels` at the truth with confidence `whole`, else 4° off about
/// the camera's axis (a pose that passes verification) with confidence
/// `part`: the network on a region that lost part of its object.
fn doubting(object_pixels: u32, part: f32, whole: f32) -> impl Estimator {
    PoseEach(move |inst: &fusepose_estimator::Instance, _: &[[f32; 3]]| {
        let whole_seen = inst.pixels as f64 >= 0.7 * object_pixels as f64;
        let turn = UnitQuaternion::from_scaled_axis(Vector3::z() * if whole_seen { 0.0 } else { 4f64.to_radians() });
        let pose = Pose::from_parts(truth().translation, turn * truth().rotation);
        (pose, if whole_seen { whole } else { part })
    })
}

const DOUBTED: RemaskConfig = RemaskConfig { max_confidence: 0.8, ..RemaskConfig::DEFAULT };

/// The left part of an L block, posed by [`doubting`] with confidences
/// `part` and `whole`, verified and given second masks under [`DOUBTED`];
/// the first pose (4° off) passes.
fn doubted(part: f32, whole: f32) -> Outcome {
    let (frame, object_pixels) = left_part(painted(render(&[(1, &l_block(), truth())])));
    let out =
        second_mask_with(&frame.view(), &mut doubting(object_pixels, part, whole), DEFAULT_SUPPORT_FLOOR_M, DOUBTED);
    assert!(out.before[0].passed, "the pose 4° off passes: {:?}", out.before[0]);
    out
}

#[test]
fn a_pose_the_network_doubted_is_replaced_by_one_it_is_surer_of() {
    let out = doubted(0.5, 0.9);
    assert_eq!((out.stats.tried, out.stats.doubted_tried, out.stats.doubted_kept), (0, 1, 1), "{:?}", out.stats);
    let p = out.poses.as_slice()[0];
    assert!(p.rotation.angle_to(&truth().rotation) < 1e-9, "the second mask's pose is the truth");
    assert_eq!(p.confidence, 0.9);
    assert!(out.verdicts[0].passed);
    let inst = out.ws.instances[p.instance_id as usize];
    assert_eq!((p.bbox, p.mask_pixels), (inst.bbox, inst.pixels), "the published mask stays the segmenter's");
}

#[test]
fn a_doubted_pose_stays_when_the_network_is_no_surer_of_its_successor() {
    let out = doubted(0.5, 0.45);
    assert_eq!((out.stats.doubted_tried, out.stats.doubted_kept), (1, 0), "{:?}", out.stats);
    let p = out.poses.as_slice()[0];
    assert!((p.rotation.angle_to(&truth().rotation) - 4f64.to_radians()).abs() < 1e-9, "the first pose stays");
    let (a, b) = (out.verdicts[0], out.before[0]);
    assert_eq!(
        (a.fit, a.inlier_fraction, a.mask_agreement),
        (b.fit, b.inlier_fraction, b.mask_agreement),
        "its verdict"
    );
}

#[test]
fn a_pose_the_network_is_sure_of_gets_no_second_mask() {
    let out = doubted(0.85, 0.99);
    assert_eq!(out.stats, RemaskStats::default(), "confidence 0.85 is above the 0.8 limit");
}

#[test]
fn a_pose_failed_on_its_region_area_gets_no_second_mask() {
    // The partial region of the first test, judged with an area floor it is
    // under: a pose made up for a speck must not be rebuilt from its posed box.
    let (frame, object_pixels) = left_part(painted(render(&[(1, &l_block(), truth())])));
    let view = frame.view();
    let objects = object_set(&[l_block()]);
    let ws_config = WorkspaceConfig { num_classes: 1, ..Default::default() };
    let mut ws = Workspace::new(ws_config).unwrap();
    let mut poses = PoseSet::with_capacity(ws_config.max_instances);
    let mut estimator = partial(truth(), object_pixels);
    ws.prepare(&view, 7).unwrap();
    estimator.estimate(&view, &mut ws, &mut poses).unwrap();
    for floor in [0.0, 1.0] {
        let mut verifier = Verifier::new(&objects, VerifyConfig { min_region_area_share: floor, ..Default::default() });
        let mut verdicts: Vec<Verification> = poses
            .as_slice()
            .iter()
            .map(|p| {
                let mut v =
                    verifier.verify(&view, ws.mask_ref(ws.component_id(p.instance_id as usize).unwrap(), p.bbox), p);
                v.region_area_share = verifier.region_area_share(&view, p);
                v
            })
            .collect();
        assert!(verdicts[0].region_area_share < 1.0 && !verdicts[0].passed, "{:?}", verdicts[0]);
        let mut remask = Remask::new(&objects, ws_config, RemaskConfig::DEFAULT).unwrap();
        let mut out = poses.clone();
        let stats = remask.run(&view, &ws, &mut out, &mut verdicts, &mut estimator, &mut verifier, None, 7).unwrap();
        let expected = if floor == 0.0 { (1, 1) } else { (0, 0) };
        assert_eq!((stats.tried, stats.kept), expected, "area floor {floor}: {stats:?}");
    }
}
