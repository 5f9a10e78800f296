//! Pose verification on rendered scenes of the built-in objects: true poses
//! pass, poses shifted by 3 cm score lower and fail (always on objects under
//! 15 cm across, at least 90 % of the time on all), and a bowl pose made up
//! for a patch of flat table fails.

use fusepose_estimator::verify::{MaskRef, Verifier, VerifyConfig};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView, LabelPlane, ObjectPose, Workspace, WorkspaceConfig};
use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{FrameTruth, LabelKind, SamplerConfig, render_view_labelled, sample_scene};
use fusepose_scene::{Intrinsics, ObjectSet, Pose};
use nalgebra::{UnitQuaternion, Vector3};

struct Rendered {
    target: RenderTarget,
    truth: FrameTruth,
}

fn render(set: &ObjectSet, seed: u64) -> Rendered {
    let k = Intrinsics::YCB_VIDEO;
    let scene = sample_scene(set, &SamplerConfig::default(), seed).unwrap();
    let mut target = RenderTarget::for_intrinsics(&k);
    let truth =
        render_view_labelled(&scene, set, 0, &k, &NoiseConfig::default(), LabelKind::Class, &mut target).unwrap();
    Rendered { target, truth }
}

fn view<'a>(r: &'a Rendered, labels: &'a [u16]) -> FrameView<'a> {
    FrameView {
        intrinsics: r.truth.intrinsics,
        color_format: ColorFormat::Rgb8,
        color: r.target.rgb(),
        depth: DepthPlane::F32(r.target.depth_m()),
        labels: Some(LabelPlane::U16(labels)),
    }
}

fn workspace(set: &ObjectSet) -> Workspace {
    Workspace::new(WorkspaceConfig { num_classes: set.len() as u16, ..WorkspaceConfig::default() }).unwrap()
}

fn pose_of(class_id: u16, instance: usize, ws: &Workspace, p: &Pose) -> ObjectPose {
    let inst = ws.instances[instance];
    ObjectPose {
        class_id,
        instance_id: instance as u16,
        rotation: p.rotation,
        translation: p.translation.vector,
        confidence: 1.0,
        mask_pixels: inst.pixels,
        bbox: inst.bbox,
        iterations: 0,
    }
}

fn mask<'a>(ws: &'a Workspace, i: usize) -> MaskRef<'a> {
    MaskRef { ids: ws.component_ids(), id: ws.component_id(i).unwrap(), bbox: ws.instances[i].bbox }
}

#[test]
fn true_poses_pass_and_poses_shifted_by_3_cm_fail() {
    let set = builtin_objects();
    let mut verifier = Verifier::new(&set, VerifyConfig::default());
    let mut ws = workspace(&set);
    let (mut checked, mut passed, mut shifted_passed, mut shifted) = (0, 0, 0, 0);
    for seed in 0..6 {
        let r = render(&set, 7_000 + seed);
        let labels = r.target.labels().to_vec();
        let frame = view(&r, &labels);
        let n = ws.prepare(&frame, 1).unwrap();
        for i in 0..n {
            let inst = ws.instances[i];
            let Some(t) = r.truth.objects.iter().find(|o| o.class_id == inst.class_id) else { continue };
            if t.visible_fraction < 0.5 || inst.pixels < 400 {
                continue;
            }
            let good = verifier.verify(&frame, mask(&ws, i), &pose_of(inst.class_id, i, &ws, &t.pose));
            checked += 1;
            passed += good.passed as usize;
            assert!(good.depth_residual_m < 0.01, "true pose residual {good:?}");
            for d in [Vector3::new(0.03, 0.0, 0.0), Vector3::new(0.0, -0.03, 0.0), Vector3::new(0.0, 0.0, 0.03)] {
                let mut p = t.pose;
                p.translation.vector += d;
                let bad = verifier.verify(&frame, mask(&ws, i), &pose_of(inst.class_id, i, &ws, &p));
                shifted += 1;
                shifted_passed += bad.passed as usize;
                // The defaults keep network poses up to ~1.2 cm off (the lateral
                // slack), so on objects over 15 cm across a 3 cm shift can still
                // pass; on smaller ones it never may.
                let diameter = set.objects[inst.class_id as usize - 1].diameter;
                assert!(!(bad.passed && diameter < 0.15), "a {diameter:.3} m object shifted by {d:?} passed: {bad:?}");
                assert!(bad.fit < good.fit, "shift {d:?}: {bad:?} vs true {good:?}");
            }
        }
    }
    assert!(checked >= 12, "too few objects checked: {checked}");
    assert!(passed as f64 >= 0.9 * checked as f64, "true poses passed {passed} of {checked}");
    assert!(shifted_passed * 10 <= shifted, "{shifted_passed} of {shifted} poses shifted by 3 cm passed");
}

#[test]
fn a_bowl_made_up_for_a_patch_of_table_fails() {
    let set = builtin_objects();
    let bowl = set.class_of("bowl").unwrap();
    let mut verifier = Verifier::new(&set, VerifyConfig::default());
    let mut ws = workspace(&set);
    let mut tried = 0;
    for seed in 0..24 {
        if tried >= 5 {
            break;
        }
        let r = render(&set, 9_100 + seed);
        let (w, h) = (r.truth.intrinsics.width as usize, r.truth.intrinsics.height as usize);
        // A 60x40 px patch of bare table (background label, valid depth) near the image's lower middle.
        let table_from_camera = r.truth.camera_from_table.inverse();
        let Some((u0, v0)) = (0..(h - 50) / 10)
            .rev()
            .flat_map(|j| (0..(w - 70) / 10).map(move |i| (i * 10, j * 10)))
            .find(|&(u0, v0)| {
                (v0..v0 + 40).all(|v| {
                    (u0..u0 + 60).all(|u| {
                        let p = v * w + u;
                        let z = r.target.depth_m()[p];
                        if r.target.labels()[p] != 0 || z <= 0.0 {
                            return false;
                        }
                        // On the table top: the back-projected point lies in the table plane (z = 0).
                        let k = &r.truth.intrinsics;
                        let c = Vector3::new(
                            (u as f64 - k.cx) / k.fx * z as f64,
                            (v as f64 - k.cy) / k.fy * z as f64,
                            z as f64,
                        );
                        (table_from_camera * nalgebra::Point3::from(c)).z.abs() < 0.01
                    })
                })
            })
        else {
            continue;
        };
        let mut labels = vec![0u16; w * h];
        for v in v0..v0 + 40 {
            labels[v * w + u0..v * w + u0 + 60].fill(bowl);
        }
        let frame = view(&r, &labels);
        assert_eq!(ws.prepare(&frame, 1).unwrap(), 1);
        // The most plausible ghost: an upright bowl standing on the patch's centre point.
        let (uc, vc) = (u0 + 30, v0 + 20);
        let z = r.target.depth_m()[vc * w + uc] as f64;
        let k = &r.truth.intrinsics;
        let on_table =
            table_from_camera * nalgebra::Point3::new((uc as f64 - k.cx) / k.fx * z, (vc as f64 - k.cy) / k.fy * z, z);
        let model = set.by_class(bowl).unwrap();
        let table_pose = Pose::from_parts(
            nalgebra::Translation3::new(on_table.x, on_table.y, -model.bbox_min.z),
            UnitQuaternion::identity(),
        );
        let ghost = r.truth.camera_from_table * table_pose;
        let v = verifier.verify(&frame, mask(&ws, 0), &pose_of(bowl, 0, &ws, &ghost));
        assert!(!v.passed, "bowl on a table patch passed: {v:?}");
        tried += 1;
    }
    assert!(tried >= 3, "found a bare table patch in only {tried} scenes");
}
