//! `fusepose watch --overlay DIR`: keeps copies of the camera's last frames
//! (watch subscribes to the frame service next to the daemon) and, for each
//! pose message whose frame it still holds, writes `DIR/frame_<sequence>.png`
//! with the labels tinted and the poses drawn (`crate::pose_overlay`). Labels
//! are the frame's own when it carries them, else the built-in segmenter's
//! from `--weights` (the same network the daemon runs, so the same labels).
//! A frame's instance plane is tinted per instance, and each pose takes the
//! shade of the instance of its class holding most of its mask's box (the
//! message's `instance_id` is the daemon's, not the producer's); elsewhere
//! the copies of a class are told apart by their poses' shades.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};

use anyhow::Context;
use fusepose_client::{ColorFormat, FrameHeader, LabelData, PoseMessage, decode_frame};
use fusepose_estimator::seg::SegEngine;
use fusepose_estimator::{DepthPlane, FrameView};
use fusepose_scene::{Intrinsics, ObjectSet, Pose};
use nalgebra::{Quaternion, Translation3, UnitQuaternion};

use crate::pose_overlay::{DrawnPose, Tint};

/// Frames kept while waiting for their pose messages.
const FRAMES_KEPT: usize = 8;

pub struct OverlayWriter {
    dir: PathBuf,
    objects: ObjectSet,
    segmenter: Option<SegEngine>,
    /// `(header, payload copy)`, newest last.
    frames: VecDeque<(FrameHeader, Vec<u8>)>,
    rgb: Vec<u8>,
    labels: Vec<u16>,
    /// A frame's instance plane widened to the overlay's id type.
    instance_ids: Vec<u32>,
}

/// The pose of a wire quaternion `[x, y, z, w]` and translation (metres); `None` unless finite.
fn wire_pose(q: [f64; 4], t: [f64; 3]) -> Option<Pose> {
    let q = Quaternion::new(q[3], q[0], q[1], q[2]);
    (q.coords.iter().chain(&t).all(|v| v.is_finite()) && q.norm() > 1e-6)
        .then(|| Pose::from_parts(Translation3::new(t[0], t[1], t[2]), UnitQuaternion::from_quaternion(q)))
}

impl OverlayWriter {
    /// `weights`: a network file with an embedded segmenter (for frames without labels).
    pub fn new(dir: &Path, objects: ObjectSet, weights: Option<&Path>) -> anyhow::Result<Self> {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        let segmenter = weights
            .map(|w| SegEngine::load(w, &objects).with_context(|| format!("loading the segmenter of {}", w.display())))
            .transpose()?;
        Ok(Self {
            dir: dir.to_path_buf(),
            objects,
            segmenter,
            frames: VecDeque::new(),
            rgb: Vec::new(),
            labels: Vec::new(),
            instance_ids: Vec::new(),
        })
    }

    /// Keeps a copy of a received frame.
    pub fn push(&mut self, header: FrameHeader, payload: &[u8]) {
        if self.frames.len() == FRAMES_KEPT {
            self.frames.pop_front();
        }
        self.frames.push_back((header, payload.to_vec()));
    }

    /// Writes the overlay of `msg`'s frame; `None` when that frame is no longer held.
    pub fn write(&mut self, msg: &PoseMessage) -> anyhow::Result<Option<PathBuf>> {
        let Some((header, payload)) = self.frames.iter().find(|(h, _)| h.sequence == msg.frame_sequence) else {
            return Ok(None);
        };
        let planes = decode_frame(header, payload, Some(msg.camera_id))
            .map_err(|e| anyhow::anyhow!("frame {}: {e}", msg.frame_sequence))?;
        let h = &planes.header;
        let k = Intrinsics { fx: h.fx, fy: h.fy, cx: h.cx, cy: h.cy, width: h.width, height: h.height };
        let pixels = h.width as usize * h.height as usize;
        self.rgb.clear();
        match planes.color_format {
            ColorFormat::Rgb8 => self.rgb.extend_from_slice(planes.color),
            ColorFormat::Bgr8 => self.rgb.extend(planes.color.chunks_exact(3).flat_map(|p| [p[2], p[1], p[0]])),
        }
        self.labels.resize(pixels, 0);
        let mut instances: Vec<(u32, u16)> = Vec::new();
        let labels = match (planes.labels, &mut self.segmenter) {
            (Some(LabelData::U8(l)), _) => {
                self.labels.iter_mut().zip(l).for_each(|(d, &s)| *d = s as u16);
                Some(&self.labels[..])
            }
            (Some(LabelData::U16(l)), _) => Some(l),
            (Some(LabelData::Instances { ids, classes }), _) => {
                let class = |id: u16| classes.get(id as usize).copied().unwrap_or(0);
                self.instance_ids.clear();
                self.instance_ids.extend(ids.iter().map(|&id| id as u32));
                let mut present = vec![false; classes.len()];
                for &id in ids {
                    if let Some(p) = present.get_mut(id as usize) {
                        *p = true;
                    }
                }
                instances.extend(
                    (1..present.len())
                        .filter(|&id| present[id] && class(id as u16) != 0)
                        .map(|id| (id as u32, class(id as u16))),
                );
                None
            }
            (None, Some(seg)) => {
                let view = FrameView {
                    intrinsics: k,
                    color_format: fusepose_estimator::ColorFormat::Rgb8,
                    color: &self.rgb,
                    depth: match planes.depth {
                        fusepose_client::DepthData::U16 { data, scale } => DepthPlane::U16 { data, scale },
                        fusepose_client::DepthData::F32(data) => DepthPlane::F32(data),
                    },
                    labels: None,
                };
                seg.segment(&view, &mut self.labels)
                    .with_context(|| format!("segmenting frame {}", msg.frame_sequence))?;
                Some(&self.labels[..])
            }
            (None, None) => None,
        };
        let width = h.width as usize;
        let poses: Vec<DrawnPose> = msg
            .objects()
            .iter()
            .filter_map(|o| {
                let pose = wire_pose(o.quaternion, o.translation_m)?;
                let instance = instance_in_box(&self.instance_ids, width, &instances, o.class_id, o.bbox);
                Some(DrawnPose { class_id: o.class_id, pose, instance })
            })
            .collect();
        let tint = match labels {
            Some(l) => Tint::Classes(l),
            None if !instances.is_empty() => Tint::Instances { ids: &self.instance_ids, instances: &instances },
            None => Tint::None,
        };
        let path = self.dir.join(format!("frame_{:06}.png", msg.frame_sequence));
        crate::pose_overlay::write(&path, &k, &self.rgb, tint, &poses, &self.objects)?;
        Ok(Some(path))
    }
}

/// The instance of `class` (among `instances`, ids in `ids`, rows `width`
/// long) holding the most pixels inside `bbox` ([u_min, v_min, u_max, v_max],
/// inclusive): the producer's instance a pose's mask came from. `None`
/// without an instance plane or when none of the class lies in the box.
fn instance_in_box(ids: &[u32], width: usize, instances: &[(u32, u16)], class: u16, bbox: [u16; 4]) -> Option<u32> {
    if instances.is_empty() || width == 0 {
        return None;
    }
    let height = ids.len() / width;
    let [u0, v0, u1, v1] = bbox.map(usize::from);
    if u0 > u1 || v0 > v1 || u0 >= width {
        return None;
    }
    let mut counts: Vec<(u32, usize)> =
        instances.iter().filter(|&&(_, c)| c == class).map(|&(id, _)| (id, 0)).collect();
    for v in v0..=v1.min(height.saturating_sub(1)) {
        for &id in &ids[v * width + u0..v * width + (u1 + 1).min(width)] {
            if let Some(c) = counts.iter_mut().find(|(i, _)| *i == id) {
                c.1 += 1;
            }
        }
    }
    counts.into_iter().filter(|&(_, n)| n > 0).max_by_key(|&(_, n)| n).map(|(id, _)| id)
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_client::{DepthFormat, FrameLayout, LabelFormat};
    use fusepose_scene::builtin::builtin_objects;
    use fusepose_scene::overlay::{INSTANCE_BORDER, instance_colour};

    #[test]
    fn a_frames_instance_plane_is_tinted_per_copy_and_each_pose_takes_its_copys_shade() {
        // Two copies of class 3 side by side in the frame's instance plane
        // (ids 1 and 2, meeting at u = 80), posed at x = -/+ 6 cm, 0.5 m away.
        let (w, h) = (160usize, 120usize);
        let layout = FrameLayout {
            width: w as u32,
            height: h as u32,
            color_format: ColorFormat::Rgb8,
            depth_format: DepthFormat::U16,
            depth_scale: 0.001,
            labels: Some(LabelFormat::InstanceU16 { max_instances: 3 }),
        };
        let mut header = layout.header(0);
        (header.sequence, header.fx, header.fy, header.cx, header.cy) = (42, 300.0, 300.0, 80.0, 60.0);
        let mut payload = vec![0u8; layout.payload_len()];
        let [color, depth, labels] = layout.planes();
        payload[color.offset as usize..(color.offset + color.len) as usize].fill(90);
        for d in payload[depth.offset as usize..(depth.offset + depth.len) as usize].chunks_exact_mut(2) {
            d.copy_from_slice(&500u16.to_ne_bytes());
        }
        let id_at = |p: usize| {
            if p / w < 30 || p / w > 90 {
                0u16
            } else if p % w < 80 {
                1
            } else {
                2
            }
        };
        for (p, l) in
            payload[labels.offset as usize..(labels.offset + labels.len) as usize].chunks_exact_mut(2).enumerate()
        {
            l.copy_from_slice(&id_at(p).to_ne_bytes());
        }
        let table = layout.instance_classes();
        for (i, c) in [0u16, 3, 3, 0].iter().enumerate() {
            let at = table.offset as usize + 2 * i;
            payload[at..at + 2].copy_from_slice(&c.to_ne_bytes());
        }
        let mut msg = PoseMessage { camera_id: 0, frame_sequence: 42, object_count: 2, ..PoseMessage::default() };
        for (o, (x, bbox)) in msg.objects.iter_mut().zip([(-0.06, [0, 30, 79, 90]), (0.06, [80, 30, 159, 90])]) {
            (o.class_id, o.bbox, o.quaternion, o.translation_m) = (3, bbox, [0.0, 0.0, 0.0, 1.0], [x, 0.0, 0.5]);
        }
        // The daemon's instance ids are its own: the pose on the right comes first.
        msg.objects.swap(0, 1);
        let dir = std::env::temp_dir().join(format!("fusepose_watch_overlay_{}", std::process::id()));
        let mut writer = OverlayWriter::new(&dir, builtin_objects(), None).unwrap();
        writer.push(header, &payload);
        let path = writer.write(&msg).unwrap().expect("the frame is held");
        let img = image::open(&path).unwrap().to_rgb8();
        let count = |c: [u8; 3]| img.pixels().filter(|p| p.0 == c).count();
        let (first, second) = (instance_colour(3, 0), instance_colour(3, 1));
        assert!(count(first) > 20 && count(second) > 20, "each pose outlined in its copy's shade");
        // The left pose (instance 1, the first shade) is outlined left of the
        // line between the copies, the right one right of it.
        let cols =
            |c: [u8; 3]| img.enumerate_pixels().filter(|(_, _, p)| p.0 == c).map(|(u, _, _)| u).collect::<Vec<_>>();
        assert!(cols(first).iter().all(|&u| u < 80) && cols(second).iter().all(|&u| u >= 80));
        let line = img.enumerate_pixels().filter(|(u, _, p)| (79..=80).contains(u) && p.0 == INSTANCE_BORDER).count();
        assert!(line >= 100, "{line} white pixels where the copies meet");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_pose_takes_the_instance_of_its_class_filling_its_box() {
        // 4x2 plane: id 1 (class 3) on the left, id 2 (class 3) on the right, id 4 (class 5) bottom-right.
        let ids = [1, 1, 2, 2, 1, 2, 2, 4];
        let instances = [(1, 3), (2, 3), (4, 5)];
        assert_eq!(instance_in_box(&ids, 4, &instances, 3, [0, 0, 1, 1]), Some(1));
        assert_eq!(instance_in_box(&ids, 4, &instances, 3, [1, 0, 3, 1]), Some(2));
        assert_eq!(instance_in_box(&ids, 4, &instances, 5, [0, 0, 3, 1]), Some(4));
        // No instance of the class in the box, or no instance plane at all.
        assert_eq!(instance_in_box(&ids, 4, &instances, 5, [0, 0, 1, 1]), None);
        assert_eq!(instance_in_box(&ids, 4, &[], 3, [0, 0, 3, 1]), None);
        // A box past the frame is clipped, an inverted one ignored, not a panic.
        assert_eq!(instance_in_box(&ids, 4, &instances, 3, [2, 1, 900, 900]), Some(2));
        assert_eq!(instance_in_box(&ids, 4, &instances, 3, [3, 1, 1, 0]), None);
        assert_eq!(instance_in_box(&ids, 4, &instances, 3, [7, 0, 9, 1]), None);
    }
}
