//! One scene seen by two cameras at known places (issue 21): the daemon
//! serves both, moves their poses into the cell frame with each camera's
//! extrinsics and merges them. Each object appears once in the cell, listing
//! both views, and the fused poses are no worse than the better camera's.

use std::time::{Duration, Instant};

use fusepose_client::{
    CellConsumer, CellPoseMessage, Consumer, DepthMut, FrameLayout, Ipc, LabelFormat, LabelsMut, PoseMessage, Producer,
    camera_id,
};
use fusepose_scene::metrics::ObjectMetric;
use fusepose_scene::render::{RenderItem, RenderSettings, RenderTarget, render_scene};
use fusepose_scene::{Intrinsics, Pose};
use fusepose_tests::*;
use nalgebra::{Isometry3, Translation3, UnitQuaternion, Vector3};

/// Built-in classes in the scene (one of each, so class labels are instance labels).
const CLASSES: [u16; 3] = [1, 3, 6];
/// Where the objects stand in the cell frame (camera A's optical frame).
const CENTRE: [f64; 3] = [0.0, 0.0, 0.75];
/// Camera B looks at the centre from this far to the side (rotation about y), degrees.
const B_YAW_DEG: f64 = 35.0;

fn intrinsics() -> Intrinsics {
    Intrinsics { fx: 572.4, fy: 573.6, cx: 325.3, cy: 242.0, width: 640, height: 480 }
}

/// Camera → cell of the two cameras: A is the cell frame; B turned about the
/// vertical axis through the scene centre.
fn cameras() -> [Isometry3<f64>; 2] {
    let c = Vector3::from(CENTRE);
    let r = UnitQuaternion::from_scaled_axis(Vector3::y() * B_YAW_DEG.to_radians());
    let b = Isometry3::from_parts(Translation3::from(c - r * Vector3::new(0.0, 0.0, CENTRE[2])), r);
    [Isometry3::identity(), b]
}

fn truth() -> Vec<Pose> {
    let spins = [[0.3, 0.5, 0.1], [-0.2, 1.4, 0.0], [0.1, -0.8, 0.4]];
    (0..CLASSES.len())
        .map(|i| {
            let x = (i as f64 - 1.0) * 0.15;
            let t = Translation3::new(CENTRE[0] + x, CENTRE[1] + 0.02 * i as f64, CENTRE[2] + 0.03 * (i % 2) as f64);
            Pose::from_parts(t, UnitQuaternion::from_scaled_axis(Vector3::from(spins[i])))
        })
        .collect()
}

fn extrinsics_toml(name: &str, cell_from_camera: &Isometry3<f64>) -> String {
    let t = cell_from_camera.translation.vector;
    let q = cell_from_camera.rotation;
    format!(
        "[[camera]]\nname = \"{name}\"\n[camera.extrinsics]\ntranslation_m = [{}, {}, {}]\nquaternion_xyzw = [{}, {}, {}, {}]\n\n",
        t.x, t.y, t.z, q.i, q.j, q.k, q.w
    )
}

fn send_view(
    producer: &mut Producer,
    k: &Intrinsics,
    cell_from_camera: &Isometry3<f64>,
    objects: &fusepose_scene::ObjectSet,
) -> anyhow::Result<u64> {
    send_scene(producer, k, cell_from_camera, objects, &CLASSES, &truth())
}

/// Renders `classes` at `truth` (cell frame) as the camera at `cell_from_camera` sees them and sends the frame.
fn send_scene(
    producer: &mut Producer,
    k: &Intrinsics,
    cell_from_camera: &Isometry3<f64>,
    objects: &fusepose_scene::ObjectSet,
    classes: &[u16],
    truth: &[Pose],
) -> anyhow::Result<u64> {
    let camera_from_cell = cell_from_camera.inverse();
    let items: Vec<RenderItem<'_>> = classes
        .iter()
        .zip(truth)
        .map(|(&class, pose)| RenderItem {
            mesh: &objects.by_class(class).expect("built-in class").mesh,
            pose: camera_from_cell * pose,
            instance_label: class,
            shadow_mesh: None,
        })
        .collect();
    let mut target = RenderTarget::for_intrinsics(k);
    render_scene(&items, k, &RenderSettings::default(), &mut target).map_err(|e| anyhow::anyhow!("{e}"))?;
    for &class in classes {
        let px = target.labels().iter().filter(|&&l| l == class).count();
        anyhow::ensure!(px > 800, "class {class} shows only {px} px in this view");
    }
    let mut frame = producer.loan()?;
    frame.set_intrinsics(k.fx, k.fy, k.cx, k.cy);
    let planes = frame.planes_mut();
    planes.color.copy_from_slice(target.rgb());
    match planes.depth {
        DepthMut::U16(d) => d.copy_from_slice(target.depth_u16()),
        _ => anyhow::bail!("u16 depth expected"),
    }
    match planes.labels {
        Some(LabelsMut::U16(l)) => l.copy_from_slice(target.labels()),
        _ => anyhow::bail!("u16 labels expected"),
    }
    Ok(frame.send()?)
}

/// A daemon (the shipped network, true class labels) serving cameras `a` and
/// `b` as `cameras_toml` declares them, and a producer and consumer of each.
struct Rig {
    _daemon: Proc,
    ipc: Ipc,
    producers: [Producer; 2],
    consumers: [Consumer; 2],
}

fn two_camera_rig(env: &TestEnv, cameras_toml: &str, cell_toml: &str) -> anyhow::Result<Rig> {
    let weights = workspace_root()?.join("models/builtin.safetensors");
    let config = env.dir.path().join("fuseposed.toml");
    std::fs::write(
        &config,
        format!(
            "{cameras_toml}[estimator]\nkind = \"net\"\nweights = {:?}\nmasks = \"labels\"\ndeadline_aware = false\n\n{cell_toml}[stats]\nhlog_path = \"\"\n\n[ipc]\nroot_path = {:?}\nprefix = {:?}\n",
            weights.display().to_string(),
            env.iox_root,
            env.prefix
        ),
    )?;
    let daemon = start_daemon_for(env, &config, "a")?;
    let layout = FrameLayout { labels: Some(LabelFormat::U16), ..rendered_layout(&intrinsics()) };
    let ipc = Ipc::new(&env.ipc_options())?;
    let producers = [Producer::create(&ipc, "a", layout)?, Producer::create(&ipc, "b", layout)?];
    let consumers = [Consumer::open(&ipc, "a")?, Consumer::open(&ipc, "b")?];
    Ok(Rig { _daemon: daemon, ipc, producers, consumers })
}

fn wait_cell(cell: &mut CellConsumer, trigger: u32, timeout: Duration) -> anyhow::Result<CellPoseMessage> {
    let end = Instant::now() + timeout;
    let mut all = Vec::new();
    while Instant::now() < end {
        std::thread::sleep(Duration::from_millis(20));
        all.clear();
        cell.drain(&mut all)?;
        if let Some(m) = all.iter().rev().find(|m| m.trigger_camera_id == trigger && m.camera_count == 2) {
            return Ok(*m);
        }
    }
    anyhow::bail!("no cell message combining both cameras after camera {trigger:08x}'s frame")
}

/// ADD-S (m) of a camera's pose of `class` in the cell frame; None when it has none.
fn view_add_s(
    msg: &PoseMessage,
    cell_from_camera: &Isometry3<f64>,
    class: u16,
    truth: &Pose,
    metric: &ObjectMetric,
) -> Option<f64> {
    let o = msg.objects().iter().find(|o| o.class_id == class)?;
    Some(metric.add_s(&(cell_from_camera * wire_pose(o.quaternion, o.translation_m)), truth))
}

#[test]
fn an_object_seen_by_two_cameras_is_one_cell_entry_no_worse_than_the_better_view() -> anyhow::Result<()> {
    let env = TestEnv::new("cell")?;
    let cams = cameras();
    let cameras = format!("{}{}", extrinsics_toml("a", &cams[0]), extrinsics_toml("b", &cams[1]));
    let mut rig = two_camera_rig(&env, &cameras, "[cell]\nmax_age_ms = 60000\n\n")?;
    let k = intrinsics();
    let objects = fusepose_scene::builtin::builtin_objects();
    let mut cell = CellConsumer::open(&rig.ipc)?;

    let mut views = Vec::new();
    for ((producer, consumer), cam) in rig.producers.iter_mut().zip(rig.consumers.iter_mut()).zip(&cams) {
        let seq = send_view(producer, &k, cam, &objects)?;
        views.push(wait_for_sequence(consumer, seq, Duration::from_secs(30))?);
    }
    let fused = wait_cell(&mut cell, camera_id("b"), Duration::from_secs(10))?;

    let truth = truth();
    let (mut sum_a, mut sum_b, mut sum_fused) = (0.0, 0.0, 0.0);
    for (i, &class) in CLASSES.iter().enumerate() {
        let metric = ObjectMetric::for_model(objects.by_class(class).unwrap()).map_err(|e| anyhow::anyhow!("{e}"))?;
        let entries: Vec<_> = fused.objects().iter().filter(|o| o.class_id == class).collect();
        assert_eq!(entries.len(), 1, "class {class}: {} cell entries", entries.len());
        let entry = entries[0];
        let a = view_add_s(&views[0], &cams[0], class, &truth[i], &metric).expect("camera a posed it");
        let b = view_add_s(&views[1], &cams[1], class, &truth[i], &metric).expect("camera b posed it");
        assert_eq!(entry.view_count, 2, "class {class}: both cameras saw it");
        let ids: Vec<u32> = entry.views().iter().map(|v| v.camera_id).collect();
        assert!(ids.contains(&camera_id("a")) && ids.contains(&camera_id("b")), "{ids:?}");
        let captures: Vec<u64> = [&views[0], &views[1]].iter().map(|m| m.capture_time_ns).collect();
        for v in entry.views() {
            assert!(captures.contains(&v.capture_time_ns), "a view stamped with a frame that was not sent");
        }
        let f = metric.add_s(&wire_pose(entry.quaternion, entry.translation_m), &truth[i]);
        for v in entry.views() {
            println!(
                "RESULT   view camera {:08x} confidence {:.3} offset {:.1} mm flags {}",
                v.camera_id,
                v.confidence,
                v.offset_m * 1e3,
                v.flags
            );
        }
        println!(
            "RESULT class {class}: ADD-S camera a {:.1} mm, camera b {:.1} mm, fused {:.1} mm",
            a * 1e3,
            b * 1e3,
            f * 1e3
        );
        assert!(f <= a.max(b) + 1e-3, "class {class}: fused {f} worse than both views ({a}, {b})");
        (sum_a, sum_b, sum_fused) = (sum_a + a, sum_b + b, sum_fused + f);
    }
    let n = CLASSES.len() as f64;
    println!(
        "RESULT mean ADD-S: camera a {:.2} mm, camera b {:.2} mm, fused {:.2} mm",
        sum_a / n * 1e3,
        sum_b / n * 1e3,
        sum_fused / n * 1e3
    );
    assert!(sum_fused <= sum_a.min(sum_b) + 1e-3 * n, "fused mean ADD-S is worse than the better camera's");
    assert_eq!(fused.object_count as usize, CLASSES.len(), "no extra cell objects");
    Ok(())
}

/// A random two-view scene of the fusion study (tuning seeds only): three
/// distinct built-in classes on a row in front of camera A, camera B turned
/// 25–60° to either side about the row's centre.
struct StudyScene {
    classes: [u16; 3],
    truth: Vec<Pose>,
    cams: [Isometry3<f64>; 2],
}

fn study_scene(seed: u64) -> StudyScene {
    let mut state = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
    let mut next = move || {
        state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut classes = [0u16; 3];
    let mut n = 0;
    while n < 3 {
        let c = 1 + (next() * 8.0) as u16 % 8;
        if !classes[..n].contains(&c) {
            classes[n] = c;
            n += 1;
        }
    }
    let z = 0.6 + 0.3 * next();
    let truth = (0..3)
        .map(|i| {
            let t = Translation3::new(
                (i as f64 - 1.0) * 0.16 + 0.02 * next(),
                0.05 * (next() - 0.5),
                z + 0.06 * (next() - 0.5),
            );
            let axis = Vector3::new(next() - 0.5, next() - 0.5, next() - 0.5) * 2.5;
            Pose::from_parts(t, UnitQuaternion::from_scaled_axis(axis))
        })
        .collect();
    let yaw = (25.0 + 35.0 * next()) * if next() < 0.5 { -1.0 } else { 1.0 };
    let c = Vector3::new(0.0, 0.0, z);
    let r = UnitQuaternion::from_scaled_axis(Vector3::y() * f64::to_radians(yaw));
    let b = Isometry3::from_parts(Translation3::from(c - r * Vector3::new(0.0, 0.0, z)), r);
    StudyScene { classes, truth, cams: [Isometry3::identity(), b] }
}

/// The fusion study behind `cell`'s choices (docs/BENCHMARKS.md, "Cell
/// fusion"): 24 random two-view scenes of tuning seeds, each camera's poses
/// from the daemon, fused offline by every variant. Run by hand:
/// `cargo test --release -p fusepose-tests --test cell_two_views -- --ignored --nocapture`.
#[test]
#[ignore = "a study, not a check: prints a table (about a minute)"]
fn fusion_study_on_tuning_scenes() -> anyhow::Result<()> {
    use fusepose_daemon::cell::{CellFuser, CellSource, Fusion};
    let env = TestEnv::new("cellstudy")?;
    let mut rig = two_camera_rig(&env, "cameras = [\"a\", \"b\"]\n", "")?;
    let k = intrinsics();
    let objects = fusepose_scene::builtin::builtin_objects();
    let merge: Vec<f64> = objects.objects.iter().map(|o| 0.5 * o.diameter).collect();
    let variants: [(&str, Fusion, f64); 3] = [
        ("best fit: the view with the smallest verified depth residual [default]", Fusion::BestFit, 20.0),
        ("mean: confidence-weighted, rotations within 20 deg of the best view", Fusion::Mean, 20.0),
        ("mean: confidence-weighted translation, the most confident view's rotation", Fusion::Mean, 0.0),
    ];
    let mut sums = vec![0.0; variants.len()];
    let (mut sum_a, mut sum_b, mut sum_best, mut sum_best_resid, mut n) = (0.0, 0.0, 0.0, 0.0, 0usize);
    let mut not_worse = vec![0usize; variants.len()];
    for seed in 1000..1024u64 {
        let scene = study_scene(seed);
        let mut views = Vec::new();
        let mut skip = false;
        for i in 0..2 {
            match send_scene(&mut rig.producers[i], &k, &scene.cams[i], &objects, &scene.classes, &scene.truth) {
                Ok(seq) => views.push(wait_for_sequence(&mut rig.consumers[i], seq, Duration::from_secs(30))?),
                Err(_) => skip = true,
            }
        }
        if skip {
            continue;
        }
        let mut fused = Vec::new();
        for &(_, fusion, rot) in &variants {
            let mut fuser = CellFuser::new(merge.clone(), rot).with_fusion(fusion);
            let mut out = CellPoseMessage::default();
            let sources =
                [0, 1].map(|i| CellSource { msg: &views[i], cell_from_camera: &scene.cams[i], class_map: &[] });
            let now = views.iter().map(|v| v.capture_time_ns).max().unwrap_or(0);
            fuser.fuse(sources, now, u64::MAX, 0, &mut out);
            fused.push(out);
        }
        for (j, &class) in scene.classes.iter().enumerate() {
            let metric =
                ObjectMetric::for_model(objects.by_class(class).unwrap()).map_err(|e| anyhow::anyhow!("{e}"))?;
            let a = view_add_s(&views[0], &scene.cams[0], class, &scene.truth[j], &metric);
            let b = view_add_s(&views[1], &scene.cams[1], class, &scene.truth[j], &metric);
            let (Some(a), Some(b)) = (a, b) else { continue };
            let conf = |m: &PoseMessage| m.objects().iter().find(|o| o.class_id == class).map_or(0.0, |o| o.confidence);
            let best = if conf(&views[0]) >= conf(&views[1]) { a } else { b };
            let resid = |m: &PoseMessage| {
                m.objects().iter().find(|o| o.class_id == class).map_or(f32::NAN, |o| o.depth_residual_m)
            };
            sum_best_resid += if resid(&views[0]) <= resid(&views[1]) { a } else { b };
            n += 1;
            (sum_a, sum_b, sum_best) = (sum_a + a, sum_b + b, sum_best + best);
            for (v, out) in fused.iter().enumerate() {
                let Some(e) = out.objects().iter().find(|o| o.class_id == class) else { continue };
                let f = metric.add_s(&wire_pose(e.quaternion, e.translation_m), &scene.truth[j]);
                sums[v] += f;
                not_worse[v] += (f <= a.min(b) + 1e-4) as usize;
            }
        }
    }
    let mm = |s: f64| s / n as f64 * 1e3;
    println!("RESULT fusion study: {n} objects seen by both cameras in 24 tuning scenes (seeds 1000-1023)");
    println!(
        "RESULT mean ADD-S camera a {:.2} mm, camera b {:.2} mm, more confident view {:.2} mm, smaller depth residual {:.2} mm",
        mm(sum_a),
        mm(sum_b),
        mm(sum_best),
        mm(sum_best_resid)
    );
    for (v, (name, _, _)) in variants.iter().enumerate() {
        println!(
            "RESULT {name}: mean ADD-S {:.2} mm, no worse than the better view for {}/{n} objects",
            mm(sums[v]),
            not_worse[v]
        );
    }
    Ok(())
}
