//! Parity: the segmenter inference engine (`fusepose_estimator::seg`) and the
//! burn forward pass give the same logits for the same weights and input,
//! within 1e-4 of the largest logit magnitude — for the default 160x120 input
//! and an odd size whose nearest upsampling ratios are not integers. Also: the
//! engine's labels are the argmax of burn's logits, and loading refuses files
//! that do not fit the object set or are not segmenter files.

use burn::prelude::{Device, Tensor, TensorData};
use fusepose_estimator::net::NetLoadError;
use fusepose_estimator::net::meta::{TrainRecord, object_entries};
use fusepose_estimator::seg::{SegConfig, SegEngine, SegFile};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView};
use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::{Intrinsics, ObjectSet};
use fusepose_train::seg::model::SegNet;
use fusepose_train::seg::store;
use rand::{Rng, SeedableRng};

/// A scratch directory removed on drop.
struct Scratch(std::path::PathBuf);

impl Scratch {
    fn new(name: &str) -> Self {
        let d = std::env::temp_dir().join(format!("fusepose-seg-parity-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        Self(d)
    }
    fn path(&self) -> &std::path::Path {
        &self.0
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn three_objects() -> ObjectSet {
    ObjectSet { objects: builtin_objects().objects.into_iter().take(3).collect() }
}

fn save_random(cfg: &SegConfig, set: &ObjectSet, path: &std::path::Path) -> SegNet {
    let net = SegNet::new(cfg, &Device::flex());
    store::save(&net, cfg, &object_entries(set), &TrainRecord::default(), &serde_json::json!({}), path).unwrap();
    net
}

/// A segmenter file without offsets or contacts (as the shipped one), its
/// config, path and network.
fn plain_segmenter(set: &ObjectSet, dir: &Scratch) -> (SegConfig, std::path::PathBuf, SegNet) {
    let plain = SegConfig { offsets: false, ..SegConfig::new(set.len()) };
    let path = dir.path().join("plain.safetensors");
    save_random(&plain, set, &path);
    let net = store::load(&path, &Device::flex()).unwrap().net;
    (plain, path, net)
}

/// Three training steps with the trunk frozen, written to `out` (a branch and `resume` to set).
fn frozen_steps(set: &ObjectSet, dir: &Scratch, out: &std::path::Path) -> fusepose_train::seg::SegTrainConfig {
    fusepose_train::seg::SegTrainConfig {
        objects: std::sync::Arc::new(set.clone()),
        out: out.to_path_buf(),
        minutes: None,
        steps: Some(3),
        batch: 2,
        lr: 1e-2,
        weight_frames: 2,
        val_frames: 2,
        data_threads: 1,
        checkpoint_dir: dir.path().join("ck"),
        progress: false,
        freeze_trunk: true,
        ..Default::default()
    }
}

/// An RGB frame with depth in metres and no labels.
fn rgb_view<'a>(k: Intrinsics, color: &'a [u8], depth: &'a [f32]) -> FrameView<'a> {
    FrameView { intrinsics: k, color_format: ColorFormat::Rgb8, color, depth: DepthPlane::F32(depth), labels: None }
}

fn burn_logits(net: &SegNet, cfg: &SegConfig, input: &[f32]) -> Vec<f32> {
    let x = Tensor::<4>::from_data(
        TensorData::new(input.to_vec(), [1, 4, cfg.input_height, cfg.input_width]),
        &Device::flex(),
    );
    let y = net.forward(x);
    let (h1, w1) = cfg.output_size();
    assert_eq!(y.dims(), [1, cfg.outputs(), h1, w1]);
    y.into_data().try_to_vec::<f32>().unwrap()
}

fn random_input(cfg: &SegConfig, seed: u64) -> Vec<f32> {
    let mut rng = rand_pcg::Pcg64::seed_from_u64(seed);
    let plane = cfg.input_width * cfg.input_height;
    (0..4 * plane)
        .map(|i| if i >= 3 * plane { rng.random_range(0.0..2.0) } else { rng.random_range(-2.0..2.0) })
        .collect()
}

fn assert_close(engine: &[f32], burn: &[f32]) {
    assert_eq!(engine.len(), burn.len());
    let scale = burn.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1e-6);
    let err = engine.iter().zip(burn).fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    eprintln!("logits: max abs diff {err:.3e}, scale {scale:.3e}");
    assert!(err <= 1e-4 * scale, "max |diff| {err} vs scale {scale}");
    assert!(scale > 1e-3, "logits are all ~0: the test would prove nothing");
}

#[test]
fn engine_logits_match_burn_forward() {
    let set = three_objects();
    let dir = Scratch::new("logits");
    let mut odd = SegConfig::new(3);
    (odd.input_width, odd.input_height) = (150, 110);
    odd.enc = [8, 16, 24, 40];
    odd.dec = [24, 12, 8];
    for (i, cfg) in [SegConfig::new(3), odd].into_iter().enumerate() {
        let path = dir.path().join(format!("seg{i}.safetensors"));
        let net = save_random(&cfg, &set, &path);
        let mut engine = SegEngine::load(&path, &set).unwrap();
        assert_eq!(engine.config(), &cfg);
        for seed in [1u64, 2] {
            let input = random_input(&cfg, seed + 10 * i as u64);
            let expect = burn_logits(&net, &cfg, &input);
            let got = engine.forward(&input).unwrap().to_vec();
            assert_close(&got, &expect);
        }
        let wrong = vec![0.0; 7];
        assert!(engine.forward(&wrong).is_err());
    }
}

#[test]
fn engine_offsets_match_burn_forward_and_old_files_have_none() {
    let set = three_objects();
    let dir = Scratch::new("offsets");
    let cfg = SegConfig::new(3);
    assert!(cfg.offsets);
    let path = dir.path().join("seg.safetensors");
    // The head starts at zero in training; give it random weights so the comparison means something.
    let mut net = SegNet::new(&cfg, &Device::flex());
    net.offset = Some(burn::nn::conv::Conv2dConfig::new([cfg.dec[2], 2], [1, 1]).init(&Device::flex()));
    store::save(&net, &cfg, &object_entries(&set), &TrainRecord::default(), &serde_json::json!({}), &path).unwrap();
    let mut engine = SegEngine::load(&path, &set).unwrap();
    assert!(!engine.separates_instances(), "the head is ignored unless voting is asked for");
    engine.set_voting_mode(fusepose_estimator::seg::VotingMode::On(Default::default()));
    assert!(engine.separates_instances());
    let input = random_input(&cfg, 5);
    engine.forward(&input).unwrap();
    let x = Tensor::<4>::from_data(TensorData::new(input, [1, 4, cfg.input_height, cfg.input_width]), &Device::flex());
    let (_, offsets) = net.forward_all(x);
    let expect = offsets.expect("offset head").into_data().try_to_vec::<f32>().unwrap();
    assert_close(engine.offsets(), &expect);
    // `VotingMode::Off` ignores the head: class regions, as for a file without it.
    let (w, h) = (Intrinsics::YCB_VIDEO.width as usize, Intrinsics::YCB_VIDEO.height as usize);
    let (color, depth) = (vec![90u8; w * h * 3], vec![0.6f32; w * h]);
    let frame = FrameView {
        intrinsics: Intrinsics::YCB_VIDEO,
        color_format: ColorFormat::Rgb8,
        color: &color,
        depth: DepthPlane::F32(&depth),
        labels: None,
    };
    let mut buf = Vec::new();
    let instances =
        |p: &fusepose_estimator::LabelPlane<'_>| matches!(p, fusepose_estimator::LabelPlane::Instances { .. });
    assert!(instances(&engine.segment_plane(&frame, &mut buf).unwrap()));
    engine.set_voting_mode(fusepose_estimator::seg::VotingMode::Off);
    assert!(!engine.separates_instances());
    assert!(!instances(&engine.segment_plane(&frame, &mut buf).unwrap()), "Off gives a class plane");
    engine.set_voting_mode(fusepose_estimator::seg::VotingMode::On(Default::default()));
    assert!(engine.separates_instances());
    // A file written without the head (as before it existed) loads without offsets.
    let old = SegConfig { offsets: false, ..SegConfig::new(3) };
    let old_path = dir.path().join("old.safetensors");
    save_random(&old, &set, &old_path);
    let engine = SegEngine::load(&old_path, &set).unwrap();
    assert!(!engine.separates_instances() && engine.offsets().is_empty());
    // Resuming it for training adds a head the engine then reads.
    let loaded = store::load(&old_path, &Device::flex()).unwrap();
    assert!(loaded.net.offset.is_none());
    let with = loaded.net.with_offset_head(&cfg, &Device::flex());
    let new_path = dir.path().join("new.safetensors");
    store::save(&with, &cfg, &object_entries(&set), &TrainRecord::default(), &serde_json::json!({}), &new_path)
        .unwrap();
    let mut engine = SegEngine::load(&new_path, &set).unwrap();
    engine.set_voting_mode(fusepose_estimator::seg::VotingMode::On(Default::default()));
    assert!(engine.separates_instances(), "the added head is read");
    assert_eq!(engine.offsets().len(), 2 * cfg.output_size().0 * cfg.output_size().1);
}

#[test]
fn segment_labels_are_argmax_of_burn_logits() {
    let set = three_objects();
    let cfg = SegConfig::new(3);
    let dir = Scratch::new("argmax");
    let path = dir.path().join("seg.safetensors");
    let net = save_random(&cfg, &set, &path);
    let mut engine = SegEngine::load(&path, &set).unwrap();
    // Plain argmax: no fragment, strip or interior-less region removal (tested in the engine's unit tests).
    engine.set_min_component_cells(0);
    engine.set_max_elongation(0.0);
    engine.set_min_interior_cells(0);
    engine.set_boundary(fusepose_estimator::seg::Boundary::Cells);
    // A 640x480 frame with smooth structure so the logits vary across cells.
    let (w, h) = (640usize, 480usize);
    let color: Vec<u8> =
        (0..w * h).flat_map(|p| [(p % w / 3) as u8, (p / w / 2) as u8, ((p % w + p / w) / 5) as u8]).collect();
    let depth: Vec<f32> = (0..w * h).map(|p| if p % 97 == 0 { 0.0 } else { 0.5 + (p % w) as f32 / 640.0 }).collect();
    let k = Intrinsics::YCB_VIDEO;
    let frame = rgb_view(k, &color, &depth);
    let mut labels = vec![u16::MAX; w * h];
    engine.segment(&frame, &mut labels).unwrap();
    // The engine's input is what the trainer feeds burn; its argmax is the labels.
    let map = fusepose_estimator::seg::FrameMap::new(w, h, &cfg);
    let mut input = vec![0.0; map.input_len()];
    map.fill_input(&frame, &mut input);
    let logits = burn_logits(&net, &cfg, &input);
    let cells = map.cells();
    let mut checked = 0;
    for (i, &got) in engine.cell_labels().iter().enumerate() {
        let mut v: Vec<(f32, usize)> = (0..cfg.outputs()).map(|c| (logits[c * cells + i], c)).collect();
        v.sort_by(|a, b| b.0.total_cmp(&a.0));
        if v[0].0 - v[1].0 > 1e-3 {
            assert_eq!(got as usize, v[0].1, "cell {i}");
            checked += 1;
        }
    }
    assert!(checked > cells / 2, "only {checked} of {cells} cells had a clear argmax");
    // Every frame pixel carries its cell's label (8x8 blocks at 640x480 → 80x60 cells).
    let (_, w1) = cfg.output_size();
    for (p, &l) in labels.iter().enumerate() {
        let (u, v) = (p % w, p / w);
        assert_eq!(l, engine.cell_labels()[(v / 8) * w1 + u / 8]);
    }
    // Wrong output length and an invalid frame are errors, not panics.
    assert!(engine.segment(&frame, &mut labels[..10]).is_err());
    let bad = FrameView { color: &color[..30], ..frame };
    assert!(engine.segment(&bad, &mut labels).is_err());
}

#[test]
fn load_refuses_files_that_do_not_fit() {
    let set = three_objects();
    let cfg = SegConfig::new(3);
    let dir = Scratch::new("refuse");
    let path = dir.path().join("seg.safetensors");
    save_random(&cfg, &set, &path);
    // Different order of the same objects.
    let mut swapped = three_objects();
    swapped.objects.swap(0, 1);
    assert!(matches!(
        SegEngine::load(&path, &swapped),
        Err(NetLoadError::ObjectMismatch { class: 1, what: "name", .. })
    ));
    // Fewer objects.
    let two = ObjectSet { objects: set.objects[..2].to_vec() };
    assert!(matches!(SegEngine::load(&path, &two), Err(NetLoadError::ObjectCount { file: 3, set: 2 })));
    // Truncated file.
    let bytes = std::fs::read(&path).unwrap();
    assert!(matches!(SegFile::from_bytes(&bytes[..bytes.len() / 2]), Err(NetLoadError::Format(_))));
    // Missing file.
    assert!(matches!(SegEngine::load(&dir.path().join("nope.safetensors"), &set), Err(NetLoadError::Io { .. })));
}

/// A short smoke training run (not part of the normal suite):
/// `FUSEPOSE_SEG_MINUTES=2.5 nice -n 10 cargo test -p fusepose-train --test seg_parity -- --ignored --nocapture`
/// Writes `/work/scratch/seg/smoke.safetensors` (or `$FUSEPOSE_SEG_OUT`; resumes from
/// `$FUSEPOSE_SEG_RESUME` when set) and
/// checks that the loss fell and the held-out mIoU is above zero.
#[test]
#[ignore]
fn smoke_training() {
    use fusepose_train::seg::{SegTrainConfig, train_segmenter};
    let env = |k: &str| std::env::var(k).ok();
    let out = std::path::PathBuf::from(env("FUSEPOSE_SEG_OUT").unwrap_or("/work/scratch/seg/smoke.safetensors".into()));
    let dir = out.parent().unwrap().to_path_buf();
    let minutes: f64 = env("FUSEPOSE_SEG_MINUTES").and_then(|m| m.parse().ok()).unwrap_or(2.5);
    let cfg = SegTrainConfig {
        out: out.clone(),
        minutes: Some(minutes),
        resume: env("FUSEPOSE_SEG_RESUME").map(std::path::PathBuf::from),
        checkpoint_dir: dir.join("ckpt"),
        log: Some(dir.join("smoke.log")),
        weight_frames: 16,
        val_frames: 16,
        progress: false,
        ..SegTrainConfig::default()
    };
    let r = train_segmenter(cfg).unwrap();
    println!(
        "steps {} frames {} | loss first10 {:.4} last10 {:.4} | {:.0} ms/step",
        r.record.steps, r.record.samples, r.first_loss, r.last_loss, r.step_ms
    );
    println!("class weights {:?}", r.class_weights);
    println!("curve {:?}", r.loss_curve);
    println!("{}", r.validation.summary());
    assert!(r.last_loss < r.first_loss, "loss did not fall");
    assert!(r.validation.miou > 0.0);
    assert!(SegEngine::load(&out, &fusepose_scene::builtin::builtin_objects()).is_ok());
}

fn save_random_pose_net(set: &ObjectSet, path: &std::path::Path) {
    let cfg = fusepose_estimator::net::NetConfig::new(set.len());
    let net = fusepose_train::model::FusionNet::new(&cfg, &Device::flex());
    fusepose_train::store::save(&net, &cfg, &object_entries(set), &TrainRecord::default(), path).unwrap();
}

#[test]
fn segmenter_embeds_into_the_pose_network_file() {
    use fusepose_estimator::net::WeightFile;
    use fusepose_estimator::seg::file::embed;
    let set = three_objects();
    let cfg = SegConfig::new(3);
    let dir = Scratch::new("embed");
    let (pose, seg) = (dir.path().join("pose.safetensors"), dir.path().join("seg.safetensors"));
    save_random_pose_net(&set, &pose);
    save_random(&cfg, &set, &seg);
    // A pose-network file without a segmenter says so.
    assert!(matches!(SegFile::read(&pose), Err(NetLoadError::NoSegmenter)));

    let seg_file = SegFile::read(&seg).unwrap();
    let pose_bytes = std::fs::read(&pose).unwrap();
    let both = embed(&pose_bytes, &seg_file).unwrap();
    // Embedding again replaces, it does not duplicate.
    let again = embed(&both, &seg_file).unwrap();
    assert_eq!(again.len(), both.len());
    let combined = dir.path().join("both.safetensors");
    std::fs::write(&combined, &both).unwrap();

    // The pose network is untouched, the segmenter reads back identically.
    let (before, after) = (WeightFile::from_bytes(&pose_bytes).unwrap(), WeightFile::read(&combined).unwrap());
    for (name, _) in before.config.tensor_shapes() {
        assert_eq!(before.tensor(&name).unwrap(), after.tensor(&name).unwrap(), "{name}");
    }
    let embedded = SegFile::read(&combined).unwrap();
    assert_eq!(embedded.config, seg_file.config);
    assert_eq!(embedded.objects, seg_file.objects);
    for (name, _) in cfg.tensor_shapes() {
        assert_eq!(embedded.tensor(&name).unwrap(), seg_file.tensor(&name).unwrap(), "{name}");
    }
    let input = random_input(&cfg, 5);
    let mut a = SegEngine::load(&seg, &set).unwrap();
    let mut b = SegEngine::load(&combined, &set).unwrap();
    assert_eq!(a.forward(&input).unwrap(), b.forward(&input).unwrap());
    // The trainer resumes from the embedded segmenter: same logits as the segmenter-only file.
    let resumed = store::load(&combined, &Device::flex()).unwrap();
    assert_eq!(resumed.file.config, cfg);
    assert_close(a.forward(&input).unwrap(), &burn_logits(&resumed.net, &cfg, &input));

    // A pose network for other objects (same count, other order) refuses the segmenter.
    let mut swapped = three_objects();
    swapped.objects.swap(1, 2);
    let other = dir.path().join("other.safetensors");
    save_random_pose_net(&swapped, &other);
    let err = embed(&std::fs::read(&other).unwrap(), &seg_file).unwrap_err();
    assert!(matches!(err, NetLoadError::ObjectMismatch { class: 2, what: "name", .. }), "{err}");
}

/// The offset branch (`o1` over d1's input, then the 1x1 offset head): the
/// engine's offsets (computed on demand) and logits match burn's; a branch added to a trained file
/// starts as a copy of `d1`; and training with the trunk frozen changes only
/// the branch and the head, so every class output stays bit for bit.
#[test]
fn offset_branch_matches_burn_and_frozen_training_keeps_the_trunk() {
    use fusepose_train::seg::{SegTrainConfig, train_segmenter};
    let set = three_objects();
    let dir = Scratch::new("branch");
    let cfg = SegConfig { offset_branch: true, ..SegConfig::new(3) };
    let path = dir.path().join("branch.safetensors");
    let mut net = SegNet::new(&cfg, &Device::flex());
    assert!(net.o1.is_some());
    net.offset = Some(burn::nn::conv::Conv2dConfig::new([cfg.dec[2], 2], [1, 1]).init(&Device::flex()));
    store::save(&net, &cfg, &object_entries(&set), &TrainRecord::default(), &serde_json::json!({}), &path).unwrap();
    let mut engine = SegEngine::load(&path, &set).unwrap();
    let input = random_input(&cfg, 11);
    let logits = engine.forward(&input).unwrap().to_vec();
    let x = Tensor::<4>::from_data(TensorData::new(input, [1, 4, cfg.input_height, cfg.input_width]), &Device::flex());
    let (burn_logits, offsets) = net.forward_all(x);
    assert_close(&logits, &burn_logits.into_data().try_to_vec::<f32>().unwrap());
    // The branch runs on demand (voting is off): no offsets until asked for.
    assert!(engine.offsets().is_empty() && engine.config().offsets);
    engine.compute_votes();
    assert_close(engine.offsets(), &offsets.unwrap().into_data().try_to_vec::<f32>().unwrap());

    // A trained file without offsets: the branch starts as d1 and the head at zero.
    let (plain, plain_path, loaded) = plain_segmenter(&set, &dir);
    let d1 = loaded.d1.weight.val().into_data().try_to_vec::<f32>().unwrap();
    let with = loaded.with_offset_branch(&cfg, &Device::flex());
    let o1 = with.o1.as_ref().unwrap().weight.val().into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(d1, o1, "the branch starts as a copy of d1");

    // Frozen training from the plain file: three steps on the offset loss alone.
    let out = dir.path().join("frozen.safetensors");
    let train = |resume: Option<std::path::PathBuf>| {
        train_segmenter(SegTrainConfig { resume, offset_branch: true, ..frozen_steps(&set, &dir, &out) })
    };
    let e = train(None).expect_err("freezing a fresh network is refused").to_string();
    assert!(e.contains("--resume"), "{e}");
    let report = train(Some(plain_path.clone())).unwrap();
    assert!(report.config.offsets && report.config.offset_branch);
    let (before, after) = (SegFile::read(&plain_path).unwrap(), SegFile::read(&out).unwrap());
    for (name, _) in plain.tensor_shapes() {
        assert_eq!(before.tensor(&name).unwrap(), after.tensor(&name).unwrap(), "{name} changed");
    }
    let head = after.tensor("offset.weight").unwrap();
    assert!(head.iter().any(|&w| w != 0.0), "the offset head learned nothing");
    let branch = after.tensor("o1.weight").unwrap();
    assert_ne!(branch, before.tensor("d1.weight").unwrap(), "the branch learned nothing");
}

/// The contact branch (`b1` over d1's input, then the 1x1 contact head): the
/// engine's contact logits (computed on demand) match burn's, and its
/// probability at a pixel is the sigmoid of its cell's logit; a branch added
/// to a trained file starts as a copy of `d1` with the head sure of no
/// contact; training it with the trunk frozen changes only the branch and
/// the head.
#[test]
fn contact_branch_matches_burn_and_frozen_training_keeps_the_trunk() {
    use fusepose_train::seg::{SegTrainConfig, train_segmenter};
    let set = three_objects();
    let dir = Scratch::new("contacts");
    let cfg = SegConfig { offsets: false, contacts: true, ..SegConfig::new(3) };
    let path = dir.path().join("contacts.safetensors");
    let mut net = SegNet::new(&cfg, &Device::flex());
    net.contact = Some(burn::nn::conv::Conv2dConfig::new([cfg.dec[2], 1], [1, 1]).init(&Device::flex()));
    store::save(&net, &cfg, &object_entries(&set), &TrainRecord::default(), &serde_json::json!({}), &path).unwrap();
    let mut engine = SegEngine::load(&path, &set).unwrap();
    assert!(engine.has_contacts());
    let input = random_input(&cfg, 12);
    let logits = engine.forward(&input).unwrap().to_vec();
    let x = Tensor::<4>::from_data(TensorData::new(input, [1, 4, cfg.input_height, cfg.input_width]), &Device::flex());
    let out = net.forward_outputs(x);
    assert_close(&logits, &out.logits.into_data().try_to_vec::<f32>().unwrap());
    assert!(engine.contacts().is_empty(), "computed on demand only");
    engine.compute_contacts();
    assert_close(engine.contacts(), &out.contacts.unwrap().into_data().try_to_vec::<f32>().unwrap());

    // Through a segmentation: each pixel reads its cell's probability.
    let k = Intrinsics { fx: 300.0, fy: 300.0, cx: 159.5, cy: 119.5, width: 320, height: 240 };
    let color: Vec<u8> = (0..320 * 240 * 3).map(|i| (i * 31 % 251) as u8).collect();
    let depth = vec![0.6f32; 320 * 240];
    let frame = rgb_view(k, &color, &depth);
    let mut labels = vec![0u16; 320 * 240];
    engine.segment(&frame, &mut labels).unwrap();
    assert_eq!(engine.contact_at(100, 50), None, "not yet computed for this frame");
    engine.compute_contacts();
    let (_, w1) = cfg.output_size();
    // 320x240 onto the 80x60 grid: 4 pixels per cell.
    let logit = engine.contacts()[(50 / 4) * w1 + 100 / 4];
    let p = engine.contact_at(100, 50).unwrap();
    assert!((p - 1.0 / (1.0 + (-logit).exp())).abs() < 1e-6, "{p} vs logit {logit}");
    assert_eq!(engine.contact_at(320, 0), None, "off the frame");

    // A trained file without the branch: b1 starts as d1, the head at 5 %.
    let (plain, plain_path, loaded) = plain_segmenter(&set, &dir);
    let d1 = loaded.d1.weight.val().into_data().try_to_vec::<f32>().unwrap();
    let with = loaded.with_contact_branch(&cfg, &Device::flex());
    let b1 = with.b1.as_ref().unwrap().weight.val().into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(d1, b1, "the branch starts as a copy of d1");
    let bias = with.contact.as_ref().unwrap().bias.as_ref().unwrap().val().into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(bias, vec![-3.0]);

    // Frozen training from the plain file: three steps on the contact loss alone.
    let out = dir.path().join("frozen.safetensors");
    let report = train_segmenter(SegTrainConfig {
        resume: Some(plain_path.clone()),
        offsets: false,
        contacts: true,
        sampler: fusepose_scene::sampler::SamplerConfig { pair_probability: 1.0, ..Default::default() },
        ..frozen_steps(&set, &dir, &out)
    })
    .unwrap();
    assert!(report.config.contacts && !report.config.offsets);
    let (before, after) = (SegFile::read(&plain_path).unwrap(), SegFile::read(&out).unwrap());
    for (name, _) in plain.tensor_shapes() {
        assert_eq!(before.tensor(&name).unwrap(), after.tensor(&name).unwrap(), "{name} changed");
    }
    assert!(after.tensor("contact.weight").unwrap().iter().any(|&w| w != 0.0), "the contact head learned nothing");
    assert_ne!(after.tensor("b1.weight").unwrap(), before.tensor("d1.weight").unwrap(), "the branch learned nothing");
}
