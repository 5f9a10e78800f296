//! The daemon's per-frame path in one process, with a trivial in-test
//! estimator: wire conversion of poses (quaternion order, units, bbox), stage
//! times, keep-newest draining, rejection of a malformed frame.

use std::f64::consts::FRAC_PI_2;
use std::time::Duration;

use fusepose_client::{
    Consumer, DepthMut, FrameLayout, InvalidReason, Ipc, IpcOptions, LabelFormat, LabelsMut, PlaneRef, PoseStatus,
    Producer, Stage,
};
use fusepose_daemon::camera::{CameraPorts, CameraState};
use fusepose_daemon::engine::PoseEngine;
use fusepose_estimator::{EstimateError, Estimator, FrameView, ObjectPose, PoseSet, Workspace, WorkspaceConfig};
use nalgebra::{UnitQuaternion, Vector3};

/// Puts every instance at (0.1, -0.2, 1.0) m, rotated 90° about z.
struct FixedPose;

impl Estimator for FixedPose {
    fn name(&self) -> &str {
        "fixed"
    }

    fn estimate(&mut self, _frame: &FrameView<'_>, ws: &mut Workspace, out: &mut PoseSet) -> Result<(), EstimateError> {
        out.clear();
        for (i, inst) in ws.instances.iter().enumerate() {
            out.push(ObjectPose {
                class_id: inst.class_id,
                instance_id: i as u16,
                rotation: UnitQuaternion::from_axis_angle(&Vector3::z_axis(), FRAC_PI_2),
                translation: Vector3::new(0.1, -0.2, 1.0),
                confidence: 0.5,
                mask_pixels: inst.pixels,
                bbox: inst.bbox,
                iterations: 7,
            });
        }
        Ok(())
    }
}

const W: u32 = 64;
const H: u32 = 48;

fn send_frame(producer: &mut Producer) -> u64 {
    let mut frame = producer.loan().unwrap();
    frame.set_intrinsics(60.0, 60.0, 31.5, 23.5);
    let planes = frame.planes_mut();
    planes.color.fill(128);
    if let DepthMut::U16(depth) = planes.depth {
        depth.fill(1000);
    }
    if let Some(LabelsMut::U8(labels)) = planes.labels {
        labels.fill(0);
        for v in 10..20 {
            for u in 20..32 {
                labels[(v * W + u) as usize] = 3;
            }
        }
    }
    frame.send().unwrap()
}

#[test]
fn frames_become_pose_messages_with_exact_wire_values() {
    let dir = tempfile::tempdir().unwrap();
    let options = IpcOptions {
        root_path: Some(dir.path().to_owned()),
        prefix: Some(format!("fpd{}_", std::process::id())),
        ..Default::default()
    };
    let ipc = Ipc::new(&options).unwrap();
    let ports = CameraPorts::open(&ipc, "cam0").unwrap();
    let workspace = WorkspaceConfig { max_instances: 4, num_points: 64, crop_size: 16, ..WorkspaceConfig::default() };
    let engine = PoseEngine::with_estimator(Box::new(FixedPose), workspace, Stage::Refine).unwrap();
    let mut state = CameraState::new("cam0", engine, 1_000_000_000, fusepose_client::monotonic_ns());
    let layout = FrameLayout { width: W, height: H, labels: Some(LabelFormat::U8), ..FrameLayout::vga_rgbd() };
    let mut producer = Producer::create(&ipc, "cam0", layout).unwrap();
    let mut consumer = Consumer::open(&ipc, "cam0").unwrap();

    // Two frames before the daemon looks: only the newest is processed.
    send_frame(&mut producer);
    let newest = send_frame(&mut producer);
    assert!(state.process_newest(&ports));
    assert!(!state.process_newest(&ports), "nothing left to process");
    assert_eq!((state.counters.received, state.counters.skipped_stale, state.counters.processed), (2, 1, 1));

    let msg = consumer.wait(Duration::from_secs(1)).unwrap().expect("a pose message");
    assert_eq!(msg.frame_sequence, newest);
    assert_eq!(msg.status, PoseStatus::OK);
    assert_eq!(msg.camera_id, fusepose_client::camera_id("cam0"));
    assert_eq!(msg.object_count, 1);
    let o = msg.objects()[0];
    assert_eq!((o.class_id, o.instance_id, o.refine_iterations, o.mask_pixels), (3, 0, 7, 120));
    assert_eq!(o.bbox, [20, 10, 31, 19]);
    let expected_q = [0.0, 0.0, (FRAC_PI_2 / 2.0).sin(), (FRAC_PI_2 / 2.0).cos()];
    for (got, want) in o.quaternion.iter().zip(expected_q) {
        assert!((got - want).abs() < 1e-12, "quaternion {:?} is not [x, y, z, w] = {expected_q:?}", o.quaternion);
    }
    assert_eq!(o.translation_m, [0.1, -0.2, 1.0]);
    assert!(msg.stage_ns[Stage::Sampling as usize] > 0 && msg.stage_ns[Stage::Refine as usize] > 0);
    assert_eq!(msg.stage_ns[Stage::Network as usize], 0);
    assert!(msg.capture_time_ns <= msg.received_time_ns && msg.received_time_ns <= msg.published_time_ns);

    // A colour plane one byte short: rejected with its reason, counted, answered.
    let mut header = layout.header(fusepose_client::camera_id("cam0"));
    (header.fx, header.fy, header.cx, header.cy) = (60.0, 60.0, 31.5, 23.5);
    header.sequence = 99;
    header.color = PlaneRef { offset: 0, len: header.color.len - 1 };
    producer.send_raw(header, &vec![0u8; layout.payload_len()]).unwrap();
    assert!(state.process_newest(&ports));
    let msg = consumer.wait(Duration::from_secs(1)).unwrap().expect("an invalid-frame message");
    assert_eq!(msg.frame_sequence, 99);
    assert_eq!(msg.status, PoseStatus::INVALID_FRAME);
    assert_eq!(msg.invalid(), Some(InvalidReason::PlaneLength));
    assert_eq!(msg.object_count, 0);
    assert_eq!(state.counters.invalid_by_reason[InvalidReason::PlaneLength as usize], 1);

    let stats = state.snapshot(fusepose_client::monotonic_ns());
    assert_eq!(stats.frames_invalid, 1);
    assert_eq!(stats.frames_processed, 1);
    assert_eq!(stats.since_start[fusepose_client::STAGE_COUNT].count, 1);

    // iceoryx2 leaves a node-management object per prefix in /dev/shm: remove ours.
    drop((consumer, producer, state, ports, ipc));
    for entry in std::fs::read_dir("/dev/shm").unwrap().flatten() {
        if entry.file_name().to_string_lossy().starts_with(options.prefix.as_deref().unwrap()) {
            let _ = std::fs::remove_file(entry.path());
        }
    }
}
