//! Training mechanics on the real data path: samples rendered by the scene
//! crate and prepared by the estimator's workspace; a few Adam steps on one
//! batch lower the DenseFusion and refiner losses (gradients reach the
//! weights); a saved file loads back into an identical network (what
//! `--resume` relies on, for checkpoints and shipped files alike).

use std::sync::Arc;

use burn::optim::{AdamConfig, GradientsParams};
use burn::prelude::{Device, Int, Tensor, TensorData};
use fusepose_estimator::net::NetConfig;
use fusepose_estimator::net::meta::{TrainRecord, object_entries};
use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::RenderTarget;
use fusepose_scene::{Intrinsics, ObjectSet};
use fusepose_train::data::{DataConfig, Sample, frame_samples, workspace};
use fusepose_train::geometry::rot_rows;
use fusepose_train::loss::{GtInstance, model_tensor, pose_loss, refine_loss};
use fusepose_train::model::FusionNet;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

fn samples(set: &ObjectSet, cfg: &NetConfig, want: usize) -> Vec<Sample> {
    let dc = DataConfig { augment: true, ..DataConfig::unaugmented(cfg.num_points, cfg.crop_size) };
    let mut ws = workspace(set, &dc).unwrap();
    let mut target = RenderTarget::for_intrinsics(&Intrinsics::YCB_VIDEO);
    let mut out = Vec::new();
    let mut seed = 100;
    while out.len() < want {
        out.extend(frame_samples(set, &dc, seed, &mut ws, &mut target, None).unwrap());
        seed += 1;
    }
    out.truncate(want);
    out
}

struct Batch {
    crops: Tensor<4>,
    points: Tensor<3>,
    choose: Tensor<2, Int>,
    half: Tensor<2, Int>,
    classes: Vec<usize>,
    gts: Vec<GtInstance>,
    r0: Tensor<3>,
    t0: Tensor<2>,
}

fn batch(set: &ObjectSet, cfg: &NetConfig, xs: &[Sample], device: &Device) -> Batch {
    let (b, n, s) = (xs.len(), cfg.num_points, cfg.crop_size);
    let crops = Tensor::<4>::from_data(
        TensorData::new(xs.iter().flat_map(|x| x.crop.clone()).collect::<Vec<_>>(), [b, 3, s, s]),
        device,
    );
    let points = Tensor::<3>::from_data(
        TensorData::new(xs.iter().flat_map(|x| x.points.clone()).collect::<Vec<_>>(), [b, n, 3]),
        device,
    );
    let cv: Vec<i64> = xs.iter().flat_map(|x| x.choose.iter().map(|&c| c as i64)).collect();
    let hv: Vec<i64> = cv.iter().map(|&c| ((c as usize / s / 2) * (s / 2) + (c as usize % s) / 2) as i64).collect();
    let gts: Vec<GtInstance> = xs
        .iter()
        .map(|x| {
            let m = &set.objects[x.class];
            let pts = m
                .samples
                .iter()
                .step_by((m.samples.len() / 200).max(1))
                .map(|p| [p.x as f32, p.y as f32, p.z as f32])
                .collect();
            GtInstance::new(x.pose, pts, &m.symmetry)
        })
        .collect();
    // Refiner start: ground truth turned 15° and moved 2 cm.
    let starts: Vec<Isometry3<f64>> = xs
        .iter()
        .map(|x| {
            Isometry3::from_parts(
                Translation3::from(x.pose.translation.vector + Vector3::new(0.02, 0.0, 0.0)),
                UnitQuaternion::from_scaled_axis(Vector3::new(0.0, 15f64.to_radians(), 0.0)) * x.pose.rotation,
            )
        })
        .collect();
    let r0 = Tensor::<3>::from_data(
        TensorData::new(starts.iter().flat_map(rot_rows).collect::<Vec<_>>(), [b, 3, 3]),
        device,
    );
    let t0 = Tensor::<2>::from_data(
        TensorData::new(
            starts
                .iter()
                .flat_map(|p| p.translation.vector.iter().map(|&v| v as f32).collect::<Vec<_>>())
                .collect::<Vec<_>>(),
            [b, 3],
        ),
        device,
    );
    Batch {
        crops,
        points,
        choose: Tensor::from_data(TensorData::new(cv, [b, n]), device),
        half: Tensor::from_data(TensorData::new(hv, [b, n]), device),
        classes: xs.iter().map(|x| x.class).collect(),
        gts,
        r0,
        t0,
    }
}

fn scalar(t: Tensor<1>) -> f32 {
    t.into_data().try_to_vec::<f32>().unwrap()[0]
}

#[test]
fn adam_steps_on_one_batch_lower_pose_and_refiner_losses() {
    let set = Arc::new(builtin_objects());
    let mut cfg = NetConfig::new(set.len());
    cfg.num_points = 128;
    let device = Device::flex().autodiff();
    device.seed(5);
    let xs = samples(&set, &cfg, 4);
    let bt = batch(&set, &cfg, &xs, &device);
    let mut net = FusionNet::new(&cfg, &device);
    let mut optim = AdamConfig::new().init();
    let mut first = None;
    let mut last = (0.0, 0.0);
    for _ in 0..25 {
        let model = model_tensor(&bt.gts, &device);
        let emb = net.cnn.forward(bt.crops.clone(), bt.choose.clone(), bt.half.clone());
        let out = net.pose.forward(&cfg, bt.points.clone(), emb.clone(), &bt.classes);
        let (lp, _) = pose_loss(&out, model.clone(), &bt.gts, 0.015);
        let color = net.refine.color(emb);
        let (r1, t1) = net.refine.step(&cfg, bt.points.clone(), &color, bt.r0.clone(), bt.t0.clone(), &bt.classes);
        let lr = refine_loss(r1, t1, model, &bt.gts);
        last = (scalar(lp.clone()), scalar(lr.clone()));
        first.get_or_insert(last);
        let grads = GradientsParams::from_grads((lp + lr).backward(), &net);
        net = optim.step(1e-3, net, grads);
    }
    let first = first.unwrap();
    assert!(last.0 < 0.8 * first.0, "pose loss {} -> {}", first.0, last.0);
    assert!(last.1 < 0.8 * first.1, "refiner loss {} -> {}", first.1, last.1);
}

#[test]
fn saved_weights_load_back_identically() {
    let set = builtin_objects();
    let cfg = NetConfig::new(set.len());
    let device = Device::flex();
    let net = FusionNet::new(&cfg, &device);
    let dir = std::env::temp_dir().join(format!("fusepose-train-rt-{}", std::process::id()));
    let path = dir.join("w.safetensors");
    let record = TrainRecord { seed: 9, steps: 123, samples: 984, ..TrainRecord::default() };
    fusepose_train::store::save(&net, &cfg, &object_entries(&set), &record, &path).unwrap();
    let loaded = fusepose_train::store::load(&path, &device).unwrap();
    assert_eq!(loaded.file.config, cfg);
    assert_eq!(loaded.file.train.as_ref().map(|r| r.steps), Some(123));
    let a = net.pose.l2.weight.val().into_data().try_to_vec::<f32>().unwrap();
    let b = loaded.net.pose.l2.weight.val().into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(a, b);
    let a = net.cnn.d1.weight.val().into_data().try_to_vec::<f32>().unwrap();
    let b = loaded.net.cnn.d1.weight.val().into_data().try_to_vec::<f32>().unwrap();
    assert_eq!(a, b);
    let _ = std::fs::remove_dir_all(dir);
}
