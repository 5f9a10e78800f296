//! Tests on a tiny YCB-Video tree written by the tests (images + v5 .mat).

use std::path::Path;

use nalgebra::{Translation3, UnitQuaternion, Vector3};

use super::mat_writer::{MatData, mat_v5};
use super::*;
use crate::bop::images::{write_rgb8_png, write_u8_png, write_u16_png};
use crate::bop::tests::TempDir;

const W: u32 = 8;
const H: u32 = 6;

fn pose_a() -> Pose {
    Pose::from_parts(Translation3::new(0.1, -0.05, 0.9), UnitQuaternion::from_axis_angle(&Vector3::y_axis(), 0.5))
}

fn pose_b() -> Pose {
    Pose::from_parts(Translation3::new(-0.2, 0.0, 1.1), UnitQuaternion::from_euler_angles(0.3, -0.4, 1.2))
}

/// Column-major 3x4xn array of `poses`.
fn poses_col_major(poses: &[Pose]) -> Vec<f64> {
    let mut out = Vec::new();
    for p in poses {
        let m = p.to_homogeneous();
        for c in 0..4 {
            for r in 0..3 {
                out.push(m[(r, c)]);
            }
        }
    }
    out
}

fn k_col_major() -> Vec<f64> {
    // K = [fx 0 cx; 0 fy cy; 0 0 1] with fx 1066.778, fy 1067.487, cx 312.9869, cy 241.3109.
    vec![1066.778, 0.0, 0.0, 0.0, 1067.487, 0.0, 312.9869, 241.3109, 1.0]
}

fn write_frame(dir: &Path, entry: &str, seed: u8, cls_as_u8: bool) {
    let prefix = dir.join("data").join(entry);
    std::fs::create_dir_all(prefix.parent().unwrap()).unwrap();
    let p = |s: &str| {
        let mut x = prefix.clone().into_os_string();
        x.push(s);
        std::path::PathBuf::from(x)
    };
    let n = (W * H) as usize;
    let rgb: Vec<u8> = (0..n * 3).map(|i| (i as u8).wrapping_add(seed)).collect();
    write_rgb8_png(&p("-color.png"), W, H, &rgb).unwrap();
    let depth: Vec<u16> = (0..n).map(|i| 9000 + i as u16).collect();
    write_u16_png(&p("-depth.png"), W, H, &depth).unwrap();
    let labels: Vec<u8> = (0..n)
        .map(|i| {
            if i % 5 == 0 {
                3
            } else if i % 7 == 0 {
                14
            } else {
                0
            }
        })
        .collect();
    write_u8_png(&p("-label.png"), W, H, &labels).unwrap();
    let poses = poses_col_major(&[pose_a(), pose_b()]);
    let k = k_col_major();
    let cls = if cls_as_u8 { MatData::DoubleAsU8(&[3, 14]) } else { MatData::Double(&[3.0, 14.0]) };
    let mat = mat_v5(&[
        ("cls_indexes", &[2, 1], cls),
        ("factor_depth", &[1, 1], MatData::Double(&[10000.0])),
        ("intrinsic_matrix", &[3, 3], MatData::Double(&k)),
        ("poses", &[3, 4, 2], MatData::Double(&poses)),
    ]);
    std::fs::write(p("-meta.mat"), mat).unwrap();
}

fn dataset() -> TempDir {
    let dir = TempDir::new("ycbv");
    std::fs::create_dir_all(dir.0.join("image_sets")).unwrap();
    let classes: Vec<String> = (1..=21).map(|i| format!("{i:03}_object")).collect();
    std::fs::write(dir.0.join("image_sets/classes.txt"), classes.join("\n") + "\n").unwrap();
    std::fs::write(dir.0.join("image_sets/keyframe.txt"), "0048/000001\n0059/000010\n\n").unwrap();
    write_frame(&dir.0, "0048/000001", 0, false);
    write_frame(&dir.0, "0059/000010", 9, true);
    dir
}

#[test]
fn reads_meta_columns_in_matlab_order() {
    let dir = dataset();
    let meta = read_meta(&dir.0.join("data/0048/000001-meta.mat")).unwrap();
    assert_eq!(meta.class_ids, vec![3, 14]);
    assert_eq!(meta.factor_depth, 10000.0);
    assert_eq!(meta.intrinsic_matrix, [1066.778, 0.0, 312.9869, 0.0, 1067.487, 241.3109, 0.0, 0.0, 1.0]);
    for (got, want) in meta.poses.iter().zip([pose_a(), pose_b()]) {
        let d = got.inverse() * want;
        assert!(d.translation.vector.norm() < 1e-12 && d.rotation.angle() < 1e-9, "{got} vs {want}");
    }
    let k = meta.intrinsics(640, 480);
    assert_eq!(k, Intrinsics::YCB_VIDEO);
}

#[test]
fn loads_key_frames_with_images_and_ground_truth() {
    let dir = dataset();
    let ds = YcbVideo::open(&dir.0).unwrap();
    assert_eq!(ds.len(), 2);
    assert_eq!(ds.classes()[2], "003_object");
    assert_eq!(ds.frame_ids(), ["0048/000001", "0059/000010"]);
    for (i, frame) in ds.iter().enumerate() {
        let f = frame.unwrap();
        assert_eq!((f.intrinsics.width, f.intrinsics.height), (W, H));
        assert_eq!(f.intrinsics.fx, 1066.778);
        assert_eq!(f.rgb[5], 5u8.wrapping_add(if i == 0 { 0 } else { 9 }));
        assert_eq!(f.depth[3], 9003);
        assert!((f.depth_metres()[3] - 0.9003).abs() < 1e-6);
        assert!((f.depth_unit_m - 1e-4).abs() < 1e-18);
        assert_eq!(f.labels[0], 3);
        assert_eq!(f.labels[7], 14);
        assert_eq!(f.labels[1], 0);
        assert_eq!(f.gt.iter().map(|g| g.class_id).collect::<Vec<_>>(), vec![3, 14]);
        assert!((f.gt[1].pose.translation.vector - Vector3::new(-0.2, 0.0, 1.1)).norm() < 1e-12);
    }
}

#[test]
fn errors_name_the_file() {
    let dir = dataset();
    let bad = dir.0.join("data/0059/000010-meta.mat");
    std::fs::write(&bad, b"not a mat file at all").unwrap();
    let ds = YcbVideo::open(&dir.0).unwrap();
    let err = ds.load(1).unwrap_err();
    assert!(matches!(err, YcbError::Mat { .. }));
    assert!(err.to_string().contains("000010-meta.mat"), "{err}");

    // Poses for one object but two class ids.
    let poses = poses_col_major(&[pose_a()]);
    let k = k_col_major();
    std::fs::write(
        &bad,
        mat_v5(&[
            ("cls_indexes", &[2, 1], MatData::Double(&[1.0, 2.0])),
            ("factor_depth", &[1, 1], MatData::Double(&[10000.0])),
            ("intrinsic_matrix", &[3, 3], MatData::Double(&k)),
            ("poses", &[3, 4], MatData::Double(&poses)),
        ]),
    )
    .unwrap();
    let err = ds.load(1).unwrap_err();
    assert!(matches!(err, YcbError::Invalid { .. }) && err.to_string().contains("3x4x2"), "{err}");

    std::fs::remove_file(dir.0.join("data/0048/000001-depth.png")).unwrap();
    let err = ds.load(0).unwrap_err();
    assert!(err.to_string().contains("000001-depth.png"), "{err}");
    assert!(matches!(ds.load(2), Err(YcbError::FrameOutOfRange { index: 2, len: 2 })));

    std::fs::write(dir.0.join("image_sets/keyframe.txt"), "0048/../../etc\n").unwrap();
    assert!(matches!(YcbVideo::open(&dir.0), Err(YcbError::BadListEntry { line: 1, .. })));
    std::fs::remove_file(dir.0.join("image_sets/classes.txt")).unwrap();
    assert!(matches!(YcbVideo::open(&dir.0), Err(YcbError::NoClasses { .. })));
}

#[test]
fn single_object_meta_has_two_dimensional_poses() {
    let dir = TempDir::new("ycbv-one");
    let path = dir.0.join("m.mat");
    let poses = poses_col_major(&[pose_b()]);
    std::fs::write(
        &path,
        mat_v5(&[
            ("poses", &[3, 4], MatData::Double(&poses)),
            ("cls_indexes", &[1, 1], MatData::DoubleAsU8(&[21])),
            ("intrinsic_matrix", &[3, 3], MatData::Double(&k_col_major())),
            ("factor_depth", &[1, 1], MatData::Double(&[1000.0])),
        ]),
    )
    .unwrap();
    let meta = read_meta(&path).unwrap();
    assert_eq!(meta.class_ids, vec![21]);
    assert_eq!(meta.factor_depth, 1000.0);
    assert!((meta.poses[0].translation.vector - Vector3::new(-0.2, 0.0, 1.1)).norm() < 1e-12);
}
