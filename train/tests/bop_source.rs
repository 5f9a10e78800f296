//! Training from a BOP split (`fusepose train --dataset`): frames written by
//! the scene crate's BOP writer come back as samples whose ground truth is the
//! right instance (the points sit on the object at its pose), frames with
//! index % 10 == 0 are held out, and a class-name mismatch is refused.

mod common;

use fusepose_scene::bop::BopDataset;
use fusepose_scene::builtin::builtin_objects;
use fusepose_train::data::{DataConfig, Source, bop_frame_samples, bop_indices, workspace};
use nalgebra::Point3;

#[test]
fn bop_frames_become_samples_matched_to_their_ground_truth() {
    let set = builtin_objects();
    let root = std::env::temp_dir().join(format!("fusepose-bop-src-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    common::write_rendered_split(&root, "train", &set, 11, 40);
    let split = root.join("train");
    let Source::Bop(ds) = Source::bop(&split, &set).unwrap() else { panic!("not a BOP source") };
    assert_eq!(ds.len(), 11);
    assert_eq!(bop_indices(&ds, true), vec![0, 10]);
    assert_eq!(bop_indices(&ds, false).len(), 9);

    let cfg = DataConfig { min_visible: 0.3, ..DataConfig::unaugmented(256, 64) };
    let mut ws = workspace(&set, &cfg).unwrap();
    let mut total = 0;
    for i in 0..3 {
        for s in bop_frame_samples(&ds, i, &cfg, 1, &mut ws).unwrap() {
            total += 1;
            // The observed points lie on the object: within its radius of its centre.
            let model = &set.objects[s.class];
            let centre = Point3::from((model.bbox_min.coords + model.bbox_max.coords) / 2.0);
            let c = s.pose * centre;
            let far = s
                .points
                .chunks_exact(3)
                .filter(|p| {
                    (Point3::new(p[0] as f64, p[1] as f64, p[2] as f64) - c).norm() > 0.6 * model.diameter + 0.01
                })
                .count();
            assert!(far * 10 < s.points.len() / 3, "{} of the points are far from {}", far, model.name);
        }
    }
    assert!(total >= 5, "only {total} samples from 3 frames");

    let mut other = set.clone();
    other.objects[0].name = "something_else".into();
    assert!(Source::bop(&split, &other).is_err());
    let _ = BopDataset::open(&split).unwrap();
    let _ = std::fs::remove_dir_all(&root);
}
