//! Reads one split of a BOP dataset: annotations of every frame at open,
//! images on demand, converted to metres.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion};

use super::error::{BopError, image_err, invalid, io_err};
use super::images::{read_depth_u16, read_mask, read_rgb8};
use super::json::{SceneCamera, SceneGt, SceneGtInfo, read_json};
use super::manifest::DatasetManifest;
use super::models_info::{BopModelInfo, read_models_info};
use crate::{Intrinsics, Pose};

/// A frame's identity inside a split.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct FrameId {
    pub scene_id: u32,
    pub im_id: u32,
}

/// One ground-truth instance, in metres and pixels.
#[derive(Clone, Debug, PartialEq)]
pub struct BopGt {
    /// BOP obj_id (our class id for fusepose datasets).
    pub obj_id: u16,
    /// Object → camera, metres.
    pub pose: Pose,
    /// Visible share of the object's in-image silhouette, 0..=1.
    pub visib_fract: f64,
    /// Visible pixel count.
    pub px_count_visib: i64,
    /// `[x, y, width, height]` of the visible pixels; `[-1; 4]` when hidden.
    pub bbox_visib: [i32; 4],
    /// `[x, y, width, height]` of the full silhouette (may leave the image).
    pub bbox_obj: [i32; 4],
}

/// One loaded frame.
#[derive(Clone, Debug, PartialEq)]
pub struct BopFrame {
    pub id: FrameId,
    /// Intrinsics, with the image size taken from the RGB file.
    pub intrinsics: Intrinsics,
    /// RGB8, row-major, `width * height * 3` bytes.
    pub rgb: Vec<u8>,
    /// Raw depth values, `width * height`; metres = value * `depth_unit_m`; 0 = missing.
    pub depth: Vec<u16>,
    /// Metres per depth unit (BOP `depth_scale / 1000`).
    pub depth_unit_m: f64,
    /// Ground truth in `scene_gt.json` order (instance `k` ↔ `mask_visib/*_k.png`).
    pub gt: Vec<BopGt>,
    /// Class-id plane from the visible masks: `obj_id` where instance is
    /// visible, 0 = background; later instances win on (invalid) overlaps.
    pub labels: Vec<u16>,
    /// Instance plane from the same masks: `k + 1` where ground-truth
    /// instance `k` (`gt[k]`) is visible, 0 = background.
    pub instances: Vec<u16>,
}

impl BopFrame {
    pub fn width(&self) -> u32 {
        self.intrinsics.width
    }

    pub fn height(&self) -> u32 {
        self.intrinsics.height
    }

    /// Depth of pixel `(u, v)` in metres (0 = missing); `None` outside the image.
    pub fn depth_m(&self, u: u32, v: u32) -> Option<f64> {
        if u >= self.width() || v >= self.height() {
            return None;
        }
        Some(self.depth[(v * self.width() + u) as usize] as f64 * self.depth_unit_m)
    }

    /// The depth plane in metres (0 = missing).
    pub fn depth_metres(&self) -> Vec<f32> {
        self.depth.iter().map(|&d| (d as f64 * self.depth_unit_m) as f32).collect()
    }
}

#[derive(Clone, Debug)]
struct FrameRecord {
    id: FrameId,
    scene_dir: PathBuf,
    k: [f64; 9],
    depth_scale: f64,
    gt: Vec<BopGt>,
}

/// One split of a BOP dataset.
#[derive(Clone, Debug)]
pub struct BopDataset {
    split_dir: PathBuf,
    root: PathBuf,
    manifest: Option<DatasetManifest>,
    models_info: Option<BTreeMap<u16, BopModelInfo>>,
    frames: Vec<FrameRecord>,
    ids: Vec<FrameId>,
}

fn scene_id_of(name: &str) -> Option<u32> {
    (name.len() == 6 && name.bytes().all(|b| b.is_ascii_digit())).then(|| name.parse().ok()).flatten()
}

fn to_pose(path: &Path, im_id: u32, r: &[f64; 9], t_mm: &[f64; 3]) -> Result<Pose, BopError> {
    if !(r.iter().chain(t_mm).all(|v| v.is_finite())) {
        return Err(invalid(path, format!("image {im_id}: pose is not finite")));
    }
    let m = Matrix3::from_row_slice(r);
    if (m.determinant() - 1.0).abs() > 0.05 {
        return Err(invalid(path, format!("image {im_id}: cam_R_m2c is not a rotation (det {})", m.determinant())));
    }
    // Re-orthonormalise (files store ~8 significant digits).
    let rot = Rotation3::from_matrix_eps(&m, 1e-12, 100, Rotation3::identity());
    Ok(Pose::from_parts(
        Translation3::new(t_mm[0] / 1000.0, t_mm[1] / 1000.0, t_mm[2] / 1000.0),
        UnitQuaternion::from_rotation_matrix(&rot),
    ))
}

fn bbox(b: &[i64; 4]) -> [i32; 4] {
    b.map(|v| v.clamp(i32::MIN as i64, i32::MAX as i64) as i32)
}

impl BopDataset {
    /// Opens a split folder (e.g. `out/test`): every `NNNNNN/` scene in it
    /// with a `scene_gt.json`. The dataset root is its parent, where the
    /// optional `fusepose_dataset.json` and `models/models_info.json` are read.
    /// Frames are those listed in `scene_gt.json`, ordered by scene then image.
    pub fn open(split_dir: impl AsRef<Path>) -> Result<Self, BopError> {
        let split_dir = split_dir.as_ref().to_path_buf();
        let root = split_dir.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
        let mut scenes: Vec<(u32, PathBuf)> = Vec::new();
        for entry in std::fs::read_dir(&split_dir).map_err(io_err(&split_dir))? {
            let entry = entry.map_err(io_err(&split_dir))?;
            let path = entry.path();
            let Some(id) = path.file_name().and_then(|n| n.to_str()).and_then(scene_id_of) else { continue };
            if path.join("scene_gt.json").is_file() {
                scenes.push((id, path));
            }
        }
        if scenes.is_empty() {
            return Err(BopError::NoScenes { path: split_dir });
        }
        scenes.sort();
        let mut frames = Vec::new();
        for (scene_id, dir) in scenes {
            let (cam_path, gt_path, info_path) =
                (dir.join("scene_camera.json"), dir.join("scene_gt.json"), dir.join("scene_gt_info.json"));
            let camera: SceneCamera = read_json(&cam_path)?;
            let gt: SceneGt = read_json(&gt_path)?;
            let info: SceneGtInfo = read_json(&info_path)?;
            for (&im_id, entries) in &gt {
                let cam = camera.get(&im_id).ok_or(BopError::MissingEntry { path: cam_path.clone(), im_id })?;
                if !(cam.cam_k.iter().all(|v| v.is_finite()) && cam.cam_k[0] > 0.0 && cam.cam_k[4] > 0.0) {
                    return Err(invalid(&cam_path, format!("image {im_id}: cam_K is not a usable camera matrix")));
                }
                if !(cam.depth_scale.is_finite() && cam.depth_scale > 0.0) {
                    return Err(invalid(
                        &cam_path,
                        format!("image {im_id}: depth_scale {} is not > 0", cam.depth_scale),
                    ));
                }
                let infos = info.get(&im_id).ok_or(BopError::MissingEntry { path: info_path.clone(), im_id })?;
                if infos.len() != entries.len() {
                    return Err(invalid(
                        &info_path,
                        format!("image {im_id}: {} info entries for {} GT instances", infos.len(), entries.len()),
                    ));
                }
                let mut list = Vec::with_capacity(entries.len());
                for (e, i) in entries.iter().zip(infos) {
                    list.push(BopGt {
                        obj_id: e.obj_id,
                        pose: to_pose(&gt_path, im_id, &e.cam_r_m2c, &e.cam_t_m2c)?,
                        visib_fract: i.visib_fract,
                        px_count_visib: i.px_count_visib,
                        bbox_visib: bbox(&i.bbox_visib),
                        bbox_obj: bbox(&i.bbox_obj),
                    });
                }
                frames.push(FrameRecord {
                    id: FrameId { scene_id, im_id },
                    scene_dir: dir.clone(),
                    k: cam.cam_k,
                    depth_scale: cam.depth_scale,
                    gt: list,
                });
            }
        }
        let manifest = DatasetManifest::read(&root)?;
        let info_path = root.join("models").join("models_info.json");
        let models_info = if info_path.is_file() { Some(read_models_info(&info_path)?) } else { None };
        let ids = frames.iter().map(|f| f.id).collect();
        Ok(BopDataset { split_dir, root, manifest, models_info, frames, ids })
    }

    /// Opens `root/split`.
    pub fn open_split(root: impl AsRef<Path>, split: &str) -> Result<Self, BopError> {
        Self::open(root.as_ref().join(split))
    }

    pub fn split_dir(&self) -> &Path {
        &self.split_dir
    }

    /// The dataset root (the split folder's parent).
    pub fn root(&self) -> &Path {
        &self.root
    }

    /// `fusepose_dataset.json`, when the dataset has one.
    pub fn manifest(&self) -> Option<&DatasetManifest> {
        self.manifest.as_ref()
    }

    /// `models/models_info.json` in metres, keyed by obj_id, when present.
    pub fn models_info(&self) -> Option<&BTreeMap<u16, BopModelInfo>> {
        self.models_info.as_ref()
    }

    pub fn len(&self) -> usize {
        self.frames.len()
    }

    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// Every frame, by scene then image.
    pub fn frame_ids(&self) -> &[FrameId] {
        &self.ids
    }

    /// The ground truth of frame `index` without loading its images.
    pub fn gt(&self, index: usize) -> Result<&[BopGt], BopError> {
        self.record(index).map(|r| r.gt.as_slice())
    }

    fn record(&self, index: usize) -> Result<&FrameRecord, BopError> {
        self.frames.get(index).ok_or(BopError::FrameOutOfRange { index, len: self.frames.len() })
    }

    /// Loads frame `index`: RGB (`rgb/IIIIII.png`, else `.jpg`), depth, and
    /// the class-id plane from `mask_visib/`.
    pub fn load(&self, index: usize) -> Result<BopFrame, BopError> {
        let r = self.record(index)?;
        let im = r.id.im_id;
        let png = r.scene_dir.join("rgb").join(format!("{im:06}.png"));
        let rgb_path = if png.is_file() { png } else { r.scene_dir.join("rgb").join(format!("{im:06}.jpg")) };
        let rgb = read_rgb8(&rgb_path).map_err(image_err(&rgb_path))?;
        let (w, h) = (rgb.width, rgb.height);
        let depth_path = r.scene_dir.join("depth").join(format!("{im:06}.png"));
        let depth = read_depth_u16(&depth_path).map_err(image_err(&depth_path))?;
        if (depth.width, depth.height) != (w, h) {
            return Err(invalid(&depth_path, format!("{}x{} but the RGB image is {w}x{h}", depth.width, depth.height)));
        }
        let mut labels = vec![0u16; w as usize * h as usize];
        let mut instances = vec![0u16; labels.len()];
        for (k, g) in r.gt.iter().enumerate() {
            let p = r.scene_dir.join("mask_visib").join(format!("{im:06}_{k:06}.png"));
            let mask = read_mask(&p).map_err(image_err(&p))?;
            if (mask.width, mask.height) != (w, h) {
                return Err(invalid(&p, format!("{}x{} but the RGB image is {w}x{h}", mask.width, mask.height)));
            }
            let id = u16::try_from(k + 1).unwrap_or(u16::MAX);
            for ((l, i), &m) in labels.iter_mut().zip(instances.iter_mut()).zip(&mask.data) {
                if m {
                    *l = g.obj_id;
                    *i = id;
                }
            }
        }
        let k = &r.k;
        Ok(BopFrame {
            id: r.id,
            intrinsics: Intrinsics { fx: k[0], fy: k[4], cx: k[2], cy: k[5], width: w, height: h },
            rgb: rgb.data,
            depth: depth.data,
            depth_unit_m: r.depth_scale / 1000.0,
            gt: r.gt.clone(),
            labels,
            instances,
        })
    }

    /// Loads every frame in order.
    pub fn iter(&self) -> impl Iterator<Item = Result<BopFrame, BopError>> + '_ {
        (0..self.len()).map(move |i| self.load(i))
    }
}
