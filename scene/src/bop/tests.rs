//! Round-trip and error tests on small datasets written by the tests.

use std::path::PathBuf;

use nalgebra::{Isometry3, Point3, Translation3, UnitQuaternion, Vector3};

use super::*;
use crate::{Intrinsics, Mesh, ObjectModel, ObjectSet, Pose, Symmetry};

pub(crate) struct TempDir(pub PathBuf);

impl TempDir {
    pub(crate) fn new(tag: &str) -> TempDir {
        use std::sync::atomic::{AtomicUsize, Ordering};
        static N: AtomicUsize = AtomicUsize::new(0);
        let p = std::env::temp_dir().join(format!(
            "fusepose-{tag}-{}-{}",
            std::process::id(),
            N.fetch_add(1, Ordering::Relaxed)
        ));
        let _ = std::fs::remove_dir_all(&p);
        std::fs::create_dir_all(&p).unwrap();
        TempDir(p)
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// A box object of the given half sizes (metres): 8 vertices, no triangles
/// needed for the writer (it projects vertices only).
fn box_model(name: &str, half: [f64; 3], symmetry: Symmetry) -> ObjectModel {
    let mut positions = Vec::new();
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                positions.push([(sx * half[0]) as f32, (sy * half[1]) as f32, (sz * half[2]) as f32]);
            }
        }
    }
    let d = 2.0 * (half[0] * half[0] + half[1] * half[1] + half[2] * half[2]).sqrt();
    ObjectModel {
        name: name.to_string(),
        mesh: Mesh { positions, ..Default::default() },
        symmetry,
        samples: vec![Point3::origin()],
        diameter: d,
        bbox_min: Point3::new(-half[0], -half[1], -half[2]),
        bbox_max: Point3::new(half[0], half[1], half[2]),
        shadow_mesh: None,
    }
}

fn objects() -> ObjectSet {
    let flip = Isometry3::from_parts(
        Translation3::new(0.0, 0.0, 0.002),
        UnitQuaternion::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI),
    );
    ObjectSet {
        objects: vec![
            box_model("crate", [0.05, 0.03, 0.02], Symmetry::None),
            box_model(
                "can",
                [0.03, 0.03, 0.06],
                Symmetry::Continuous { axis: Vector3::new(0.0, 0.0, 2.0), origin: Point3::new(0.001, 0.0, 0.0) },
            ),
            box_model("plate", [0.04, 0.04, 0.01], Symmetry::Discrete(vec![flip])),
        ],
    }
}

const K: Intrinsics = Intrinsics { fx: 100.0, fy: 110.0, cx: 15.5, cy: 11.5, width: 32, height: 24 };

struct Fake {
    rgb: Vec<u8>,
    depth: Vec<u16>,
    labels: Vec<u16>,
    instances: Vec<InstanceToWrite>,
}

/// A frame with instance 7 (obj 1) filling columns 2..=5, rows 3..=4 and
/// instance 9 (obj 3) filling columns 10..=12 of row 20; instance 9's
/// depth is missing on one pixel.
fn fake(seed: u8) -> Fake {
    let (w, h) = (K.width as usize, K.height as usize);
    let rgb = (0..w * h * 3).map(|i| (i as u8).wrapping_mul(7).wrapping_add(seed)).collect();
    let mut depth: Vec<u16> = (0..w * h).map(|i| 5000 + i as u16 + seed as u16).collect();
    let mut labels = vec![0u16; w * h];
    for v in 3..=4 {
        for u in 2..=5 {
            labels[v * w + u] = 7;
        }
    }
    for u in 10..=12 {
        labels[20 * w + u] = 9;
    }
    depth[20 * w + 11] = 0;
    let pose_a = Pose::from_parts(
        Translation3::new(0.01, -0.02, 0.5 + seed as f64 * 0.01),
        UnitQuaternion::from_euler_angles(0.1, 0.2 + seed as f64 * 0.1, -0.3),
    );
    let pose_b =
        Pose::from_parts(Translation3::new(-0.05, 0.04, 0.7), UnitQuaternion::from_euler_angles(1.0, 0.0, 2.0));
    let instances = vec![
        InstanceToWrite { obj_id: 1, pose: pose_a, instance_label: 7, px_count_all: Some(16) },
        InstanceToWrite { obj_id: 3, pose: pose_b, instance_label: 9, px_count_all: None },
    ];
    Fake { rgb, depth, labels, instances }
}

fn frame<'a>(f: &'a Fake, scene_id: u32, im_id: u32) -> FrameToWrite<'a> {
    FrameToWrite {
        scene_id,
        im_id,
        intrinsics: K,
        rgb: &f.rgb,
        depth: &f.depth,
        depth_unit_m: 1e-4,
        instance_labels: &f.labels,
        instances: &f.instances,
    }
}

fn write_dataset(root: &std::path::Path) -> Vec<(u32, u32, Fake)> {
    let set = objects();
    let mut w = BopWriter::create(root, "test", &set, &ObjectSource::Builtin).unwrap();
    let mut written = Vec::new();
    for (scene, im, seed) in [(0, 0, 1), (0, 1, 2), (3, 0, 3), (3, 5, 4)] {
        let f = fake(seed);
        w.write_frame(&frame(&f, scene, im)).unwrap();
        written.push((scene, im, f));
    }
    w.set_split_params(serde_json::json!({"seed": 5})).unwrap();
    assert_eq!(w.frames_written(), 4);
    written
}

#[test]
fn round_trip_preserves_images_poses_and_labels() {
    let dir = TempDir::new("bop-rt");
    let written = write_dataset(&dir.0);
    let ds = BopDataset::open_split(&dir.0, "test").unwrap();
    assert_eq!(ds.len(), 4);
    let ids: Vec<(u32, u32)> = ds.frame_ids().iter().map(|f| (f.scene_id, f.im_id)).collect();
    assert_eq!(ids, vec![(0, 0), (0, 1), (3, 0), (3, 5)]);
    for (i, frame) in ds.iter().enumerate() {
        let frame = frame.unwrap();
        let (_, _, f) = &written[i];
        assert_eq!(frame.intrinsics, K);
        assert_eq!(frame.rgb, f.rgb);
        assert_eq!(frame.depth, f.depth);
        assert!((frame.depth_unit_m - 1e-4).abs() < 1e-18);
        assert!((frame.depth_m(0, 0).unwrap() - f.depth[0] as f64 * 1e-4).abs() < 1e-12);
        assert_eq!(frame.depth_m(K.width, 0), None);
        assert!((frame.depth_metres()[0] as f64 - f.depth[0] as f64 * 1e-4).abs() < 1e-6);
        // Labels: instance 7 -> obj 1, instance 9 -> obj 3.
        let expected: Vec<u16> = f
            .labels
            .iter()
            .map(|&l| match l {
                7 => 1,
                9 => 3,
                _ => 0,
            })
            .collect();
        assert_eq!(frame.labels, expected);
        assert_eq!(frame.gt.len(), 2);
        for (g, inst) in frame.gt.iter().zip(&f.instances) {
            assert_eq!(g.obj_id, inst.obj_id);
            let d = g.pose.inverse() * inst.pose;
            assert!(d.translation.vector.norm() < 1e-12 && d.rotation.angle() < 1e-9);
        }
        // Instance 7: 8 visible pixels of 16 -> 0.5; bbox x 2, y 3, 4 x 2.
        assert_eq!(frame.gt[0].bbox_visib, [2, 3, 4, 2]);
        assert_eq!(frame.gt[0].px_count_visib, 8);
        assert!((frame.gt[0].visib_fract - 0.5).abs() < 1e-12);
        // Instance 9: all count unknown -> visible count -> 1.
        assert_eq!(frame.gt[1].bbox_visib, [10, 20, 3, 1]);
        assert!((frame.gt[1].visib_fract - 1.0).abs() < 1e-12);
    }
    let manifest = ds.manifest().unwrap();
    assert_eq!(manifest.objects, ObjectSource::Builtin);
    assert_eq!(manifest.name_of(3), Some("plate"));
    assert_eq!(manifest.splits["test"]["seed"], 5);
}

#[test]
fn scene_files_use_bop_units_and_names() {
    let dir = TempDir::new("bop-units");
    write_dataset(&dir.0);
    let scene = dir.0.join("test/000003");
    for f in ["rgb/000005.png", "depth/000005.png", "mask_visib/000005_000000.png", "mask_visib/000005_000001.png"] {
        assert!(scene.join(f).is_file(), "missing {f}");
    }
    let cam: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(scene.join("scene_camera.json")).unwrap()).unwrap();
    assert_eq!(cam["5"]["depth_scale"], 0.1);
    assert_eq!(cam["5"]["cam_K"], serde_json::json!([100.0, 0.0, 15.5, 0.0, 110.0, 11.5, 0.0, 0.0, 1.0]));
    let gt: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(scene.join("scene_gt.json")).unwrap()).unwrap();
    let t = gt["5"][1]["cam_t_m2c"].as_array().unwrap();
    assert!((t[0].as_f64().unwrap() + 50.0).abs() < 1e-9 && (t[2].as_f64().unwrap() - 700.0).abs() < 1e-9);
    assert_eq!(gt["5"][1]["obj_id"], 3);
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(scene.join("scene_gt_info.json")).unwrap()).unwrap();
    assert_eq!(info["5"][1]["px_count_valid"], 2);
    assert_eq!(info["5"][0]["px_count_all"], 16);
    // bbox_obj of the plate (half sizes 4, 4, 1 cm) at (-5, 4, 70) cm rotated:
    // recompute from the projected corners.
    let pose = Pose::from_parts(Translation3::new(-0.05, 0.04, 0.7), UnitQuaternion::from_euler_angles(1.0, 0.0, 2.0));
    let (mut u0, mut v0, mut u1, mut v1) = (f64::MAX, f64::MAX, f64::MIN, f64::MIN);
    for sx in [-1.0, 1.0] {
        for sy in [-1.0, 1.0] {
            for sz in [-1.0, 1.0] {
                let p = pose * Point3::new(sx * 0.04f32 as f64, sy * 0.04f32 as f64, sz * 0.01f32 as f64);
                let (u, v) = K.project(&p).unwrap();
                (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
            }
        }
    }
    let expected = [u0.ceil(), v0.ceil(), u1.floor() - u0.ceil() + 1.0, v1.floor() - v0.ceil() + 1.0];
    let got: Vec<f64> = info["5"][1]["bbox_obj"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(got, expected);
    let root_cam: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.0.join("camera.json")).unwrap()).unwrap();
    assert_eq!(root_cam["width"], 32);
}

#[test]
fn models_info_is_in_millimetres_and_reads_back() {
    let dir = TempDir::new("bop-models");
    write_dataset(&dir.0);
    let raw: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.0.join("models/models_info.json")).unwrap()).unwrap();
    assert!((raw["1"]["size_x"].as_f64().unwrap() - 100.0).abs() < 1e-9);
    assert!((raw["1"]["min_z"].as_f64().unwrap() + 20.0).abs() < 1e-9);
    assert_eq!(raw["2"]["symmetries_continuous"][0]["axis"], serde_json::json!([0.0, 0.0, 1.0]));
    assert!((raw["2"]["symmetries_continuous"][0]["offset"][0].as_f64().unwrap() - 1.0).abs() < 1e-9);
    // Discrete: 180° about x, translation 2 mm along z (row-major 4x4).
    let m: Vec<f64> =
        raw["3"]["symmetries_discrete"][0].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let expected = [1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, 0.0, -1.0, 2.0, 0.0, 0.0, 0.0, 1.0];
    assert!(m.iter().zip(expected).all(|(a, b)| (a - b).abs() < 1e-9), "{m:?}");
    assert!(raw["1"].get("symmetries_discrete").is_none());

    let ds = BopDataset::open(dir.0.join("test")).unwrap();
    let info = ds.models_info().unwrap();
    assert!((info[&1].diameter - objects().objects[0].diameter).abs() < 1e-12);
    assert_eq!(info[&1].symmetry, Symmetry::None);
    match &info[&2].symmetry {
        Symmetry::Continuous { axis, origin } => {
            assert!((axis - Vector3::z()).norm() < 1e-12 && (origin.x - 0.001).abs() < 1e-12);
        }
        s => panic!("expected continuous, got {s:?}"),
    }
    match &info[&3].symmetry {
        Symmetry::Discrete(v) => {
            assert_eq!(v.len(), 1);
            assert!((v[0].translation.vector - Vector3::new(0.0, 0.0, 0.002)).norm() < 1e-12);
            assert!((v[0].rotation.angle() - std::f64::consts::PI).abs() < 1e-9);
            let back = v[0].to_homogeneous();
            assert!(
                (0..16)
                    .all(|k| (back[(k / 4, k % 4)] * if k % 4 == 3 && k < 12 { 1e3 } else { 1.0 } - expected[k]).abs()
                        < 1e-9),
                "{back}"
            );
        }
        s => panic!("expected discrete, got {s:?}"),
    }
}

#[test]
fn writer_refuses_to_mix_splits_or_object_sets() {
    let dir = TempDir::new("bop-mix");
    write_dataset(&dir.0);
    let set = objects();
    let again = BopWriter::create(&dir.0, "test", &set, &ObjectSource::Builtin);
    assert!(matches!(again, Err(BopError::SplitNotEmpty { .. })));
    let other = BopWriter::create(&dir.0, "train", &set, &ObjectSource::Directory("/x".into()));
    assert!(matches!(other, Err(BopError::ObjectSetMismatch { .. })));
    assert!(!dir.0.join("train").exists(), "a refused writer must not create the split");
    // Same set, new split: fine, and both splits are listed.
    BopWriter::create(&dir.0, "train", &set, &ObjectSource::Builtin).unwrap();
    let m = DatasetManifest::read(&dir.0).unwrap().unwrap();
    assert_eq!(m.splits.keys().collect::<Vec<_>>(), vec!["test", "train"]);
    assert!(BopWriter::create(&dir.0, "../evil", &set, &ObjectSource::Builtin).is_err());
}

#[test]
fn writer_rejects_inconsistent_frames() {
    let dir = TempDir::new("bop-bad");
    let set = objects();
    let mut w = BopWriter::create(&dir.0, "train", &set, &ObjectSource::Builtin).unwrap();
    let f = fake(0);
    let mut bad = frame(&f, 0, 0);
    bad.rgb = &f.rgb[..10];
    assert!(matches!(w.write_frame(&bad), Err(BopError::BadFrame { .. })));
    let insts = vec![InstanceToWrite { obj_id: 4, ..f.instances[0].clone() }];
    let mut bad = frame(&f, 0, 0);
    bad.instances = &insts;
    let err = w.write_frame(&bad).unwrap_err();
    assert!(err.to_string().contains("obj_id 4"), "{err}");
    let dup = vec![f.instances[0].clone(), f.instances[0].clone()];
    let mut bad = frame(&f, 0, 0);
    bad.instances = &dup;
    assert!(w.write_frame(&bad).is_err());
    assert_eq!(w.frames_written(), 0);
}

#[test]
fn reader_errors_name_the_file() {
    let dir = TempDir::new("bop-err");
    write_dataset(&dir.0);
    let mask = dir.0.join("test/000000/mask_visib/000001_000001.png");
    std::fs::remove_file(&mask).unwrap();
    let ds = BopDataset::open(dir.0.join("test")).unwrap();
    let err = ds.load(1).unwrap_err();
    assert!(err.to_string().contains("000001_000001.png"), "{err}");
    assert!(matches!(ds.load(99), Err(BopError::FrameOutOfRange { index: 99, len: 4 })));

    let gt = dir.0.join("test/000003/scene_gt.json");
    std::fs::write(&gt, "{\"0\": [").unwrap();
    let err = BopDataset::open(dir.0.join("test")).unwrap_err();
    assert!(matches!(err, BopError::Json { .. }));
    assert!(err.to_string().contains("000003/scene_gt.json"), "{err}");

    let empty = TempDir::new("bop-empty");
    assert!(matches!(BopDataset::open(&empty.0), Err(BopError::NoScenes { .. })));
}

#[test]
fn reader_rejects_a_depth_image_that_is_not_16_bit() {
    let dir = TempDir::new("bop-depth8");
    write_dataset(&dir.0);
    let depth = dir.0.join("test/000000/depth/000000.png");
    images::write_u8_png(&depth, K.width, K.height, &vec![0u8; (K.width * K.height) as usize]).unwrap();
    let ds = BopDataset::open(dir.0.join("test")).unwrap();
    let err = ds.load(0).unwrap_err();
    assert!(err.to_string().contains("depth/000000.png") && err.to_string().contains("16-bit"), "{err}");
}

#[test]
fn rendered_scene_round_trips_through_the_writer_and_reader() {
    use crate::render::{DEPTH_U16_PER_METRE, NoiseConfig, RenderTarget};
    use crate::sampler::{SamplerConfig, render_view, sample_scene};
    let set = crate::builtin::builtin_objects();
    let k = Intrinsics { fx: 266.7, fy: 266.9, cx: 79.5, cy: 59.5, width: 160, height: 120 };
    let cfg = SamplerConfig { views: 2, intrinsics: k, ..SamplerConfig::default() };
    let scene = sample_scene(&set, &cfg, 11).unwrap();
    let dir = TempDir::new("bop-render");
    let mut w = BopWriter::create(&dir.0, "train", &set, &ObjectSource::Builtin).unwrap();
    let mut target = RenderTarget::for_intrinsics(&k);
    let mut truths = Vec::new();
    let mut class_planes = Vec::new();
    for view in 0..2 {
        let truth = render_view(&scene, &set, view, &k, &NoiseConfig::default(), &mut target).unwrap();
        let instances = InstanceToWrite::of_truth(&truth);
        w.write_frame(&FrameToWrite {
            scene_id: 0,
            im_id: view as u32,
            intrinsics: k,
            rgb: target.rgb(),
            depth: target.depth_u16(),
            depth_unit_m: 1.0 / DEPTH_U16_PER_METRE,
            instance_labels: target.labels(),
            instances: &instances,
        })
        .unwrap();
        let mut classes = Vec::new();
        target.map_labels(&truth.class_lut(), &mut classes);
        class_planes.push((classes, target.depth_u16().to_vec()));
        truths.push(truth);
    }
    let ds = BopDataset::open_split(&dir.0, "train").unwrap();
    assert_eq!(ds.len(), 2);
    for (i, frame) in ds.iter().enumerate() {
        let frame = frame.unwrap();
        assert_eq!(frame.labels, class_planes[i].0);
        assert_eq!(frame.depth, class_planes[i].1);
        assert_eq!(frame.gt.len(), truths[i].objects.len());
        for (g, t) in frame.gt.iter().zip(&truths[i].objects) {
            assert_eq!(g.obj_id, t.class_id);
            assert!((g.visib_fract - t.visible_fraction).abs() < 1e-12);
            let d = g.pose.inverse() * t.pose;
            assert!(d.translation.vector.norm() < 1e-9 && d.rotation.angle() < 1e-9);
            if let Some(b) = t.bbox {
                assert_eq!(g.bbox_visib, [b.u_min as i32, b.v_min as i32, b.width() as i32, b.height() as i32]);
                // The full silhouette's box contains the visible box.
                let o = g.bbox_obj;
                assert!(o[0] <= b.u_min as i32 && o[1] <= b.v_min as i32);
                assert!(o[0] + o[2] >= (b.u_max + 1) as i32 && o[1] + o[3] >= (b.v_max + 1) as i32);
            }
        }
    }
    let names: Vec<String> = ds.manifest().unwrap().classes.iter().map(|c| c.name.clone()).collect();
    assert_eq!(names, set.objects.iter().map(|o| o.name.clone()).collect::<Vec<_>>());
}

#[test]
fn model_ply_files_are_written_in_millimetres() {
    let dir = TempDir::new("bop-ply");
    write_dataset(&dir.0);
    let bytes = std::fs::read(dir.0.join("models/obj_000001.ply")).unwrap();
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header = std::str::from_utf8(&bytes[..at]).unwrap();
    assert!(header.contains("element vertex 8\n") && header.contains("element face 0\n"), "{header}");
    // First vertex (-5, -3, -2) cm -> mm as f32, then r, g, b.
    let f = |o: usize| f32::from_le_bytes(bytes[at + o..at + o + 4].try_into().unwrap());
    assert_eq!((f(0), f(4), f(8)), (-50.0, -30.0, -20.0));
    assert_eq!(bytes.len(), at + 8 * (12 + 3));
    assert!(dir.0.join("models/obj_000003.ply").is_file());
}
