//! The daemon's engine gives the second look (`estimator.recut`) what
//! `fusepose eval` gives it: the poses that failed verification too, before
//! they are dropped. In a heap the one pose of a region of several copies
//! lies between them and fails; with `recut_poses = "any"` (the default)
//! the region is cut and each copy posed, with `"passed"` it is left alone.
//! Objects: a block ray-cast by the estimator tests' synthetic scenes, its
//! mesh written as a Wavefront OBJ folder and estimated by ICP, so that no
//! weight file decides.

#[path = "../../estimator/tests/common/mod.rs"]
mod common;

use common::{BoxObject, l_block, painted, render};
use fusepose_daemon::EstimatorKind;
use fusepose_daemon::config::{EstimatorConfig, MaskSource};
use fusepose_daemon::engine::{PoseEngine, StageTimes, resolve};
use fusepose_scene::Pose;
use nalgebra::{Translation3, UnitQuaternion, Vector3};

/// Four L blocks, 2 × 2, side by side (painted alike: one class region).
const BLOCKS: [[f64; 2]; 4] = [[-0.04, -0.035], [0.04, -0.035], [-0.04, 0.035], [0.04, 0.035]];

/// The poses (x, y) of one frame of [`BLOCKS`] through an engine with
/// `recut_poses` and the daemon's other defaults (verification drops failures).
/// Also the instances the frame ended with.
fn heap_through_the_engine(recut_poses: &str) -> (usize, Vec<[f64; 2]>) {
    let l = l_block();
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("l_block.obj"), boxes_obj(&l)).unwrap();
    let config = EstimatorConfig {
        kind: EstimatorKind::Icp,
        objects: dir.path().to_str().unwrap().to_owned(),
        masks: MaskSource::Labels,
        // The size cut before the estimate would separate the heap on its own.
        split_regions: 0.0,
        recut_poses: recut_poses.to_owned(),
        ..EstimatorConfig::default()
    };
    let spec = resolve(&config).unwrap();
    let mut engine = PoseEngine::new(&spec).unwrap();
    let turn = UnitQuaternion::from_scaled_axis(Vector3::z() * 10f64.to_radians());
    let objects: Vec<_> =
        BLOCKS.iter().map(|&[x, y]| (1, &l, Pose::from_parts(Translation3::new(x, y, 0.5), turn))).collect();
    let frame = painted(render(&objects));
    let mut times: StageTimes = Default::default();
    engine.run(&frame.view(), 7, &mut times).unwrap();
    (engine.instances_found(), engine.poses().iter().map(|p| [p.translation.x, p.translation.y]).collect())
}

/// The object's boxes as one Wavefront OBJ mesh of closed boxes (metres;
/// faces wound outward).
fn boxes_obj(object: &BoxObject) -> String {
    let mut obj = format!("o {}\n", object.name);
    for (b, (lo, hi)) in object.boxes.iter().enumerate() {
        for i in 0..8 {
            let c = |a: usize| if i >> a & 1 == 1 { hi[a] } else { lo[a] };
            obj += &format!("v {} {} {}\n", c(0), c(1), c(2));
        }
        // Vertex 8b + i + 1 has x = bit 0, y = bit 1, z = bit 2 of i.
        for f in [[1, 3, 4, 2], [5, 6, 8, 7], [1, 2, 6, 5], [3, 7, 8, 4], [1, 5, 7, 3], [2, 4, 8, 6]] {
            let [p, q, r, t] = f.map(|v| v + 8 * b);
            obj += &format!("f {p} {q} {r} {t}\n");
        }
    }
    obj
}

#[test]
fn a_failed_pose_of_a_heap_is_cut_into_a_pose_per_copy_before_failures_are_dropped() {
    let (instances, poses) = heap_through_the_engine("any");
    assert!(instances >= 2, "the region is cut");
    let nearest = |p: [f64; 2]| {
        (0..BLOCKS.len())
            .map(|b| (b, ((p[0] - BLOCKS[b][0]).powi(2) + (p[1] - BLOCKS[b][1]).powi(2)).sqrt()))
            .min_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap()
    };
    let mut blocks: Vec<usize> = poses.iter().filter(|&&p| nearest(p).1 < 0.02).map(|&p| nearest(p).0).collect();
    blocks.dedup();
    assert!(blocks.len() >= 2, "poses on two blocks or more, got {poses:.3?}");
    assert!(poses.iter().all(|&p| nearest(p).1 < 0.03), "no pose between the blocks: {poses:.3?}");
    // Only passed poses: the region's one pose fails and is dropped, uncut.
    let (instances, passed) = heap_through_the_engine("passed");
    assert_eq!(instances, 1, "one region");
    assert!(passed.is_empty(), "{passed:.3?}");
}
