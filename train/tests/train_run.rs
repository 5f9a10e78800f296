//! `fusepose_train::trainer::train` end to end, briefly: resume the shipped
//! model for two steps with half the frames masked by its own segmenter, then
//! validate. The written file loads in the inference engine, counts the
//! resumed steps, and keeps the segmenter the resumed file embedded (the
//! pose trainer writes pose tensors only; the segmenter is carried over,
//! into its checkpoints as well).

use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use fusepose_estimator::net::WeightFile;
use fusepose_estimator::seg::file::SegFile;
use fusepose_scene::builtin::builtin_objects;
use fusepose_train::data::Source;
use fusepose_train::trainer::{Stage, TrainOptions, train};

/// burn's random seed is one per process (`Device::seed`): two runs at once
/// would draw each other's initial weights, so these tests take turns (a
/// CI run once failed "fresh heads are seeded" that way).
static ONE_RUN_AT_A_TIME: Mutex<()> = Mutex::new(());

/// This test's turn, the shipped weight file, and a new folder `name` with its `out.safetensors`.
fn start(name: &str) -> (MutexGuard<'static, ()>, PathBuf, PathBuf, PathBuf) {
    let turn = ONE_RUN_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let shipped = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors");
    let dir = std::env::temp_dir().join(format!("fusepose-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("out.safetensors");
    (turn, shipped, dir, out)
}

#[test]
fn resumed_training_on_segmenter_masks_keeps_the_embedded_segmenter() {
    let (_turn, shipped, dir, out) = start("train-run");
    let start = WeightFile::read(&shipped).unwrap().train.unwrap_or_default().steps;
    let opts = TrainOptions {
        warm_start: None,
        out: out.clone(),
        minutes: None,
        steps: Some(start + 2),
        resume: Some(shipped.clone()),
        stage: Stage::Both,
        batch: 2,
        seed: 9,
        lr: 1e-5,
        loss_points: 100,
        checkpoint_dir: dir.clone(),
        checkpoint_every: Duration::ZERO,
        log: None,
        val_frames: 2,
        val_max_samples: 4,
        config: None,
        source: Source::Rendered,
        data_desc: "test".into(),
        progress: false,
        seg_masks: 0.5,
        partial_masks: 0.0,
        min_visible: 0.1,
        sampler: Default::default(),
        views_per_frame: 1,
        edge_views: 0,
        device: fusepose_train::device::TrainDevice::Cpu,
        data_threads: 2,
        heads_first: 0.0,
        warm_heads: Default::default(),
    };
    let summary = train(Arc::new(builtin_objects()), &opts).unwrap();
    assert_eq!(summary.record.steps, start + 2);
    let file = WeightFile::read(&out).unwrap();
    assert_eq!(file.train.unwrap().steps, start + 2);
    let (ours, theirs) = (SegFile::read(&out).unwrap(), SegFile::read(&shipped).unwrap());
    assert_eq!(ours.config, theirs.config);
    for (name, _) in ours.config.tensor_shapes() {
        assert_eq!(ours.tensor(&name).unwrap(), theirs.tensor(&name).unwrap(), "segmenter tensor {name}");
    }
    // The checkpoint (written after every step here) resumes like the file
    // it came from: `--seg-masks` needs the segmenter in it too.
    let ckpt = SegFile::read(&dir.join("checkpoint.safetensors")).expect("checkpoint without the segmenter");
    assert_eq!(ckpt.config, theirs.config);
    // Resuming from that checkpoint into the same folder overwrites the
    // resumed file at each checkpoint; the segmenter must survive that too.
    let resumed = dir.join("checkpoint.safetensors");
    let again = TrainOptions { resume: Some(resumed.clone()), steps: Some(start + 3), ..opts };
    train(Arc::new(builtin_objects()), &again).unwrap();
    let ckpt = SegFile::read(&resumed).expect("checkpoint resumed from itself lost the segmenter");
    assert_eq!(ckpt.config, theirs.config);
    let _ = std::fs::remove_dir_all(&dir);
}

/// `heads_first`: a warm-started run with its whole budget heads-first
/// changes the per-class output layers and leaves every trunk tensor bit for
/// bit as the warm-start file had it; with no trained trunk it is refused.
#[test]
fn heads_first_trains_the_class_heads_and_keeps_the_trunk() {
    let (_turn, shipped, dir, out) = start("heads-first");
    // Two of the built-ins: a new object set whose heads start fresh.
    let mut set = builtin_objects();
    set.objects.truncate(2);
    let opts = TrainOptions {
        warm_start: Some(shipped.clone()),
        out: out.clone(),
        minutes: None,
        steps: Some(3),
        resume: None,
        stage: Stage::Both,
        batch: 2,
        seed: 3,
        lr: 1e-3,
        loss_points: 100,
        checkpoint_dir: dir.clone(),
        checkpoint_every: Duration::from_secs(3600),
        log: None,
        val_frames: 1,
        val_max_samples: 2,
        config: None,
        source: Source::Rendered,
        data_desc: "test".into(),
        progress: false,
        seg_masks: 0.0,
        partial_masks: 0.0,
        min_visible: 0.1,
        sampler: Default::default(),
        views_per_frame: 1,
        edge_views: 0,
        device: fusepose_train::device::TrainDevice::Cpu,
        data_threads: 1,
        heads_first: 1.0,
        warm_heads: Default::default(),
    };
    let set = Arc::new(set);
    train(set.clone(), &opts).unwrap();
    let (ours, theirs) = (WeightFile::read(&out).unwrap(), WeightFile::read(&shipped).unwrap());
    let heads = ["pose.rot", "pose.tra", "pose.conf", "refine.rot", "refine.tra"];
    let mut trunk = 0;
    for (name, _) in ours.config.tensor_shapes() {
        if heads.iter().any(|h| name.starts_with(h)) {
            continue;
        }
        assert_eq!(ours.tensor(&name).unwrap(), theirs.tensor(&name).unwrap(), "trunk tensor {name} moved");
        trunk += 1;
    }
    assert!(trunk >= 40, "{trunk} trunk tensors compared");
    // The heads learned: a second run of zero steps gives the fresh heads as initialised.
    let fresh = dir.join("fresh.safetensors");
    train(set.clone(), &TrainOptions { steps: Some(0), out: fresh.clone(), heads_first: 0.0, ..opts.clone() }).unwrap();
    let fresh = WeightFile::read(&fresh).unwrap();
    let again = dir.join("fresh2.safetensors");
    train(set.clone(), &TrainOptions { steps: Some(0), out: again.clone(), heads_first: 0.0, ..opts.clone() }).unwrap();
    let again = WeightFile::read(&again).unwrap();
    assert_eq!(
        again.tensor("pose.rot.weight").unwrap(),
        fresh.tensor("pose.rot.weight").unwrap(),
        "fresh heads are seeded"
    );
    assert_ne!(
        ours.tensor("pose.rot.weight").unwrap(),
        fresh.tensor("pose.rot.weight").unwrap(),
        "heads did not learn"
    );

    let cold = TrainOptions { warm_start: None, ..opts };
    let err = train(set, &cold).unwrap_err().to_string();
    assert!(err.contains("--heads-first") && err.contains("--warm-start"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
