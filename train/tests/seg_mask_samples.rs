//! Training on the segmenter's masks (`fusepose train --seg-masks F`): with
//! the segmenter shipped in `models/builtin.safetensors`, rendered frames give
//! samples cut by the segmenter's labels — different points from the
//! ground-truth masks, but views of the same objects — and a share of 0 leaves
//! the ground-truth samples untouched.

use fusepose_estimator::seg::SegEngine;
use fusepose_scene::Intrinsics;
use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::RenderTarget;
use fusepose_train::data::{DataConfig, Sample, SegMasks, frame_samples, workspace};

fn centroid(s: &Sample) -> [f32; 3] {
    let mut c = [0.0f32; 3];
    for p in s.points.chunks_exact(3) {
        for j in 0..3 {
            c[j] += p[j];
        }
    }
    let n = (s.points.len() / 3) as f32;
    c.map(|v| v / n)
}

#[test]
fn segmenter_masks_give_other_points_of_the_same_objects() {
    let weights = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    let set = builtin_objects();
    let engine = || SegEngine::load(&weights, &set).expect("the shipped model embeds a segmenter");
    let dc = DataConfig::unaugmented(256, 64);
    let mut ws = workspace(&set, &dc).unwrap();
    let mut target = RenderTarget::for_intrinsics(&Intrinsics::YCB_VIDEO);
    let mut always = SegMasks::new(engine(), 1.0);
    let mut never = SegMasks::new(engine(), 0.0);
    let (mut seg_total, mut matched, mut differ) = (0, 0, 0);
    for seed in 200..206 {
        let gt = frame_samples(&set, &dc, seed, &mut ws, &mut target, None).unwrap();
        let gt_again = frame_samples(&set, &dc, seed, &mut ws, &mut target, Some(&mut never)).unwrap();
        assert_eq!(gt.len(), gt_again.len(), "share 0 must keep the ground-truth masks");
        for (a, b) in gt.iter().zip(&gt_again) {
            assert_eq!(a.points, b.points);
        }
        let seg = frame_samples(&set, &dc, seed, &mut ws, &mut target, Some(&mut always)).unwrap();
        for s in &seg {
            seg_total += 1;
            let Some(g) = gt.iter().find(|g| g.class == s.class) else { continue };
            let (cs, cg) = (centroid(s), centroid(g));
            let d = ((cs[0] - cg[0]).powi(2) + (cs[1] - cg[1]).powi(2) + (cs[2] - cg[2]).powi(2)).sqrt();
            matched += (d < 0.03) as usize;
            differ += (s.points != g.points) as usize;
        }
    }
    println!(
        "segmenter samples {seg_total}, centroid within 3 cm of the GT-mask sample {matched}, other points {differ}"
    );
    assert!(seg_total >= 15, "only {seg_total} samples from 6 frames with segmenter masks");
    assert!(matched * 10 >= seg_total * 8, "{matched} of {seg_total} segmenter samples view their object");
    assert!(differ * 2 >= seg_total, "segmenter masks should change most samples ({differ} of {seg_total})");
}
