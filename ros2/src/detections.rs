//! Pose messages (one camera's, or the cell's) → `vision_msgs/Detection3DArray`
//! and `tf2_msgs/TFMessage`.
//!
//! Per object: `results[0].hypothesis.class_id` = the object's name in the
//! daemon's object set, `score` = confidence, `results[0].pose.pose` = the
//! pose (object → camera optical frame), `bbox.center` = the pose applied to
//! the centre of the object's bounding box (= the pose for models centred on
//! their origin, as the built-in set is), `bbox.size` = the box's extents,
//! `id` = `<object>_<instance>` (instances are numbered per frame, largest
//! mask first: not stable across frames, see docs/PROTOCOL.md).

use fusepose_client::{CellObject, CellPoseMessage, PoseMessage};

use crate::msg::{
    BoundingBox3D, Detection3D, Detection3DArray, Header, ObjectHypothesis, ObjectHypothesisWithPose, Point, Pose,
    PoseWithCovariance, Quaternion, TfMessage, Time, Transform, TransformStamped, Vector3,
};

/// What the bridge knows about one object class (class id = index + 1).
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectInfo {
    pub name: String,
    /// Extents of the axis-aligned bounding box in the object frame, metres.
    pub size: [f64; 3],
    /// Centre of that box in the object frame, metres.
    pub box_centre: [f64; 3],
}

/// The object classes of the daemon's set, in class-id order.
#[derive(Clone, Debug, Default)]
pub struct ObjectTable {
    pub objects: Vec<ObjectInfo>,
}

impl ObjectTable {
    /// The object of class `class_id` (1-based), if the set has it.
    pub fn get(&self, class_id: u16) -> Option<&ObjectInfo> {
        (class_id as usize).checked_sub(1).and_then(|i| self.objects.get(i))
    }

    /// The class name (`class_<id>` for ids beyond the set).
    pub fn name(&self, class_id: u16) -> String {
        self.get(class_id).map(|o| o.name.clone()).unwrap_or_else(|| format!("class_{class_id}"))
    }
}

fn rotate(q: [f64; 4], v: [f64; 3]) -> [f64; 3] {
    // v' = v + 2w (u × v) + 2 u × (u × v), u = (x, y, z).
    let [x, y, z, w] = q;
    let cross =
        |a: [f64; 3], b: [f64; 3]| [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    let u = [x, y, z];
    let t = cross(u, v).map(|c| 2.0 * c);
    let ut = cross(u, t);
    [v[0] + w * t[0] + ut[0], v[1] + w * t[1] + ut[1], v[2] + w * t[2] + ut[2]]
}

fn pose_of(quaternion: [f64; 4], translation_m: [f64; 3]) -> Pose {
    let [x, y, z] = translation_m;
    let [qx, qy, qz, qw] = quaternion;
    Pose { position: Point { x, y, z }, orientation: Quaternion { x: qx, y: qy, z: qz, w: qw } }
}

/// One object's detection: pose `quaternion` / `translation_m` in `header`'s frame.
fn detection(
    header: Header,
    objects: &ObjectTable,
    class_id: u16,
    quaternion: [f64; 4],
    translation_m: [f64; 3],
    score: f32,
    id: String,
) -> Detection3D {
    let info = objects.get(class_id);
    let pose = pose_of(quaternion, translation_m);
    let centre_offset = rotate(quaternion, info.map_or([0.0; 3], |i| i.box_centre));
    let mut center = pose;
    center.position.x += centre_offset[0];
    center.position.y += centre_offset[1];
    center.position.z += centre_offset[2];
    let [sx, sy, sz] = info.map_or([0.0; 3], |i| i.size);
    Detection3D {
        header,
        results: vec![ObjectHypothesisWithPose {
            hypothesis: ObjectHypothesis { class_id: objects.name(class_id), score: score as f64 },
            pose: PoseWithCovariance { pose, covariance: [0.0; 36] },
        }],
        bbox: BoundingBox3D { center, size: Vector3 { x: sx, y: sy, z: sz } },
        id,
    }
}

/// The detections of one pose message, stamped `stamp` in frame `frame_id`.
/// Rejected or failed frames give an empty array (still published: "nothing seen at this time").
pub fn detections(msg: &PoseMessage, objects: &ObjectTable, stamp: Time, frame_id: &str) -> Detection3DArray {
    let header = Header { stamp, frame_id: frame_id.to_owned() };
    let detections = msg
        .objects()
        .iter()
        .map(|o| {
            let id = format!("{}_{}", objects.name(o.class_id), o.instance_id);
            detection(header.clone(), objects, o.class_id, o.quaternion, o.translation_m, o.confidence, id)
        })
        .collect();
    Detection3DArray { header, detections }
}

/// A cell object's id: `<object>_<camera id, 8 hex digits>_<instance>` of
/// the view whose pose it carries (stable while that camera tracks it).
pub fn cell_object_id(o: &CellObject, objects: &ObjectTable) -> String {
    format!("{}_{:08x}_{}", objects.name(o.class_id), o.views[0].camera_id, o.views[0].instance_id)
}

/// The detections of one cell message in the cell frame `frame_id`: each
/// stamped with its newest view's capture time (`stamp_of` maps
/// `CLOCK_MONOTONIC` ns to ROS time), the array with the newest of all (or
/// the publish time when empty).
pub fn cell_detections(
    msg: &CellPoseMessage,
    objects: &ObjectTable,
    mut stamp_of: impl FnMut(u64) -> Time,
    frame_id: &str,
) -> Detection3DArray {
    let valid = &msg.objects[..(msg.object_count as usize).min(msg.objects.len())];
    let newest = valid.iter().map(|o| o.newest_capture_time_ns).max().unwrap_or(msg.published_time_ns);
    let detections = valid
        .iter()
        .map(|o| {
            let header = Header { stamp: stamp_of(o.newest_capture_time_ns), frame_id: frame_id.to_owned() };
            let id = cell_object_id(o, objects);
            detection(header, objects, o.class_id, o.quaternion, o.translation_m, o.confidence, id)
        })
        .collect();
    Detection3DArray { header: Header { stamp: stamp_of(newest), frame_id: frame_id.to_owned() }, detections }
}

/// One transform per cell object: parent `frame_id` (the cell), child
/// `<prefix>/<cell object id>` ([`cell_object_id`]), stamped as its detection.
pub fn cell_transforms(
    msg: &CellPoseMessage,
    objects: &ObjectTable,
    mut stamp_of: impl FnMut(u64) -> Time,
    frame_id: &str,
    prefix: &str,
) -> TfMessage {
    let valid = &msg.objects[..(msg.object_count as usize).min(msg.objects.len())];
    let transforms = valid
        .iter()
        .map(|o| {
            let pose = pose_of(o.quaternion, o.translation_m);
            TransformStamped {
                header: Header { stamp: stamp_of(o.newest_capture_time_ns), frame_id: frame_id.to_owned() },
                child_frame_id: format!("{prefix}/{}", cell_object_id(o, objects)),
                transform: Transform {
                    translation: Vector3 { x: pose.position.x, y: pose.position.y, z: pose.position.z },
                    rotation: pose.orientation,
                },
            }
        })
        .collect();
    TfMessage { transforms }
}

/// One transform per object: parent `frame_id`, child `<prefix>/<object>_<instance>`.
pub fn transforms(msg: &PoseMessage, objects: &ObjectTable, stamp: Time, frame_id: &str, prefix: &str) -> TfMessage {
    let transforms = msg
        .objects()
        .iter()
        .map(|o| {
            let pose = pose_of(o.quaternion, o.translation_m);
            TransformStamped {
                header: Header { stamp, frame_id: frame_id.to_owned() },
                child_frame_id: format!("{prefix}/{}_{}", objects.name(o.class_id), o.instance_id),
                transform: Transform {
                    translation: Vector3 { x: pose.position.x, y: pose.position.y, z: pose.position.z },
                    rotation: pose.orientation,
                },
            }
        })
        .collect();
    TfMessage { transforms }
}

#[cfg(test)]
mod tests {
    use fusepose_client::{CellView, PoseStatus, WireObjectPose};

    use super::*;

    fn table() -> ObjectTable {
        ObjectTable {
            objects: vec![
                ObjectInfo { name: "mug".into(), size: [0.1, 0.08, 0.12], box_centre: [0.0; 3] },
                ObjectInfo { name: "box".into(), size: [0.2, 0.1, 0.05], box_centre: [0.0, 0.0, 0.025] },
            ],
        }
    }

    fn message() -> PoseMessage {
        let mut msg = PoseMessage { object_count: 2, status: PoseStatus::OK, ..PoseMessage::default() };
        // 90° about z.
        let h = std::f64::consts::FRAC_1_SQRT_2;
        msg.objects[0] = WireObjectPose {
            class_id: 2,
            instance_id: 0,
            confidence: 0.75,
            quaternion: [0.0, 0.0, h, h],
            translation_m: [0.1, -0.2, 0.9],
            ..Default::default()
        };
        msg.objects[1] = WireObjectPose {
            class_id: 9,
            instance_id: 1,
            confidence: 0.5,
            quaternion: [0.0, 0.0, 0.0, 1.0],
            translation_m: [0.0, 0.0, 0.5],
            ..Default::default()
        };
        msg
    }

    #[test]
    fn each_object_becomes_a_detection_with_its_name_score_pose_and_box() {
        let stamp = Time { sec: 7, nanosec: 8 };
        let out = detections(&message(), &table(), stamp, "cam0_color_optical_frame");
        assert_eq!(out.header.stamp, stamp);
        assert_eq!(out.header.frame_id, "cam0_color_optical_frame");
        assert_eq!(out.detections.len(), 2);
        let d = &out.detections[0];
        assert_eq!(d.header, out.header);
        assert_eq!(d.results.len(), 1);
        assert_eq!(d.results[0].hypothesis.class_id, "box");
        assert_eq!(d.results[0].hypothesis.score, 0.75);
        let p = d.results[0].pose.pose;
        assert_eq!([p.position.x, p.position.y, p.position.z], [0.1, -0.2, 0.9]);
        assert_eq!(p.orientation.z, std::f64::consts::FRAC_1_SQRT_2);
        assert_eq!([d.bbox.size.x, d.bbox.size.y, d.bbox.size.z], [0.2, 0.1, 0.05]);
        // The box centre (0, 0, 0.025) is on the rotation axis: only z moves.
        assert!((d.bbox.center.position.z - 0.925).abs() < 1e-12 && (d.bbox.center.position.x - 0.1).abs() < 1e-12);
        assert_eq!(d.id, "box_0");
        // A class beyond the set keeps its id as a name and gets an empty box.
        assert_eq!(out.detections[1].results[0].hypothesis.class_id, "class_9");
        assert_eq!(out.detections[1].bbox.size, Vector3::default());
    }

    #[test]
    fn box_centre_offsets_are_rotated_into_the_camera_frame() {
        let h = std::f64::consts::FRAC_1_SQRT_2;
        let v = rotate([0.0, 0.0, h, h], [1.0, 0.0, 0.0]);
        assert!((v[0]).abs() < 1e-12 && (v[1] - 1.0).abs() < 1e-12 && v[2].abs() < 1e-12, "{v:?}");
    }

    #[test]
    fn rejected_frames_give_an_empty_array_and_tf_names_children_per_instance() {
        let rejected = PoseMessage { status: PoseStatus::INVALID_FRAME, ..PoseMessage::default() };
        assert!(detections(&rejected, &table(), Time::default(), "f").detections.is_empty());
        let tf = transforms(&message(), &table(), Time { sec: 1, nanosec: 2 }, "f", "fusepose/cam0");
        let children: Vec<&str> = tf.transforms.iter().map(|t| t.child_frame_id.as_str()).collect();
        assert_eq!(children, ["fusepose/cam0/box_0", "fusepose/cam0/class_9_1"]);
        assert_eq!(tf.transforms[0].transform.translation.z, 0.9);
        assert_eq!(tf.transforms[0].header.frame_id, "f");
    }

    #[test]
    fn cell_objects_are_stamped_by_their_newest_view_and_named_by_the_view_they_carry() {
        let mut msg = CellPoseMessage { object_count: 2, published_time_ns: 99, ..CellPoseMessage::default() };
        msg.objects[0] = CellObject {
            class_id: 1,
            confidence: 0.9,
            quaternion: [0.0, 0.0, 0.0, 1.0],
            translation_m: [0.5, 0.0, 0.1],
            newest_capture_time_ns: 2_000,
            ..CellObject::default()
        };
        msg.objects[0].views[0] = CellView { camera_id: 0xab, instance_id: 3, ..CellView::default() };
        msg.objects[1] = CellObject { class_id: 2, newest_capture_time_ns: 5_000, ..CellObject::default() };
        // An entry beyond object_count is not published.
        msg.objects[2] = CellObject { class_id: 1, newest_capture_time_ns: 9_000, ..CellObject::default() };
        let stamp_of = |ns: u64| Time { sec: 1, nanosec: ns as u32 };
        let out = cell_detections(&msg, &table(), stamp_of, "cell");
        assert_eq!(out.header, Header { stamp: Time { sec: 1, nanosec: 5_000 }, frame_id: "cell".into() });
        assert_eq!(out.detections.len(), 2);
        let d = &out.detections[0];
        assert_eq!((d.id.as_str(), d.header.stamp.nanosec), ("mug_000000ab_3", 2_000));
        assert_eq!(d.results[0].hypothesis.score, 0.8999999761581421);
        assert_eq!(d.results[0].pose.pose.position.x, 0.5);
        let tf = cell_transforms(&msg, &table(), stamp_of, "cell", "fusepose/cell");
        assert_eq!(tf.transforms[0].child_frame_id, "fusepose/cell/mug_000000ab_3");
        assert_eq!(tf.transforms[1].header.stamp.nanosec, 5_000);
        // Nothing in the cell: an empty array at the publish time.
        let empty = CellPoseMessage { published_time_ns: 77, ..CellPoseMessage::default() };
        let out = cell_detections(&empty, &table(), stamp_of, "cell");
        assert!(out.detections.is_empty() && out.header.stamp.nanosec == 77);
    }
}
