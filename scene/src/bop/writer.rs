//! Writes one split of a BOP dataset frame by frame (see the module docs for
//! the layout). Each frame's images are written at once and its scene's three
//! JSON files are rewritten atomically after every frame, so an interrupted
//! render leaves a readable dataset of the frames written so far.

use std::path::{Path, PathBuf};

use nalgebra::Point3;

use super::error::{BopError, image_err, invalid, io_err};
use super::images::{write_rgb8_png, write_u8_png, write_u16_png};
use super::json::{CameraEntry, GtEntry, GtInfoEntry, SceneCamera, SceneGt, SceneGtInfo, read_json, write_json};
use super::manifest::{DatasetManifest, MANIFEST_FILE, ObjectSource};
use super::model_ply::write_model_ply;
use super::models_info::write_models_info;
use crate::{Intrinsics, ObjectSet, Pose};

/// One ground-truth object instance of a frame to write.
#[derive(Clone, Debug, PartialEq)]
pub struct InstanceToWrite {
    /// BOP obj_id = our class id (1-based index into the writer's object set).
    pub obj_id: u16,
    /// Object → camera, metres.
    pub pose: Pose,
    /// This instance's value in [`FrameToWrite::instance_labels`] (non-zero,
    /// unique within the frame).
    pub instance_label: u16,
    /// Pixels the instance covers inside the image when rendered alone
    /// (`ItemCoverage::alone_pixels`). `None` when unknown: the visible count
    /// is used, so `visib_fract` is then 1 for any visible instance.
    pub px_count_all: Option<u32>,
}

impl InstanceToWrite {
    /// Every object of a rendered view's truth, with its pose, label and
    /// unoccluded pixel count (what `fusepose render` writes).
    pub fn of_truth(truth: &crate::sampler::FrameTruth) -> Vec<Self> {
        truth
            .objects
            .iter()
            .map(|o| Self {
                obj_id: o.class_id,
                pose: o.pose,
                instance_label: o.instance_label,
                px_count_all: Some(o.alone_pixels),
            })
            .collect()
    }
}

/// One frame to write: planes row-major, top row first, sized by `intrinsics`.
#[derive(Clone, Copy, Debug)]
pub struct FrameToWrite<'a> {
    pub scene_id: u32,
    pub im_id: u32,
    pub intrinsics: Intrinsics,
    /// RGB8, `width * height * 3` bytes.
    pub rgb: &'a [u8],
    /// Depth, `width * height` values in units of `depth_unit_m`; 0 = missing.
    pub depth: &'a [u16],
    /// Metres per depth unit (1e-4 for our 0.1 mm convention → BOP depth_scale 0.1).
    pub depth_unit_m: f64,
    /// Instance label per pixel (0 = background), as `RenderTarget::labels`.
    pub instance_labels: &'a [u16],
    pub instances: &'a [InstanceToWrite],
}

impl<'a> FrameToWrite<'a> {
    /// The frame the renderer left in `target` for a view whose truth is
    /// `truth`, with the camera the truth reports (jittered per view under
    /// randomisation) and depth in the renderer's units.
    pub fn rendered(
        scene_id: u32,
        im_id: u32,
        truth: &crate::sampler::FrameTruth,
        target: &'a crate::render::RenderTarget,
        instances: &'a [InstanceToWrite],
    ) -> Self {
        Self {
            scene_id,
            im_id,
            intrinsics: truth.intrinsics,
            rgb: target.rgb(),
            depth: target.depth_u16(),
            depth_unit_m: 1.0 / crate::render::DEPTH_U16_PER_METRE,
            instance_labels: target.labels(),
            instances,
        }
    }
}

struct SceneState {
    scene_id: u32,
    dir: PathBuf,
    camera: SceneCamera,
    gt: SceneGt,
    info: SceneGtInfo,
}

/// Writes frames of one split into a BOP dataset root.
pub struct BopWriter {
    root: PathBuf,
    split: String,
    split_dir: PathBuf,
    /// Mesh vertices per class (object frame, metres), for `bbox_obj`.
    vertices: Vec<Vec<Point3<f64>>>,
    scene: Option<SceneState>,
    frames_written: usize,
}

fn valid_split_name(s: &str) -> bool {
    !s.is_empty()
        && s != "."
        && s != ".."
        && s.chars().all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'))
}

impl BopWriter {
    /// Prepares `root/split/` for writing: creates folders, writes
    /// `models/models_info.json` and `models/obj_NNNNNN.ply` for `objects` and adds the split to
    /// `fusepose_dataset.json` (created, or checked to name the same object
    /// set). Fails if `root/split/` exists and is not empty.
    pub fn create(root: &Path, split: &str, objects: &ObjectSet, source: &ObjectSource) -> Result<Self, BopError> {
        if !valid_split_name(split) {
            return Err(invalid(root, format!("split name {split:?} must be letters, digits, '_', '-', '.'")));
        }
        if objects.is_empty() {
            return Err(invalid(root, "the object set is empty"));
        }
        let split_dir = root.join(split);
        if split_dir.is_dir() && std::fs::read_dir(&split_dir).map_err(io_err(&split_dir))?.next().is_some() {
            return Err(BopError::SplitNotEmpty { path: split_dir });
        }
        let mut manifest = DatasetManifest::new(source.clone(), objects);
        if let Some(existing) = DatasetManifest::read(root)? {
            if existing.objects != manifest.objects || existing.classes != manifest.classes {
                return Err(BopError::ObjectSetMismatch {
                    path: root.join(MANIFEST_FILE),
                    existing: existing.objects.to_string(),
                    requested: source.to_string(),
                });
            }
            manifest.splits = existing.splits;
        }
        std::fs::create_dir_all(&split_dir).map_err(io_err(&split_dir))?;
        let models_dir = root.join("models");
        std::fs::create_dir_all(&models_dir).map_err(io_err(&models_dir))?;
        manifest.splits.insert(split.to_string(), serde_json::Value::Null);
        write_json(&root.join(MANIFEST_FILE), &manifest)?;
        write_models_info(&models_dir.join("models_info.json"), objects)?;
        for (i, o) in objects.objects.iter().enumerate() {
            write_model_ply(&models_dir.join(format!("obj_{:06}.ply", i + 1)), &o.mesh)?;
        }

        let vertices = objects
            .objects
            .iter()
            .map(|o| o.mesh.positions.iter().map(|p| Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)).collect())
            .collect();
        Ok(BopWriter {
            root: root.to_path_buf(),
            split: split.to_string(),
            split_dir,
            vertices,
            scene: None,
            frames_written: 0,
        })
    }

    /// Records the generator's parameters for this split in `fusepose_dataset.json`.
    pub fn set_split_params(&mut self, params: serde_json::Value) -> Result<(), BopError> {
        let path = self.root.join(MANIFEST_FILE);
        let mut manifest: DatasetManifest = read_json(&path)?;
        manifest.splits.insert(self.split.clone(), params);
        write_json(&path, &manifest)
    }

    /// The split folder (`root/split`).
    pub fn split_dir(&self) -> &Path {
        &self.split_dir
    }

    /// Frames written so far.
    pub fn frames_written(&self) -> usize {
        self.frames_written
    }

    fn check(&self, f: &FrameToWrite<'_>) -> Result<(), BopError> {
        let bad = |message: String| BopError::BadFrame { scene_id: f.scene_id, im_id: f.im_id, message };
        let (w, h) = (f.intrinsics.width, f.intrinsics.height);
        let n = w as usize * h as usize;
        if n == 0 {
            return Err(bad(format!("image size {w}x{h} is empty")));
        }
        if f.rgb.len() != n * 3 {
            return Err(bad(format!("rgb has {} bytes, expected {} for {w}x{h}", f.rgb.len(), n * 3)));
        }
        if f.depth.len() != n {
            return Err(bad(format!("depth has {} values, expected {n}", f.depth.len())));
        }
        if f.instance_labels.len() != n {
            return Err(bad(format!("instance_labels has {} values, expected {n}", f.instance_labels.len())));
        }
        if !(f.depth_unit_m.is_finite() && f.depth_unit_m > 0.0) {
            return Err(bad(format!("depth_unit_m must be finite and > 0, got {}", f.depth_unit_m)));
        }
        let k = &f.intrinsics;
        if ![k.fx, k.fy, k.cx, k.cy].iter().all(|v| v.is_finite()) {
            return Err(bad("intrinsics are not finite".into()));
        }
        for (i, inst) in f.instances.iter().enumerate() {
            if inst.obj_id == 0 || inst.obj_id as usize > self.vertices.len() {
                return Err(bad(format!("instance {i}: obj_id {} is not in the object set", inst.obj_id)));
            }
            if inst.instance_label == 0 {
                return Err(bad(format!("instance {i}: instance_label 0 is background")));
            }
            if f.instances[..i].iter().any(|o| o.instance_label == inst.instance_label) {
                return Err(bad(format!("instance {i}: instance_label {} is used twice", inst.instance_label)));
            }
            let p = &inst.pose;
            if !(p.translation.vector.iter().all(|v| v.is_finite()) && p.rotation.coords.iter().all(|v| v.is_finite()))
            {
                return Err(bad(format!("instance {i}: pose is not finite")));
            }
        }
        Ok(())
    }

    fn enter_scene(&mut self, scene_id: u32) -> Result<(), BopError> {
        if self.scene.as_ref().is_some_and(|s| s.scene_id == scene_id) {
            return Ok(());
        }
        let dir = self.split_dir.join(format!("{scene_id:06}"));
        for sub in ["rgb", "depth", "mask_visib"] {
            let d = dir.join(sub);
            std::fs::create_dir_all(&d).map_err(io_err(&d))?;
        }
        // Returning to a scene written earlier by this writer: continue its files.
        let load = |name: &str| dir.join(name).is_file();
        let (camera, gt, info) = if load("scene_gt.json") && load("scene_camera.json") && load("scene_gt_info.json") {
            (
                read_json(&dir.join("scene_camera.json"))?,
                read_json(&dir.join("scene_gt.json"))?,
                read_json(&dir.join("scene_gt_info.json"))?,
            )
        } else {
            Default::default()
        };
        self.scene = Some(SceneState { scene_id, dir, camera, gt, info });
        Ok(())
    }

    /// `bbox_obj`: the bounding box of the projected mesh vertices, which is
    /// the box of the full silhouette (pixels whose centres it covers), not
    /// clipped to the image. `[-1; 4]` if a vertex is behind the camera or no
    /// pixel centre is covered.
    fn bbox_obj(&self, obj_id: u16, pose: &Pose, k: &Intrinsics) -> [i64; 4] {
        let mut lo = [f64::INFINITY; 2];
        let mut hi = [f64::NEG_INFINITY; 2];
        for p in &self.vertices[obj_id as usize - 1] {
            let Some((u, v)) = k.project(&(pose * p)) else {
                return [-1; 4];
            };
            lo = [lo[0].min(u), lo[1].min(v)];
            hi = [hi[0].max(u), hi[1].max(v)];
        }
        let (x0, y0, x1, y1) = (lo[0].ceil(), lo[1].ceil(), hi[0].floor(), hi[1].floor());
        if !(x0.is_finite() && y0.is_finite() && x1 >= x0 && y1 >= y0) {
            return [-1; 4];
        }
        [x0 as i64, y0 as i64, (x1 - x0) as i64 + 1, (y1 - y0) as i64 + 1]
    }

    /// Writes one frame: `rgb/`, `depth/`, one `mask_visib/` PNG per instance,
    /// and the scene's updated JSON files.
    pub fn write_frame(&mut self, f: &FrameToWrite<'_>) -> Result<(), BopError> {
        self.check(f)?;
        let (w, h) = (f.intrinsics.width, f.intrinsics.height);
        let depth_scale = (f.depth_unit_m * 1000.0 * 1e12).round() / 1e12;
        let mut gt_entries = Vec::with_capacity(f.instances.len());
        let mut info_entries = Vec::with_capacity(f.instances.len());
        let mut masks = Vec::with_capacity(f.instances.len());
        for inst in f.instances {
            let mut mask = vec![0u8; w as usize * h as usize];
            let (mut count, mut valid) = (0i64, 0i64);
            let (mut u0, mut v0, mut u1, mut v1) = (u32::MAX, u32::MAX, 0u32, 0u32);
            for (i, (&l, &d)) in f.instance_labels.iter().zip(f.depth).enumerate() {
                if l == inst.instance_label {
                    mask[i] = 255;
                    count += 1;
                    if d > 0 {
                        valid += 1;
                    }
                    let (u, v) = ((i % w as usize) as u32, (i / w as usize) as u32);
                    (u0, v0, u1, v1) = (u0.min(u), v0.min(v), u1.max(u), v1.max(v));
                }
            }
            let bbox_visib =
                if count == 0 { [-1; 4] } else { [u0 as i64, v0 as i64, (u1 - u0) as i64 + 1, (v1 - v0) as i64 + 1] };
            let all = inst.px_count_all.map(i64::from).unwrap_or(count).max(count);
            let r = inst.pose.rotation.to_rotation_matrix();
            let m = r.matrix();
            let t = inst.pose.translation.vector * 1000.0;
            gt_entries.push(GtEntry {
                cam_r_m2c: std::array::from_fn(|k| m[(k / 3, k % 3)]),
                cam_t_m2c: [t.x, t.y, t.z],
                obj_id: inst.obj_id,
            });
            info_entries.push(GtInfoEntry {
                bbox_obj: self.bbox_obj(inst.obj_id, &inst.pose, &f.intrinsics),
                bbox_visib,
                px_count_all: all,
                px_count_valid: valid,
                px_count_visib: count,
                visib_fract: if all == 0 { 0.0 } else { count as f64 / all as f64 },
            });
            masks.push(mask);
        }

        self.enter_scene(f.scene_id)?;
        let scene = self.scene.as_mut().expect("enter_scene sets the scene");
        let rgb_path = scene.dir.join("rgb").join(format!("{:06}.png", f.im_id));
        write_rgb8_png(&rgb_path, w, h, f.rgb).map_err(image_err(&rgb_path))?;
        let depth_path = scene.dir.join("depth").join(format!("{:06}.png", f.im_id));
        write_u16_png(&depth_path, w, h, f.depth).map_err(image_err(&depth_path))?;
        for (k, mask) in masks.iter().enumerate() {
            let p = scene.dir.join("mask_visib").join(format!("{:06}_{k:06}.png", f.im_id));
            write_u8_png(&p, w, h, mask).map_err(image_err(&p))?;
        }
        scene.camera.insert(f.im_id, CameraEntry { cam_k: f.intrinsics.matrix(), depth_scale });
        scene.gt.insert(f.im_id, gt_entries);
        scene.info.insert(f.im_id, info_entries);
        write_json(&scene.dir.join("scene_camera.json"), &scene.camera)?;
        write_json(&scene.dir.join("scene_gt.json"), &scene.gt)?;
        write_json(&scene.dir.join("scene_gt_info.json"), &scene.info)?;

        let camera_path = self.root.join("camera.json");
        if !camera_path.exists() {
            let k = &f.intrinsics;
            let camera = serde_json::json!({
                "cx": k.cx, "cy": k.cy, "depth_scale": depth_scale,
                "fx": k.fx, "fy": k.fy, "height": k.height, "width": k.width,
            });
            write_json(&camera_path, &camera)?;
        }
        self.frames_written += 1;
        Ok(())
    }
}
