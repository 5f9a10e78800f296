//! A camera that sends nothing but RGB-D: rendered tabletop scenes go to
//! `fuseposed` WITHOUT a label plane; the daemon segments them with the
//! segmenter embedded in the committed `models/builtin.safetensors`
//! (`masks = "auto"`), estimates poses with the fusion network and publishes
//! them. The published classes must be the visible objects' and their poses
//! close to the renderer's ground truth; the segmentation stage must be timed.
//! A camera that turns dim and back is logged once each way (auto exposure).

use std::path::PathBuf;
use std::time::Duration;

use fusepose_client::{Consumer, Ipc, Producer, Stage};
use fusepose_scene::Intrinsics;
use fusepose_scene::metrics::ObjectMetric;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{LabelKind, SamplerConfig, render_view_labelled, sample_scene};
use fusepose_tests::*;

/// Objects at least this visible are expected in the answer.
const MIN_VISIBLE_FRACTION: f64 = 0.6;
/// Share of those the daemon must find (right class) with ADD-S below 10 % of the diameter.
const MIN_FOUND_SHARE: f64 = 0.7;

fn weights() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../models/builtin.safetensors")
}

#[test]
fn frames_without_labels_are_segmented_and_get_poses() -> anyhow::Result<()> {
    let weights = weights();
    let env = TestEnv::new("segmenter")?;
    // Every frame estimated in full: on a loaded machine a deadline-aware daemon
    // sheds the smallest instances (tested in the estimator); this test counts poses.
    let config = env.write_daemon_config(&format!(
        "kind = \"net\"\nweights = {:?}\nmasks = \"auto\"\nmax_instances = 8\nworker_threads = 2\ndeadline_aware = false",
        weights.canonicalize()?
    ))?;
    let _daemon = start_daemon(&env, &config)?;

    let objects = fusepose_scene::builtin::builtin_objects();
    let metrics: Vec<ObjectMetric> = objects.objects.iter().map(|m| ObjectMetric::for_model(m).unwrap()).collect();
    let k = Intrinsics::YCB_VIDEO;
    let layout = rendered_layout(&k);
    let ipc = Ipc::new(&env.ipc_options())?;
    let mut producer = Producer::create(&ipc, "cam0", layout)?;
    let mut consumer = Consumer::open(&ipc, "cam0")?;
    let mut target = RenderTarget::for_intrinsics(&k);

    let (mut expected, mut found, mut frames) = (0usize, 0usize, 0u64);
    for seed in 0..3u64 {
        let scene =
            sample_scene(&objects, &SamplerConfig::default(), 2000 + seed).map_err(|e| anyhow::anyhow!("{e}"))?;
        let truth =
            render_view_labelled(&scene, &objects, 0, &k, &NoiseConfig::default(), LabelKind::Class, &mut target)
                .map_err(|e| anyhow::anyhow!("{e}"))?;
        let sequence = send_rendered(&mut producer, &k, &target)?;
        let msg = wait_for_sequence(&mut consumer, sequence, Duration::from_secs(120))?;
        frames += 1;
        assert!(msg.is_ok(), "frame {sequence}: status {:#x}", msg.status);
        assert!(!msg.objects().is_empty(), "frame {sequence}: no objects found without labels");
        for gt in truth.objects.iter().filter(|o| o.visible_fraction >= MIN_VISIBLE_FRACTION) {
            let metric = &metrics[gt.class_id as usize - 1];
            let diameter = objects.objects[gt.class_id as usize - 1].diameter;
            let best = best_add_s(&msg, gt.class_id, &gt.pose, metric);
            expected += 1;
            if best < 0.1 * diameter {
                found += 1;
            }
        }
    }
    eprintln!("{found} of {expected} visible objects found with ADD-S < 10% diameter over {frames} frames");
    assert!(expected >= 5, "too few visible objects: {expected}");
    assert!(found as f64 >= MIN_FOUND_SHARE * expected as f64, "only {found} of {expected} objects found");

    let stats = query_stats(&env, Duration::from_secs(5))?;
    let seg = &stats.since_start[Stage::Segmentation as usize];
    assert_eq!(seg.count, frames, "segmentation time recorded once per frame: {stats:?}");
    assert!(seg.max_ns > 0, "{seg:?}");
    Ok(())
}

/// A camera that turns dim and back (auto exposure is on by default): the
/// daemon says so once each way in its log, not once per frame.
#[test]
fn a_camera_turning_dim_and_back_is_logged_once_each_way() -> anyhow::Result<()> {
    let env = TestEnv::new("dim-log")?;
    let config = env.write_daemon_config(&format!(
        "kind = \"net\"\nweights = {:?}\nmasks = \"auto\"\nmax_instances = 8\nworker_threads = 2\ndeadline_aware = false",
        weights().canonicalize()?
    ))?;
    let log = env.dir.path().join("fuseposed.log");
    let mut daemon = spawn_daemon(&env, &config, Some(&log))?;
    query_stats(&env, Duration::from_secs(30))?;

    let objects = fusepose_scene::builtin::builtin_objects();
    let k = Intrinsics::YCB_VIDEO;
    let ipc = Ipc::new(&env.ipc_options())?;
    let mut producer = Producer::create(&ipc, "cam0", rendered_layout(&k))?;
    let mut consumer = Consumer::open(&ipc, "cam0")?;
    let mut target = RenderTarget::for_intrinsics(&k);
    let scene = sample_scene(&objects, &SamplerConfig::default(), 2100).map_err(|e| anyhow::anyhow!("{e}"))?;
    render_view_labelled(&scene, &objects, 0, &k, &NoiseConfig::default(), LabelKind::Class, &mut target)
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let bright = target.rgb().to_vec();
    // About -3 EV: sRGB codes at a third.
    let dim: Vec<u8> = bright.iter().map(|&v| v / 3).collect();
    for colour in [&bright, &dim, &dim, &bright, &bright] {
        target.rgb_mut().copy_from_slice(colour);
        let sequence = send_rendered(&mut producer, &k, &target)?;
        let msg = wait_for_sequence(&mut consumer, sequence, Duration::from_secs(120))?;
        assert!(msg.is_ok(), "frame {sequence}: status {:#x}", msg.status);
    }
    daemon.signal(libc::SIGTERM);
    daemon.wait_timeout(Duration::from_secs(10))?;
    let text = std::fs::read_to_string(&log)?;
    let count = |needle: &str| text.lines().filter(|l| l.contains(needle)).count();
    assert_eq!(count("colour corrected before the networks"), 1, "one line when the camera turned dim:\n{text}");
    assert_eq!(count("colour no longer corrected"), 1, "one line when it was bright again:\n{text}");
    Ok(())
}
