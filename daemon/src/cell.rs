//! One cell frame for all cameras: each camera's latest poses, moved into
//! the cell frame by its extrinsics, associated across cameras (same class,
//! translations within the merge distance, at most one view per camera) and
//! merged into one entry per physical object.
//!
//! Which pose an entry carries ([`Fusion`]): by default the view that best
//! explains the depth image (the smallest verified depth residual; the most
//! confident where none is verified). Averaging the views was measured worse:
//! on 24 two-view tuning scenes the confidence-weighted mean gave 4.99 mm
//! mean ADD-S, residual-weighted 4.96 mm, the better camera alone 4.56 mm and
//! the best-fitting view 4.56 mm (docs/BENCHMARKS.md, "Cell fusion"); the
//! mean stays available (`cell.fusion = "mean"`). Preallocated: no
//! allocation per frame.

use fusepose_client::{
    CellFlags, CellObject, CellPoseMessage, CellView, MAX_CELL_OBJECTS, MAX_CELL_VIEWS, PoseFlags, PoseMessage,
};
use nalgebra::{Isometry3, Quaternion, UnitQuaternion, Vector3};

use crate::config::MAX_CAMERAS;

/// How an entry's pose comes from its views.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Fusion {
    /// The pose of the view with the smallest depth residual among the
    /// verified views (the most confident view when none is verified).
    #[default]
    BestFit,
    /// Confidence-weighted mean: translations averaged; rotations averaged
    /// (sign-aligned quaternions) over the views within `max_rotation_deg`
    /// of the most confident view.
    Mean,
}

impl std::str::FromStr for Fusion {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "best-fit" => Ok(Self::BestFit),
            "mean" => Ok(Self::Mean),
            other => Err(format!("unknown cell fusion {other:?}: use \"best-fit\" or \"mean\"")),
        }
    }
}

/// One camera's contribution: its latest pose message and where it is in the cell.
pub struct CellSource<'a> {
    pub msg: &'a PoseMessage,
    /// Camera → cell.
    pub cell_from_camera: &'a Isometry3<f64>,
    /// The camera's class id → the cell's (daemon object set) class id; 0 = not in the cell's set.
    /// Empty: identical ids.
    pub class_map: &'a [u16],
}

#[derive(Clone, Copy, Debug)]
struct Candidate {
    class_id: u16,
    view: CellView,
    pose: Isometry3<f64>,
    /// The pose's median depth residual (m) when it was verified, else infinite.
    residual_m: f32,
}

#[derive(Clone, Copy, Debug)]
struct Cluster {
    /// Indices into the candidates, most confident first.
    members: [u16; MAX_CAMERAS],
    count: usize,
}

/// Fuses the cameras' latest poses into cell messages.
pub struct CellFuser {
    /// Per cell class id − 1: merge distance, metres.
    merge_m: Vec<f64>,
    max_rotation_rad: f64,
    fusion: Fusion,
    candidates: Vec<Candidate>,
    clusters: Vec<Cluster>,
    sequence: u64,
}

impl CellFuser {
    /// `merge_m[class − 1]`: largest distance between two cameras' poses of one object.
    pub fn new(merge_m: Vec<f64>, max_rotation_deg: f64) -> Self {
        let capacity = MAX_CAMERAS * fusepose_client::MAX_OBJECTS;
        Self {
            merge_m,
            max_rotation_rad: max_rotation_deg.to_radians(),
            fusion: Fusion::default(),
            candidates: Vec::with_capacity(capacity),
            clusters: Vec::with_capacity(capacity),
            sequence: 0,
        }
    }

    /// Another fusion rule (default [`Fusion::BestFit`]).
    pub fn with_fusion(mut self, fusion: Fusion) -> Self {
        self.fusion = fusion;
        self
    }

    fn merge_distance(&self, class_id: u16) -> f64 {
        self.merge_m.get(class_id as usize - 1).copied().unwrap_or(0.0)
    }

    /// Fills `out` from the sources whose latest frame was captured at most
    /// `max_age_ns` before `now_ns` and posed OK.
    pub fn fuse<'a>(
        &mut self,
        sources: impl IntoIterator<Item = CellSource<'a>>,
        now_ns: u64,
        max_age_ns: u64,
        trigger_camera_id: u32,
        out: &mut CellPoseMessage,
    ) {
        self.candidates.clear();
        self.clusters.clear();
        let mut cameras = 0u16;
        for src in sources {
            let msg = src.msg;
            if !msg.is_ok() || now_ns.saturating_sub(msg.capture_time_ns) > max_age_ns {
                continue;
            }
            cameras += 1;
            for o in msg.objects() {
                let class_id = if src.class_map.is_empty() {
                    o.class_id
                } else {
                    src.class_map.get(o.class_id as usize).copied().unwrap_or(0)
                };
                if class_id == 0 || self.candidates.len() == self.candidates.capacity() {
                    continue;
                }
                let [x, y, z, w] = o.quaternion;
                let q = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
                let t = Vector3::from(o.translation_m);
                let pose = src.cell_from_camera * Isometry3::from_parts(t.into(), q);
                let view = CellView {
                    camera_id: msg.camera_id,
                    instance_id: o.instance_id,
                    flags: o.flags,
                    confidence: o.confidence,
                    offset_m: 0.0,
                    frame_sequence: msg.frame_sequence,
                    capture_time_ns: msg.capture_time_ns,
                };
                let verified = o.flags & PoseFlags::VERIFIED != 0 && o.depth_residual_m.is_finite();
                let residual_m = if verified { o.depth_residual_m } else { f32::INFINITY };
                self.candidates.push(Candidate { class_id, view, pose, residual_m });
            }
        }
        // Most confident first: each object's seed is its best view.
        self.candidates.sort_unstable_by(|a, b| b.view.confidence.total_cmp(&a.view.confidence));
        for i in 0..self.candidates.len() {
            let c = self.candidates[i];
            let merge = self.merge_distance(c.class_id);
            let mut best: Option<(f64, usize)> = None;
            for (k, cluster) in self.clusters.iter().enumerate() {
                let seed = &self.candidates[cluster.members[0] as usize];
                if seed.class_id != c.class_id || cluster.count >= MAX_CAMERAS {
                    continue;
                }
                let taken = cluster.members[..cluster.count]
                    .iter()
                    .any(|&m| self.candidates[m as usize].view.camera_id == c.view.camera_id);
                let d = (seed.pose.translation.vector - c.pose.translation.vector).norm();
                if !taken && d <= merge && best.is_none_or(|(bd, _)| d < bd) {
                    best = Some((d, k));
                }
            }
            match best {
                Some((_, k)) => {
                    let cluster = &mut self.clusters[k];
                    cluster.members[cluster.count] = i as u16;
                    cluster.count += 1;
                }
                None => {
                    let mut members = [0u16; MAX_CAMERAS];
                    members[0] = i as u16;
                    self.clusters.push(Cluster { members, count: 1 });
                }
            }
        }
        out.format_version = fusepose_client::WIRE_VERSION;
        out.camera_count = cameras;
        out.trigger_camera_id = trigger_camera_id;
        out.sequence = self.sequence;
        self.sequence += 1;
        out.truncated = (self.clusters.len() > MAX_CELL_OBJECTS) as u16;
        let n = self.clusters.len().min(MAX_CELL_OBJECTS);
        for (slot, cluster) in out.objects.iter_mut().zip(&self.clusters) {
            *slot = self.fuse_cluster(cluster);
        }
        out.objects[n..].iter_mut().for_each(|o| *o = CellObject::default());
        out.object_count = n as u16;
    }

    fn fuse_cluster(&self, cluster: &Cluster) -> CellObject {
        let members = &cluster.members[..cluster.count];
        let view = |m: u16| &self.candidates[m as usize];
        // Members are most confident first; the chosen view's pose is the entry's.
        let chosen = match self.fusion {
            Fusion::BestFit => members
                .iter()
                .enumerate()
                .min_by(|&(i, &a), &(j, &b)| view(a).residual_m.total_cmp(&view(b).residual_m).then(i.cmp(&j)))
                .map_or(0, |(i, _)| i),
            Fusion::Mean => 0,
        };
        let best = view(members[chosen]);
        let mut flags = CellFlags::VERIFIED;
        if members.iter().any(|&m| view(m).view.flags & PoseFlags::VERIFIED == 0) {
            flags &= !CellFlags::VERIFIED;
        }
        let (t, q) = match self.fusion {
            Fusion::BestFit => (best.pose.translation.vector, best.pose.rotation),
            Fusion::Mean => {
                let q_best = best.pose.rotation;
                let (mut t_sum, mut t_w) = (Vector3::zeros(), 0.0);
                let mut q_sum = Quaternion::new(0.0, 0.0, 0.0, 0.0);
                for &m in members {
                    let c = view(m);
                    let w = (c.view.confidence as f64).max(1e-3);
                    t_sum += w * c.pose.translation.vector;
                    t_w += w;
                    if q_best.angle_to(&c.pose.rotation) <= self.max_rotation_rad {
                        let q = c.pose.rotation.into_inner();
                        let q = if q.dot(&q_best.into_inner()) < 0.0 { -q } else { q };
                        q_sum += q * w;
                    } else {
                        flags |= CellFlags::ROTATION_FROM_BEST_VIEW;
                    }
                }
                (t_sum / t_w, UnitQuaternion::try_new(q_sum, 1e-12).unwrap_or(q_best))
            }
        };
        let mut object = CellObject {
            class_id: best.class_id,
            view_count: members.len() as u16,
            flags,
            reserved: 0,
            confidence: members.iter().map(|&m| view(m).view.confidence).fold(0.0, f32::max),
            spread_m: 0.0,
            quaternion: [q.i, q.j, q.k, q.w],
            translation_m: [t.x, t.y, t.z],
            newest_capture_time_ns: 0,
            oldest_capture_time_ns: u64::MAX,
            views: [CellView::default(); MAX_CELL_VIEWS],
        };
        // The chosen view first, then the others most confident first.
        let order = std::iter::once(chosen).chain((0..members.len()).filter(|&j| j != chosen));
        for (slot, j) in order.enumerate() {
            let c = view(members[j]);
            let offset = (c.pose.translation.vector - t).norm();
            object.spread_m = object.spread_m.max(offset as f32);
            object.newest_capture_time_ns = object.newest_capture_time_ns.max(c.view.capture_time_ns);
            object.oldest_capture_time_ns = object.oldest_capture_time_ns.min(c.view.capture_time_ns);
            if slot < MAX_CELL_VIEWS {
                object.views[slot] = CellView { offset_m: offset as f32, ..c.view };
            }
        }
        object
    }
}

#[cfg(test)]
mod tests {
    use fusepose_client::{PoseStatus, WireObjectPose};
    use nalgebra::Translation3;

    use super::*;

    /// (class, confidence, pose object → camera, verified depth residual in metres).
    type Seen = (u16, f32, Isometry3<f64>, f32);

    fn pose_msg(camera_id: u32, capture: u64, objects: &[Seen]) -> PoseMessage {
        let mut msg = PoseMessage {
            camera_id,
            capture_time_ns: capture,
            status: PoseStatus::OK,
            object_count: objects.len() as u16,
            ..PoseMessage::default()
        };
        for (i, (class_id, confidence, pose, residual)) in objects.iter().enumerate() {
            let q = pose.rotation;
            let t = pose.translation.vector;
            msg.objects[i] = WireObjectPose {
                class_id: *class_id,
                instance_id: i as u16,
                confidence: *confidence,
                flags: PoseFlags::VERIFIED,
                quaternion: [q.i, q.j, q.k, q.w],
                translation_m: [t.x, t.y, t.z],
                fit_score: 0.9,
                depth_residual_m: *residual,
                ..WireObjectPose::default()
            };
        }
        msg
    }

    fn iso(t: [f64; 3], axis_angle: [f64; 3]) -> Isometry3<f64> {
        Isometry3::new(Vector3::from(t), Vector3::from(axis_angle))
    }

    /// A camera's estimate of `truth` (cell frame): the truth in its frame, `err` off (camera frame).
    fn seen(cam: &Isometry3<f64>, truth: &Isometry3<f64>, err: [f64; 3]) -> Isometry3<f64> {
        Translation3::new(err[0], err[1], err[2]) * (cam.inverse() * truth)
    }

    fn cell_pose(o: &CellObject) -> Isometry3<f64> {
        let [x, y, z, w] = o.quaternion;
        let q = UnitQuaternion::from_quaternion(Quaternion::new(w, x, y, z));
        Isometry3::from_parts(Vector3::from(o.translation_m).into(), q)
    }

    /// Two cameras see the same two objects from different places: the cell
    /// has each once, listing both views; the entry carries the pose of the
    /// view that explains the depth best, even when it is the less confident.
    #[test]
    fn the_same_object_from_two_cameras_is_one_entry_with_the_best_fitting_pose() {
        let a_in_cell = iso([0.0, 0.0, -0.8], [0.0, 0.0, 0.0]);
        let b_in_cell = iso([0.5, 0.0, -0.4], [0.0, -0.9, 0.0]);
        let box_cell = iso([0.05, 0.02, 0.0], [0.1, 0.2, 0.3]);
        let can_cell = iso([-0.10, 0.05, 0.02], [0.0, 0.0, 1.0]);
        let msg_a = pose_msg(
            1,
            100,
            &[
                (2, 0.9, seen(&a_in_cell, &box_cell, [0.004, 0.0, 0.0]), 0.006),
                (5, 0.5, seen(&a_in_cell, &can_cell, [0.0; 3]), 0.002),
            ],
        );
        let msg_b = pose_msg(2, 90, &[(2, 0.3, seen(&b_in_cell, &box_cell, [0.0; 3]), 0.002)]);
        let mut fuser = CellFuser::new(vec![0.05; 8], 20.0);
        let mut out = CellPoseMessage::default();
        let sources = [
            CellSource { msg: &msg_a, cell_from_camera: &a_in_cell, class_map: &[] },
            CellSource { msg: &msg_b, cell_from_camera: &b_in_cell, class_map: &[] },
        ];
        fuser.fuse(sources, 110, 1_000, 1, &mut out);
        assert_eq!((out.object_count, out.camera_count, out.sequence), (2, 2, 0));
        let fused_box = out.objects().iter().find(|o| o.class_id == 2).unwrap();
        assert_eq!(fused_box.view_count, 2);
        assert_eq!((fused_box.views[0].camera_id, fused_box.views[1].camera_id), (2, 1), "the chosen view first");
        assert_eq!(fused_box.confidence, 0.9, "the highest confidence of the views");
        assert_eq!((fused_box.newest_capture_time_ns, fused_box.oldest_capture_time_ns), (100, 90));
        let error = (cell_pose(fused_box).translation.vector - box_cell.translation.vector).norm();
        assert!(error < 1e-9, "camera 2's exact pose, not camera 1's (4 mm off): {error}");
        assert!(cell_pose(fused_box).rotation.angle_to(&box_cell.rotation) < 1e-6);
        assert!((fused_box.spread_m - 0.004).abs() < 1e-6 && fused_box.views[0].offset_m < 1e-6);
        assert!(fused_box.flags & CellFlags::VERIFIED != 0);
        let can = out.objects().iter().find(|o| o.class_id == 5).unwrap();
        assert_eq!(can.view_count, 1);
        assert!((cell_pose(can).translation.vector - can_cell.translation.vector).norm() < 1e-9);
    }

    /// `Fusion::Mean`: confidence-weighted translations; a view whose rotation
    /// is far from the best view's (a symmetric object's flip) keeps only its translation.
    #[test]
    fn the_mean_fusion_averages_and_leaves_out_flipped_rotations() {
        let cam = Isometry3::identity();
        let truth = iso([0.0, 0.0, 0.8], [0.0; 3]);
        let flipped = iso([0.004, 0.0, 0.8], [0.0, 0.0, std::f64::consts::PI]);
        let msg_a = pose_msg(1, 0, &[(4, 0.6, iso([-0.004, 0.0, 0.8], [0.0; 3]), 0.003)]);
        let msg_b = pose_msg(2, 0, &[(4, 0.2, flipped, 0.001)]);
        let mut fuser = CellFuser::new(vec![0.05; 8], 20.0).with_fusion(Fusion::Mean);
        let mut out = CellPoseMessage::default();
        let sources = [
            CellSource { msg: &msg_a, cell_from_camera: &cam, class_map: &[] },
            CellSource { msg: &msg_b, cell_from_camera: &cam, class_map: &[] },
        ];
        fuser.fuse(sources, 0, 1, 2, &mut out);
        let o = &out.objects[0];
        assert_eq!((out.object_count, o.view_count), (1, 2));
        assert!((o.translation_m[0] - (-0.004 * 0.6 + 0.004 * 0.2) / 0.8).abs() < 1e-9, "{:?}", o.translation_m);
        assert!(o.flags & CellFlags::ROTATION_FROM_BEST_VIEW != 0);
        assert!(cell_pose(o).rotation.angle_to(&truth.rotation) < 1e-9, "the flipped view is not averaged in");
    }

    #[test]
    fn two_copies_side_by_side_stay_two_and_one_camera_never_merges_with_itself() {
        let cam = Isometry3::identity();
        let a = iso([0.0, 0.0, 0.8], [0.0; 3]);
        let b = iso([0.02, 0.0, 0.8], [0.0; 3]);
        let msg = pose_msg(1, 0, &[(3, 0.8, a, 0.003), (3, 0.7, b, 0.003)]);
        let mut fuser = CellFuser::new(vec![0.05; 8], 20.0);
        let mut out = CellPoseMessage::default();
        fuser.fuse([CellSource { msg: &msg, cell_from_camera: &cam, class_map: &[] }], 0, 1, 1, &mut out);
        assert_eq!(out.object_count, 2, "one camera's two instances are two objects");
        // A second camera sees one of them: it joins the nearer.
        let msg2 = pose_msg(2, 0, &[(3, 0.5, iso([0.021, 0.0, 0.8], [0.0; 3]), 0.003)]);
        let sources = [
            CellSource { msg: &msg, cell_from_camera: &cam, class_map: &[] },
            CellSource { msg: &msg2, cell_from_camera: &cam, class_map: &[] },
        ];
        fuser.fuse(sources, 0, 1, 2, &mut out);
        assert_eq!(out.object_count, 2);
        let joined = out.objects().iter().find(|o| o.view_count == 2).unwrap();
        assert_eq!((joined.views[0].camera_id, joined.views[1].camera_id), (1, 2), "equal fits: the more confident");
        assert!((joined.translation_m[0] - 0.02).abs() < 1e-12 && (joined.views[1].offset_m - 0.001).abs() < 1e-6);
        assert_eq!(out.sequence, 1);
    }

    #[test]
    fn stale_cameras_unverified_views_and_unknown_classes_are_handled() {
        let cam = Isometry3::identity();
        let truth = iso([0.0, 0.0, 0.8], [0.0; 3]);
        let mut fresh = pose_msg(1, 1_000, &[(4, 0.9, truth, 0.004), (7, 0.9, truth, 0.001)]);
        let other = pose_msg(2, 1_000, &[(4, 0.4, iso([0.01, 0.0, 0.8], [0.0; 3]), 0.001)]);
        let stale = pose_msg(3, 0, &[(4, 0.99, iso([0.5, 0.0, 0.8], [0.0; 3]), 0.0001)]);
        // Camera 2's class 4 is the cell's 4; camera 1's class 7 has no cell class.
        let map1 = [0, 1, 2, 3, 4, 5, 6, 0];
        let mut fuser = CellFuser::new(vec![0.05; 8], 20.0);
        let mut out = CellPoseMessage::default();
        let sources = [
            CellSource { msg: &fresh, cell_from_camera: &cam, class_map: &map1 },
            CellSource { msg: &other, cell_from_camera: &cam, class_map: &[] },
            CellSource { msg: &stale, cell_from_camera: &cam, class_map: &[] },
        ];
        fuser.fuse(sources, 1_100, 500, 1, &mut out);
        assert_eq!((out.object_count, out.camera_count), (1, 2), "stale camera 3 and unmapped class 7 left out");
        assert_eq!(out.objects[0].views[0].camera_id, 2, "the smaller residual wins");
        assert_eq!(out.objects[1], CellObject::default(), "entries past the count are zero");
        // Camera 2's pose unverified: its residual does not count, camera 1's pose is taken.
        let mut unverified = other;
        unverified.objects[0].flags = 0;
        fresh.objects[1].class_id = 9;
        let sources = [
            CellSource { msg: &fresh, cell_from_camera: &cam, class_map: &[] },
            CellSource { msg: &unverified, cell_from_camera: &cam, class_map: &[] },
        ];
        fuser.fuse(sources, 1_100, 500, 1, &mut out);
        let o = out.objects().iter().find(|o| o.class_id == 4).unwrap();
        assert_eq!(o.views[0].camera_id, 1);
        assert!(o.flags & CellFlags::VERIFIED == 0, "not every view verified");
    }
}
