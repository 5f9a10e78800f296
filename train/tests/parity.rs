//! Parity: the inference engine (`fusepose_estimator::net`) and the burn
//! forward pass give the same outputs for the same weights and inputs —
//! colour embedding, per-point quaternion / translation / confidence, and two
//! refiner iterations — within 1e-4 of each tensor's largest magnitude.

use burn::prelude::{Device, Int, Tensor, TensorData};
use fusepose_estimator::net::meta::{ObjectEntry, TrainRecord};
use fusepose_estimator::net::{Engine, NetConfig, Scratch, WeightFile};
use fusepose_train::geometry::quat_to_rot;
use fusepose_train::model::FusionNet;
use nalgebra::{Matrix3, Vector3};
use ndarray::{Array1, Array2};
use rand::{Rng, SeedableRng};

fn close(name: &str, engine: &[f32], burn: &[f32]) {
    assert_eq!(engine.len(), burn.len(), "{name}: lengths");
    let scale = burn.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1e-6);
    let err = engine.iter().zip(burn).fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(err <= 1e-4 * scale, "{name}: max |diff| {err} vs scale {scale}");
}

fn entries(k: usize) -> Vec<ObjectEntry> {
    (0..k)
        .map(|i| ObjectEntry {
            name: format!("o{i}"),
            symmetry: "none".into(),
            diameter: 0.1,
            hash: "0".into(),
            symmetries: None,
        })
        .collect()
}

#[test]
fn engine_matches_burn_forward_for_pose_net_and_refiner() {
    let device = Device::flex();
    let mut cfg = NetConfig::new(3);
    cfg.num_points = 96;
    let (n, s, class) = (cfg.num_points, cfg.crop_size, 2usize);
    let net = FusionNet::new(&cfg, &device);
    let mut rng = rand_pcg::Pcg64::seed_from_u64(7);
    let crop: Vec<f32> = (0..3 * s * s).map(|_| rng.random_range(-2.0..2.0)).collect();
    let points: Vec<f32> = (0..n)
        .flat_map(|_| {
            [
                0.05 + rng.random_range(-0.05..0.05),
                -0.02 + rng.random_range(-0.05..0.05),
                0.7 + rng.random_range(-0.05..0.05),
            ]
        })
        .collect();
    let choose: Vec<u32> = (0..n).map(|_| rng.random_range(0..(s * s) as u32)).collect();
    let half: Vec<i64> =
        choose.iter().map(|&p| ((p as usize / s / 2) * (s / 2) + (p as usize % s) / 2) as i64).collect();

    // burn
    let crop_t = Tensor::<4>::from_data(TensorData::new(crop.clone(), [1, 3, s, s]), &device);
    let pts_t = Tensor::<3>::from_data(TensorData::new(points.clone(), [1, n, 3]), &device);
    let ch_t = Tensor::<2, Int>::from_data(
        TensorData::new(choose.iter().map(|&c| c as i64).collect::<Vec<_>>(), [1, n]),
        &device,
    );
    let half_t = Tensor::<2, Int>::from_data(TensorData::new(half, [1, n]), &device);
    let emb = net.cnn.forward(crop_t, ch_t, half_t);
    let out = net.pose.forward(&cfg, pts_t.clone(), emb.clone(), &[class]);
    let b_emb = emb.clone().into_data().try_to_vec::<f32>().unwrap();
    let b_quat = out.quat.clone().into_data().try_to_vec::<f32>().unwrap();
    let b_trans = out.trans.clone().into_data().try_to_vec::<f32>().unwrap();
    let b_conf = out.conf.clone().into_data().try_to_vec::<f32>().unwrap();

    // The refiner starts from point 0's prediction in both.
    let q0 = out.quat.clone().narrow(1, 0, 1).reshape([1, 4]);
    let mut rot = quat_to_rot(q0);
    let mut trans = out.trans.clone().narrow(1, 0, 1).reshape([1, 3]);
    let start_r = rot.clone().into_data().try_to_vec::<f32>().unwrap();
    let start_t = trans.clone().into_data().try_to_vec::<f32>().unwrap();
    let color = net.refine.color(emb);
    let mut b_refined = Vec::new();
    for _ in 0..2 {
        (rot, trans) = net.refine.step(&cfg, pts_t.clone(), &color, rot, trans, &[class]);
        b_refined.push((
            rot.clone().into_data().try_to_vec::<f32>().unwrap(),
            trans.clone().into_data().try_to_vec::<f32>().unwrap(),
        ));
    }

    // engine, through a real weight file
    let dir = std::env::temp_dir().join(format!("fusepose-parity-{}", std::process::id()));
    let path = dir.join("net.safetensors");
    fusepose_train::store::save(&net, &cfg, &entries(3), &TrainRecord::default(), &path).unwrap();
    let file = WeightFile::read(&path).unwrap();
    let engine = Engine::new(&file).unwrap();
    let mut sc = Scratch::new(&cfg, n, s);
    let pts_a = Array2::from_shape_vec((n, 3), points).unwrap();
    let ch_a = Array1::from_vec(choose);
    engine.set_inputs(&mut sc, crop.iter(), pts_a.view(), ch_a.view());
    engine.color(&mut sc);
    close("embedding", sc.emb.as_slice().unwrap(), &b_emb);
    engine.pose(&mut sc, class);
    close("quaternion", sc.quat.as_slice().unwrap(), &b_quat);
    close("translation", sc.trans.as_slice().unwrap(), &b_trans);
    close("confidence", sc.conf.as_slice().unwrap(), &b_conf);

    engine.refine_color(&mut sc);
    let mut r = Matrix3::from_row_slice(&start_r);
    let mut t = Vector3::from_row_slice(&start_t);
    for (i, (br, bt)) in b_refined.iter().enumerate() {
        (r, t) = engine.refine(&mut sc, class, &r, &t);
        let rows: Vec<f32> = (0..9).map(|j| r[(j / 3, j % 3)]).collect();
        close(&format!("refined rotation {i}"), &rows, br);
        close(&format!("refined translation {i}"), t.as_slice(), bt);
    }
    let _ = std::fs::remove_dir_all(dir);
}
