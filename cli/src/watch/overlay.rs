//! `fusepose watch --overlay DIR`: keeps copies of the camera's last frames
//! (watch subscribes to the frame service next to the daemon) and, for each
//! pose message whose frame it still holds, writes `DIR/frame_<sequence>.png`
//! with the labels tinted and the poses drawn (`crate::pose_overlay`). Labels
//! are the frame's own when it carries them, else the built-in segmenter's
//! from `--weights` (the same network the daemon runs, so the same labels).

use std::collections::VecDeque;
use std::path::{Path, PathBuf};

use anyhow::Context;
use fusepose_client::{ColorFormat, FrameHeader, LabelData, PoseMessage, decode_frame};
use fusepose_estimator::seg::SegEngine;
use fusepose_estimator::{DepthPlane, FrameView};
use fusepose_scene::{Intrinsics, ObjectSet, Pose};
use nalgebra::{Quaternion, Translation3, UnitQuaternion};

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
        let labels = match (planes.labels, &mut self.segmenter) {
            (Some(LabelData::U8(l)), _) => {
                self.labels.iter_mut().zip(l).for_each(|(d, &s)| *d = s as u16);
                Some(&self.labels[..])
            }
            (Some(LabelData::U16(l)), _) => Some(l),
            (Some(LabelData::Instances { ids, classes }), _) => {
                let class = |id: u16| classes.get(id as usize).copied().unwrap_or(0);
                self.labels.iter_mut().zip(ids).for_each(|(d, &id)| *d = class(id));
                Some(&self.labels[..])
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
        let poses: Vec<(u16, Pose)> = msg
            .objects()
            .iter()
            .filter_map(|o| Some((o.class_id, wire_pose(o.quaternion, o.translation_m)?)))
            .collect();
        let path = self.dir.join(format!("frame_{:06}.png", msg.frame_sequence));
        crate::pose_overlay::write(&path, &k, &self.rgb, labels, &poses, &self.objects)?;
        Ok(Some(path))
    }
}
