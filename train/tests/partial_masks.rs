//! `partial_masks`: ground-truth masks cut to a part, as a segmenter finds
//! objects on images it did not learn from.

use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::RenderTarget;
use fusepose_scene::{Intrinsics, ObjectSet};
use fusepose_train::data::{DataConfig, MIN_CUT_PIXELS, Sample, cut_masks, frame_samples, workspace};
use rand::SeedableRng;

fn samples(set: &ObjectSet, partial: f64, seed: u64) -> Vec<Sample> {
    let dc = DataConfig { partial_masks: partial, ..DataConfig::unaugmented(256, 64) };
    let mut ws = workspace(set, &dc).unwrap();
    let mut target = RenderTarget::for_intrinsics(&Intrinsics::YCB_VIDEO);
    frame_samples(set, &dc, seed, &mut ws, &mut target, None).unwrap()
}

#[test]
fn a_cut_keeps_one_side_of_a_line_through_each_large_mask() {
    let (w, h) = (100usize, 60usize);
    let mut instances = vec![0u16; w * h];
    let mut classes = vec![0u16; w * h];
    // Object 1 (class 3): a 40 x 30 block; object 2 (class 5): 10 x 10, under the size cut.
    for v in 10..40 {
        for u in 10..50 {
            instances[v * w + u] = 1;
            classes[v * w + u] = 3;
        }
    }
    for v in 45..55 {
        for u in 70..80 {
            instances[v * w + u] = 2;
            classes[v * w + u] = 5;
        }
    }
    const { assert!(100 < MIN_CUT_PIXELS && 1200 >= MIN_CUT_PIXELS) };
    let mut kept_shares = Vec::new();
    for seed in 0..20 {
        let mut cut = classes.clone();
        cut_masks(&mut cut, &instances, w, &mut rand_pcg::Pcg64::seed_from_u64(seed));
        let kept: Vec<usize> = (0..w * h).filter(|&p| instances[p] == 1 && cut[p] == 3).collect();
        let share = kept.len() as f64 / 1200.0;
        assert!((0.29..=0.91).contains(&share), "seed {seed}: kept {share:.2} of the block");
        assert!((0..w * h).all(|p| instances[p] != 1 || cut[p] == 3 || cut[p] == 0), "only background is written");
        assert!((0..w * h).all(|p| instances[p] == 1 || cut[p] == classes[p]), "the small object and background stay");
        // One side of a line: every removed pixel lies farther along some direction
        // than every kept one. Checked over 360 directions.
        let removed: Vec<usize> = (0..w * h).filter(|&p| instances[p] == 1 && cut[p] == 0).collect();
        let separable = (0..360).any(|deg| {
            let a = (deg as f64).to_radians();
            let along = |p: usize| (p % w) as f64 * a.cos() + (p / w) as f64 * a.sin();
            let kept_max = kept.iter().map(|&p| along(p)).fold(f64::MIN, f64::max);
            removed.iter().all(|&p| along(p) >= kept_max - 0.7)
        });
        assert!(separable, "seed {seed}: the cut is not a line");
        kept_shares.push(share);
    }
    let (lo, hi) = kept_shares.iter().fold((1.0f64, 0.0f64), |(l, h), &s| (l.min(s), h.max(s)));
    assert!(hi - lo > 0.3, "the kept share varies ({lo:.2}..{hi:.2})");
}

#[test]
fn partial_mask_frames_train_on_parts_of_the_same_objects() {
    let set = builtin_objects();
    let whole = samples(&set, 0.0, 41);
    let cut = samples(&set, 1.0, 41);
    assert!(whole.len() >= 3, "the scene shows several objects ({} samples)", whole.len());
    let mut smaller = 0;
    for c in &cut {
        let w =
            whole.iter().find(|w| w.class == c.class && w.pose == c.pose).expect("a cut object is one of the frame's");
        // The crop covers the region's box: a part has a box of its own.
        smaller += (c.crop != w.crop) as usize;
    }
    assert!(smaller * 2 >= cut.len(), "most objects were seen in part ({smaller} of {})", cut.len());
    assert_eq!(samples(&set, 0.0, 41).len(), whole.len(), "without the share the frame is as before");
}
