//! `views_per_frame`: one render gives several samples of each object, each
//! with its own point subset, and the first view is exactly the one-view
//! sample (so `--views-per-frame 1` trains on the same data as before).
//! `edge_views`: further samples of the objects cut by the image edge only.

use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::RenderTarget;
use fusepose_scene::{Intrinsics, ObjectSet};
use fusepose_train::data::{DataConfig, Sample, cut_by_edge, frame_samples, workspace};

fn samples(set: &ObjectSet, views: usize, seed: u64) -> Vec<Sample> {
    samples_with(set, DataConfig { views_per_frame: views, ..DataConfig::unaugmented(256, 64) }, seed)
}

fn samples_with(set: &ObjectSet, dc: DataConfig, seed: u64) -> Vec<Sample> {
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

/// Pixels between the sample's nearest point and the image border (its points
/// are its mask's pixels back-projected, so they project onto those pixels).
fn border_gap(s: &Sample) -> f64 {
    let k = Intrinsics::YCB_VIDEO;
    s.points
        .chunks(3)
        .filter_map(|p| k.project(&nalgebra::Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)))
        .map(|(u, v)| u.min(v).min(k.width as f64 - 1.0 - u).min(k.height as f64 - 1.0 - v))
        .fold(f64::INFINITY, f64::min)
}

#[test]
fn edge_views_add_samples_of_the_objects_cut_by_the_image_edge_only() {
    let set = builtin_objects();
    let (mut with_extra, mut without) = (0, 0);
    for seed in 40..52 {
        let plain = samples(&set, 1, seed);
        let edge = samples_with(&set, DataConfig { edge_views: 2, ..DataConfig::unaugmented(256, 64) }, seed);
        let key = |s: &Sample| (s.class, s.pose, s.crop.clone(), s.points.clone(), s.choose.clone());
        assert!(
            edge.len() >= plain.len() && plain.iter().zip(&edge).all(|(a, b)| key(a) == key(b)),
            "seed {seed}: the frame's own samples come first, unchanged"
        );
        let extra = &edge[plain.len()..];
        for s in &plain {
            let n = extra.iter().filter(|e| (e.class, e.pose) == (s.class, s.pose)).count();
            let gap = border_gap(s);
            if n > 0 {
                assert_eq!(n, 2, "seed {seed}: two more samples of an edge-cut object");
                assert!(gap < 20.0, "seed {seed}: an extra sample of an object {gap:.1} px from the border");
                with_extra += 1;
            } else {
                assert!(gap > 0.5, "seed {seed}: an object on the border ({gap:.1} px) got no extra sample");
                without += 1;
            }
        }
        assert!(extra.iter().all(|e| plain.iter().any(|s| (s.class, s.pose) == (e.class, e.pose))));
    }
    assert!(with_extra >= 2 && without >= 2, "both kinds seen: {with_extra} cut by the edge, {without} inside");
}

#[test]
fn a_box_touching_any_side_of_the_image_is_cut_by_its_edge() {
    assert!(!cut_by_edge([1, 1, 638, 478], 640, 480));
    assert!(cut_by_edge([0, 100, 50, 200], 640, 480));
    assert!(cut_by_edge([100, 0, 150, 200], 640, 480));
    assert!(cut_by_edge([600, 100, 639, 200], 640, 480));
    assert!(cut_by_edge([100, 400, 150, 479], 640, 480));
}
