//! Pseudo-labelled frames in the segmenter's training (`--adapt-labels`):
//! a folder written by the scene crate's writer over a BOP split comes back
//! as samples whose cell targets are its labels (unknown pixels as
//! `IGNORE`, which the loss skips), and a stream with the whole share draws
//! only them; a folder for another object set is refused.

mod common;

use std::sync::Arc;
use std::time::Duration;

use fusepose_estimator::seg::SegConfig;
use fusepose_scene::Intrinsics;
use fusepose_scene::bop::{PseudoLabelWriter, UNKNOWN_LABEL};
use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::sampler::SamplerConfig;
use fusepose_train::seg::adapt::{AdaptFrames, IGNORE};
use fusepose_train::seg::data::SegStream;
use rand::SeedableRng;
use rand_pcg::Pcg64;

#[test]
fn pseudo_labels_become_cell_targets_and_unknown_cells_are_ignored() {
    let set = builtin_objects();
    let root = std::env::temp_dir().join(format!("fusepose-adapt-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&root);
    common::write_rendered_split(&root, "test", &set, 2, 70);
    let k = Intrinsics::YCB_VIDEO;
    let (w, h) = (k.width as usize, k.height as usize);
    let labels_dir = root.join("pseudo");
    let mut pseudo = PseudoLabelWriter::create(&labels_dir, &root.join("test"), set.len() as u16).unwrap();
    for im in 0..2u32 {
        // Labels: class 3 in the left half, unknown in the right half's top, background below it.
        let labels: Vec<u8> = (0..w * h)
            .map(|p| match (p % w < w / 2, p / w < h / 2) {
                (true, _) => 3,
                (false, true) => UNKNOWN_LABEL,
                (false, false) => 0,
            })
            .collect();
        pseudo.write_frame(0, im, k.width, k.height, &labels, 1).unwrap();
    }
    pseudo.finish().unwrap();

    let frames = AdaptFrames::load(std::slice::from_ref(&labels_dir), set.len()).unwrap();
    assert_eq!(frames.len(), 2);
    let cfg = SegConfig::new(set.len());
    let (gh, gw) = cfg.output_size();
    let mut rng = Pcg64::seed_from_u64(5);
    for _ in 0..6 {
        let s = frames.sample(&cfg, 0.5, &mut rng);
        assert_eq!(s.target.len(), gw * gh);
        assert!(s.input.iter().all(|v| v.is_finite()));
        // Flipped or not, each row holds 3 on one half and, on the other, unknown above and background below.
        for y in 0..gh {
            let row = &s.target[y * gw..(y + 1) * gw];
            let other = if y < gh / 2 { IGNORE } else { 0 };
            let left = row[0];
            assert!(left == 3 || left == other, "row {y}: {left}");
            let (a, b) = if left == 3 { (3, other) } else { (other, 3) };
            assert!(row[..gw / 2].iter().all(|&t| t == a) && row[gw / 2..].iter().all(|&t| t == b), "row {y}: {row:?}");
        }
    }

    // A stream drawing every frame from them delivers nothing else.
    let mut stream = SegStream::spawn(
        Arc::new(set.clone()),
        cfg.clone(),
        SamplerConfig::default(),
        0.0,
        11,
        2,
        1,
        Some((Arc::new(frames), 1.0)),
    )
    .unwrap();
    for _ in 0..3 {
        let s = stream.recv_timeout(Duration::from_secs(60)).unwrap();
        assert!(s.target.contains(&IGNORE), "a pseudo-labelled frame");
    }

    let wrong = AdaptFrames::load(std::slice::from_ref(&labels_dir), set.len() + 1).unwrap_err();
    assert!(format!("{wrong:#}").contains("classes"), "{wrong:#}");
    let missing = AdaptFrames::load(&[root.join("nowhere")], set.len()).unwrap_err();
    assert!(format!("{missing:#}").contains("fusepose eval --masks net --pseudo-labels"), "{missing:#}");
    let _ = std::fs::remove_dir_all(&root);
}
