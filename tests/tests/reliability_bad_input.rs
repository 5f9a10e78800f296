//! Every class of bad frame from issue 8 (and the instance-label faults of
//! issue 24), sent to a running `fuseposed` (separate process, ICP estimator
//! on the built-in objects): each is rejected with its own reason in the pose
//! message and in the stats, and the next good frame is served again. The
//! producer and consumer are this test process.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use fusepose_client::{
    ColorFormat, Consumer, DepthFormat, FrameHeader, FrameLayout, InvalidReason, Ipc, LabelFormat, PlaneRef, PoseFlags,
    PoseMessage, PoseStatus, Producer, camera_id, monotonic_ns,
};
use fusepose_tests::{TestEnv, query_stats, start_daemon};

const W: u32 = 64;
const H: u32 = 48;
const INTRINSICS: (f64, f64, f64, f64) = (60.0, 60.0, 31.5, 23.5);

/// f32 depth with u8 labels: the largest layout used, so the u16 variants fit in its samples.
fn f32_layout() -> FrameLayout {
    FrameLayout {
        width: W,
        height: H,
        color_format: ColorFormat::Rgb8,
        depth_format: DepthFormat::F32,
        depth_scale: 1.0,
        labels: Some(LabelFormat::U8),
    }
}

fn u16_layout() -> FrameLayout {
    FrameLayout { depth_format: DepthFormat::U16, depth_scale: 0.001, ..f32_layout() }
}

/// f32 depth with instance labels: ids 1..=2 (table of 3 entries).
fn instance_layout() -> FrameLayout {
    FrameLayout { labels: Some(LabelFormat::InstanceU16 { max_instances: 2 }), ..f32_layout() }
}

/// The producer's frame size: room for every frame sent, plus spare bytes.
fn largest_layout() -> FrameLayout {
    FrameLayout { labels: Some(LabelFormat::InstanceU16 { max_instances: 64 }), ..f32_layout() }
}

/// The object's pixels in the test frames: columns 24..40, rows 18..30.
fn on_object(i: usize) -> bool {
    let (u, v) = (i as u32 % W, i as u32 / W);
    (24..40).contains(&u) && (18..30).contains(&v)
}

/// Depth of the test frames: a table at 0.8 m and the object's top 3 cm
/// nearer (an object coplanar with the table is a picture on it, and the
/// daemon's support floor takes it for the table).
fn object_depth(i: usize) -> f32 {
    if on_object(i) { 0.77 } else { 0.8 }
}

/// A frame as header + payload bytes: a 16x12 object of class 1 standing 3 cm proud of a table at 0.8 m.
struct RawFrame {
    header: FrameHeader,
    payload: Vec<u8>,
}

impl RawFrame {
    fn good(layout: FrameLayout, sequence: u64) -> Self {
        let mut header = layout.header(camera_id("cam0"));
        (header.fx, header.fy, header.cx, header.cy) = INTRINSICS;
        header.sequence = sequence;
        let mut frame = Self { header, payload: vec![0; layout.payload_len()] };
        frame.fill_depth(object_depth);
        let labels = layout.planes()[2];
        for v in 18..30 {
            for u in 24..40 {
                frame.payload[labels.offset as usize + (v * W + u) as usize] = 1;
            }
        }
        frame
    }

    /// Two touching 8x12 instances (ids 1 and 2) of one object in the middle
    /// of the frame, 3 cm proud of a table at 0.8 m; `classes` is the class table sent.
    fn instances(sequence: u64, classes: [u16; 3]) -> Self {
        let layout = instance_layout();
        let mut header = layout.header(camera_id("cam0"));
        (header.fx, header.fy, header.cx, header.cy) = INTRINSICS;
        header.sequence = sequence;
        let mut frame = Self { header, payload: vec![0; layout.payload_len()] };
        frame.fill_depth(object_depth);
        let ids = frame.header.labels.offset as usize;
        for v in 18..30 {
            for u in 24..40 {
                let id: u16 = if u < 32 { 1 } else { 2 };
                let at = ids + 2 * (v * W + u) as usize;
                frame.payload[at..at + 2].copy_from_slice(&id.to_le_bytes());
            }
        }
        frame.set_classes(classes);
        frame
    }

    fn set_classes(&mut self, classes: [u16; 3]) {
        let table = self.header.instance_classes.offset as usize;
        for (i, c) in classes.iter().enumerate() {
            self.payload[table + 2 * i..table + 2 * i + 2].copy_from_slice(&c.to_le_bytes());
        }
    }

    /// Writes every depth value (metres) in the header's format.
    fn fill_depth(&mut self, metres: impl Fn(usize) -> f32) {
        let depth = self.header.depth;
        let n = (W * H) as usize;
        for i in 0..n {
            let z = metres(i);
            if self.header.depth_format == DepthFormat::F32 as u8 {
                let at = depth.offset as usize + 4 * i;
                self.payload[at..at + 4].copy_from_slice(&z.to_le_bytes());
            } else {
                let at = depth.offset as usize + 2 * i;
                let units = (z / self.header.depth_scale) as u16;
                self.payload[at..at + 2].copy_from_slice(&units.to_le_bytes());
            }
        }
    }
}

struct Rig {
    producer: Producer,
    consumer: Consumer,
    next_sequence: u64,
}

impl Rig {
    /// Sends `frame` (next sequence number and capture time now, unless set)
    /// and returns the daemon's answer to it.
    fn send(&mut self, mut frame: RawFrame) -> anyhow::Result<PoseMessage> {
        if frame.header.sequence == 0 {
            frame.header.sequence = self.sequence();
        }
        if frame.header.capture_time_ns == 0 {
            frame.header.capture_time_ns = monotonic_ns();
        }
        let sequence = frame.header.sequence;
        self.producer.send_raw(frame.header, &frame.payload)?;
        let deadline = Instant::now() + Duration::from_secs(10);
        let mut batch = Vec::new();
        while Instant::now() < deadline {
            if !self.consumer.wait_ready(Duration::from_millis(100))? {
                continue;
            }
            batch.clear();
            self.consumer.drain(&mut batch)?;
            if let Some(msg) = batch.iter().find(|m| m.frame_sequence == sequence) {
                return Ok(*msg);
            }
        }
        anyhow::bail!("no answer to frame {sequence}")
    }

    fn sequence(&mut self) -> u64 {
        self.next_sequence += 1;
        self.next_sequence
    }

    /// A good frame, numbered when sent.
    fn good(&mut self, layout: FrameLayout) -> RawFrame {
        RawFrame::good(layout, 0)
    }

    /// A good f32 frame with `edit` applied to its header.
    fn edited(&mut self, edit: impl FnOnce(&mut FrameHeader)) -> RawFrame {
        let mut f = self.good(f32_layout());
        edit(&mut f.header);
        f
    }

    /// A good instance-label frame (two instances of class 1) with `edit` applied to its header.
    fn edited_instances(&mut self, edit: impl FnOnce(&mut FrameHeader)) -> RawFrame {
        let mut f = RawFrame::instances(0, [0, 1, 1]);
        edit(&mut f.header);
        f
    }
}

#[test]
fn every_bad_input_class_gets_its_own_reason_and_later_frames_are_served() -> anyhow::Result<()> {
    let env = TestEnv::new("badinput")?;
    // ICP on the built-in objects: label ids above their count are out of range.
    // Verification off: the frames' objects are patches of one flat depth
    // plane, which verification rightly refuses as markings on a surface
    // (estimator/tests/verify.rs); this test is about the wire.
    let config = env.write_daemon_config("kind = \"icp\"\nmin_pixels = 20\nnum_points = 64\nverify = \"off\"")?;
    let _daemon = start_daemon(&env, &config)?;
    let ipc = Ipc::new(&env.ipc_options())?;
    let producer = Producer::create(&ipc, "cam0", largest_layout())?;
    let consumer = Consumer::open(&ipc, "cam0")?;
    let mut rig = Rig { producer, consumer, next_sequence: 0 };

    let first = rig.good(f32_layout());
    let msg = rig.send(first)?;
    assert!(msg.is_ok(), "a good frame is served: status {}", msg.status);

    type Case = (&'static str, InvalidReason, RawFrame);
    let mut cases: Vec<Case> = Vec::new();
    let full = f32_layout().payload_len();
    cases.push(("wrong wire version", InvalidReason::VersionMismatch, rig.edited(|h| h.format_version = 1)));
    cases.push((
        "previous wire version (no instance labels)",
        InvalidReason::VersionMismatch,
        rig.edited(|h| h.format_version = 2),
    ));
    cases.push(("width 0", InvalidReason::BadSize, rig.edited(|h| h.width = 0)));
    cases.push(("height huge", InvalidReason::BadSize, rig.edited(|h| h.height = 100_000)));
    cases.push((
        "plane offset outside the payload",
        InvalidReason::PlaneOutOfBounds,
        rig.edited(|h| h.depth.offset = full as u32 + 8),
    ));
    cases.push((
        "plane length beyond the payload",
        InvalidReason::PlaneOutOfBounds,
        rig.edited(|h| h.labels.len = u32::MAX),
    ));
    let mut truncated = rig.good(f32_layout());
    truncated.payload.truncate(full - 1000);
    cases.push(("payload shorter than the header claims", InvalidReason::PayloadTruncated, truncated));
    for (name, fx) in
        [("fx 0", 0.0), ("fx negative", -525.0), ("fx NaN", f64::NAN), ("fx inf", f64::INFINITY), ("fx 1e-300", 1e-300)]
    {
        cases.push((name, InvalidReason::BadFocalLength, rig.edited(|h| h.fx = fx)));
    }
    cases.push(("fy 0", InvalidReason::BadFocalLength, rig.edited(|h| h.fy = 0.0)));
    cases.push((
        "principal point far outside",
        InvalidReason::BadPrincipalPoint,
        rig.edited(|h| h.cx = 10.0 * W as f64),
    ));
    cases.push(("principal point NaN", InvalidReason::BadPrincipalPoint, rig.edited(|h| h.cy = f64::NAN)));
    cases.push(("unknown colour format", InvalidReason::UnknownFormat, rig.edited(|h| h.color_format = 9)));
    cases.push(("unknown depth format", InvalidReason::UnknownFormat, rig.edited(|h| h.depth_format = 0)));
    let mut zero = rig.good(u16_layout());
    zero.fill_depth(|_| 0.0);
    cases.push(("all-zero depth (u16)", InvalidReason::DepthEmpty, zero));
    let mut zero = rig.good(f32_layout());
    zero.fill_depth(|_| 0.0);
    cases.push(("all-zero depth (f32)", InvalidReason::DepthEmpty, zero));
    let mut nan = rig.good(f32_layout());
    nan.fill_depth(|i| if i % 2 == 0 { f32::NAN } else { f32::INFINITY });
    cases.push(("depth all NaN/inf (f32)", InvalidReason::DepthNonFinite, nan));
    let mut labels = rig.good(f32_layout());
    let at = f32_layout().planes()[2].offset as usize;
    labels.payload[at + 5] = 200;
    cases.push(("label id beyond the classes", InvalidReason::LabelOutOfRange, labels));
    cases.push((
        "label plane claimed but absent",
        InvalidReason::LabelsMissing,
        rig.edited(|h| h.labels = PlaneRef::default()),
    ));
    let now = monotonic_ns();
    cases.push((
        "capture time in the future",
        InvalidReason::CaptureInFuture,
        rig.edited(|h| h.capture_time_ns = now + 60_000_000_000),
    ));
    cases.push(("capture time far in the past", InvalidReason::CaptureTooOld, rig.edited(|h| h.capture_time_ns = 1)));
    cases.push(("unknown camera", InvalidReason::WrongCamera, rig.edited(|h| h.camera_id = camera_id("cam9"))));
    cases.push(("bad magic", InvalidReason::BadMagic, rig.edited(|h| h.magic = 0xDEAD_BEEF)));
    cases.push(("header size", InvalidReason::HeaderSize, rig.edited(|h| h.header_size = 64)));
    cases.push(("depth scale NaN", InvalidReason::BadDepthScale, rig.edited(|h| h.depth_scale = f32::NAN)));
    cases.push(("colour plane length", InvalidReason::PlaneLength, rig.edited(|h| h.color.len -= 3)));
    cases.push(("depth plane misaligned", InvalidReason::PlaneMisaligned, rig.edited(|h| h.depth.offset += 2)));
    cases.push((
        "label plane overlaps depth",
        InvalidReason::PlaneOverlap,
        rig.edited(|h| h.labels.offset = h.depth.offset),
    ));

    // Instance labels (issue 24): structural faults are the decoder's, the
    // plane's contents the daemon's content check.
    cases.push((
        "instance class table missing",
        InvalidReason::InstanceTableMissing,
        rig.edited_instances(|h| h.instance_classes = PlaneRef::default()),
    ));
    cases.push((
        "instance class table shorter than instance_count + 1",
        InvalidReason::InstanceTableLength,
        rig.edited_instances(|h| h.instance_classes.len -= 2),
    ));
    cases.push((
        "instance_count larger than the table",
        InvalidReason::InstanceTableLength,
        rig.edited_instances(|h| h.instance_count = 5),
    ));
    let mut misaligned = rig.edited_instances(|h| h.instance_classes.offset += 1);
    misaligned.payload.extend_from_slice(&[0; 8]);
    cases.push(("instance class table misaligned", InvalidReason::InstanceTableMisaligned, misaligned));
    cases.push((
        "instance labels with has_labels = 0",
        InvalidReason::InstanceLabelsInconsistent,
        rig.edited_instances(|h| h.has_labels = 0),
    ));
    cases.push((
        "instance_count on a class-label frame",
        InvalidReason::InstanceLabelsInconsistent,
        rig.edited(|h| h.instance_count = 2),
    ));
    cases.push((
        "instance class table on a class-label frame",
        InvalidReason::InstanceLabelsInconsistent,
        rig.edited(|h| h.instance_classes = PlaneRef { offset: f32_layout().payload_len() as u32, len: 4 }),
    ));
    let mut beyond = RawFrame::instances(0, [0, 1, 1]);
    let at = beyond.header.labels.offset as usize + 2 * (20 * W + 30) as usize;
    beyond.payload[at..at + 2].copy_from_slice(&3u16.to_le_bytes());
    cases.push(("instance id beyond the class table", InvalidReason::InstanceBeyondTable, beyond));
    cases.push(("instance with class 0", InvalidReason::InstanceClassUnknown, RawFrame::instances(0, [0, 1, 0])));
    cases.push((
        "instance of a class beyond the objects",
        InvalidReason::InstanceClassUnknown,
        RawFrame::instances(0, [0, 200, 1]),
    ));

    let mut expected: BTreeMap<usize, u64> = BTreeMap::new();
    for (name, reason, frame) in cases {
        let msg = rig.send(frame)?;
        assert_eq!(msg.status, PoseStatus::INVALID_FRAME, "{name}: status {}", msg.status);
        assert_eq!(msg.invalid(), Some(reason), "{name}");
        assert_eq!(msg.object_count, 0, "{name}");
        *expected.entry(reason as usize).or_default() += 1;
        // The daemon keeps serving: the next good frame is OK.
        let good = rig.good(f32_layout());
        let msg = rig.send(good)?;
        assert!(msg.is_ok(), "after {name}: status {} reason {:?}", msg.status, msg.invalid());
    }

    // Sequence numbers: a repeat and a step back from the same publisher are refused.
    let last = rig.next_sequence;
    for (name, sequence) in [("repeated sequence", last), ("sequence backwards", 1)] {
        let msg = rig.send(RawFrame::good(f32_layout(), sequence))?;
        assert_eq!(msg.invalid(), Some(InvalidReason::SequenceRegression), "{name}: status {}", msg.status);
        *expected.entry(InvalidReason::SequenceRegression as usize).or_default() += 1;
    }
    let good = rig.good(f32_layout());
    assert!(rig.send(good)?.is_ok(), "a larger sequence number is served again");

    // A good instance frame: two touching instances of one class, two poses,
    // masks marked as the frame's own.
    let msg = rig.send(RawFrame::instances(0, [0, 1, 1]))?;
    assert!(msg.is_ok(), "instance frame: status {} reason {:?}", msg.status, msg.invalid());
    let objects = msg.objects();
    assert_eq!(objects.len(), 2, "{objects:?}");
    assert_ne!(objects[0].instance_id, objects[1].instance_id);
    for o in objects {
        assert_eq!(o.class_id, 1);
        assert_ne!(o.flags & PoseFlags::FROM_INSTANCE_LABELS, 0);
        assert_eq!(o.fit_score.is_nan(), o.depth_residual_m.is_nan(), "verified: both scores, else neither");
        assert_eq!(o.mask_pixels, 96);
    }

    // Some NaN/inf among valid f32 readings are holes (protocol), not an error.
    let mut holes = rig.good(f32_layout());
    holes.fill_depth(|i| if i % 3 == 0 { f32::NAN } else { object_depth(i) });
    let msg = rig.send(holes)?;
    assert!(msg.is_ok(), "f32 depth with NaN holes: status {} reason {:?}", msg.status, msg.invalid());

    let stats = query_stats(&env, Duration::from_secs(5))?;
    for reason in InvalidReason::ALL {
        let want = expected.get(&(reason as usize)).copied().unwrap_or(0);
        assert_eq!(stats.invalid_by_reason[reason as usize], want, "stats for {}", reason.name());
    }
    assert_eq!(stats.frames_invalid, expected.values().sum::<u64>());
    assert_eq!(stats.poses_non_finite, 0);
    Ok(())
}
