//! `views_per_frame`: one render gives several samples of each object, each
//! with its own point subset, and the first view is exactly the one-view
//! sample (so `--views-per-frame 1` trains on the same data as before).

use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::RenderTarget;
use fusepose_scene::{Intrinsics, ObjectSet};
use fusepose_train::data::{DataConfig, Sample, frame_samples, workspace};

fn samples(set: &ObjectSet, views: usize, seed: u64) -> Vec<Sample> {
    let dc = DataConfig { views_per_frame: views, ..DataConfig::unaugmented(256, 64) };
    let mut ws = workspace(set, &dc).unwrap();
    let mut target = RenderTarget::for_intrinsics(&Intrinsics::YCB_VIDEO);
    frame_samples(set, &dc, seed, &mut ws, &mut target, None).unwrap()
}

fn distinct_points(s: &Sample) -> usize {
    s.points
        .chunks(3)
        .map(|p| p.iter().map(|v| v.to_bits()).collect::<Vec<_>>())
        .collect::<std::collections::HashSet<_>>()
        .len()
}

#[test]
fn each_further_view_resamples_the_points_of_the_same_objects() {
    let set = builtin_objects();
    let one = samples(&set, 1, 41);
    let three = samples(&set, 3, 41);
    assert!(one.len() >= 3, "the scene shows several objects ({} samples)", one.len());
    assert_eq!(three.len(), 3 * one.len(), "three samples per object");
    let mut resampled = 0;
    for (view, chunk) in three.chunks(one.len()).enumerate() {
        for (a, b) in one.iter().zip(chunk) {
            assert_eq!((a.class, a.pose), (b.class, b.pose), "view {view}: the same object at the same pose");
            assert_eq!(a.crop, b.crop, "view {view}: the same render, so the same crop (no augmentation here)");
            if view == 0 {
                assert_eq!((&a.points, &a.choose), (&b.points, &b.choose), "the first view is the one-view sample");
            } else if distinct_points(a) == a.points.len() / 3 {
                // (A mask of fewer than 256 pixels is tiled, the same for every view.)
                let same = a.points.chunks(3).zip(b.points.chunks(3)).filter(|(x, y)| x == y).count();
                assert!(same < 128, "view {view}: its own point subset ({same} of 256 points shared)");
                resampled += 1;
            }
        }
    }
    assert!(resampled >= 2 * (one.len() - 1), "at most one small object ({resampled} resampled)");
}
