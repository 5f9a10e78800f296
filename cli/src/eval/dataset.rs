//! The datasets `fusepose eval` reads, behind one frame type: a BOP split
//! (ours from `fusepose render`, or any BOP dataset) or YCB-Video.
//!
//! Class ids are mapped onto the evaluated object set (class id `i + 1` ↔
//! `objects[i]`): BOP `obj_id` is taken as the class id (our datasets write it
//! so); YCB-Video class names (`classes.txt`) are matched to object names.

use std::path::Path;

use anyhow::{Context, bail};
use fusepose_scene::bop::{BopDataset, ObjectSource};
use fusepose_scene::ycbv::YcbVideo;
use fusepose_scene::{Intrinsics, ObjectSet, Pose};

/// One ground-truth object, class id in the evaluated object set.
#[derive(Clone, Debug)]
pub struct GtObject {
    pub class_id: u16,
    /// Object → camera, metres.
    pub pose: Pose,
    /// Visible share of the object's silhouette, 0..=1 (BOP `visib_fract`;
    /// `None` where the dataset does not say).
    pub visible: Option<f64>,
}

/// One frame with ground truth, class ids mapped onto the object set.
pub struct EvalFrame {
    pub scene_id: u32,
    pub im_id: u32,
    pub intrinsics: Intrinsics,
    /// RGB8, width * height * 3.
    pub rgb: Vec<u8>,
    /// Raw depth; metres = value * `depth_unit_m`; 0 = missing.
    pub depth: Vec<u16>,
    pub depth_unit_m: f64,
    /// Ground-truth class-id plane (0 = background or an object not in the set).
    pub labels: Vec<u16>,
    /// Ground-truth instance ids per pixel (`k + 1` for `gt[k]`, 0 = none;
    /// all 0 where the dataset has no instance masks, e.g. YCB-Video).
    pub instances: Vec<u16>,
    /// Instance id → class id for [`EvalFrame::instances`] (index 0 = background).
    pub instance_classes: Vec<u16>,
    /// Ground-truth objects of the set (objects outside it are left out).
    pub gt: Vec<GtObject>,
}

/// A dataset to evaluate on.
pub enum EvalDataset {
    Bop(BopDataset),
    Ycb { data: YcbVideo, to_set: Vec<u16> },
}

impl EvalDataset {
    /// Opens `path` as YCB-Video (has `image_sets/keyframe.txt`), a BOP split
    /// folder (has `NNNNNN/scene_gt.json`), or a BOP root with `split/`.
    pub fn open(path: &Path, split: &str) -> anyhow::Result<Self> {
        if path.join("image_sets").join("keyframe.txt").is_file() {
            let data = YcbVideo::open(path).with_context(|| format!("opening YCB-Video at {}", path.display()))?;
            return Ok(EvalDataset::Ycb { data, to_set: Vec::new() });
        }
        let split_dir = crate::dataset_path::resolve_bop_split(path, split)?;
        let bop = BopDataset::open(&split_dir).with_context(|| format!("opening BOP split {}", split_dir.display()))?;
        Ok(EvalDataset::Bop(bop))
    }

    /// The BOP split folder the frames come from (absolute when it can be);
    /// an error for YCB-Video, which `--pseudo-labels` does not take.
    pub fn split_dir(&self) -> anyhow::Result<std::path::PathBuf> {
        match self {
            EvalDataset::Bop(b) => {
                Ok(std::fs::canonicalize(b.split_dir()).unwrap_or_else(|_| b.split_dir().to_path_buf()))
            }
            EvalDataset::Ycb { .. } => anyhow::bail!("--pseudo-labels needs a BOP split, not YCB-Video"),
        }
    }

    /// The object set the dataset names (`builtin` or a mesh folder), if any.
    pub fn object_source(&self) -> Option<String> {
        match self {
            EvalDataset::Bop(b) => b.manifest().map(|m| match &m.objects {
                ObjectSource::Builtin => "builtin".to_string(),
                ObjectSource::Directory(p) => p.display().to_string(),
            }),
            EvalDataset::Ycb { .. } => None,
        }
    }

    /// Binds the dataset's class ids to `set`; fails when names don't match.
    pub fn bind(&mut self, set: &ObjectSet) -> anyhow::Result<()> {
        match self {
            EvalDataset::Bop(b) => {
                if let Some(m) = b.manifest() {
                    for c in &m.classes {
                        match set.by_class(c.obj_id) {
                            Some(o) if o.name == c.name => {}
                            other => bail!(
                                "dataset class {} is `{}` but the object set has {}",
                                c.obj_id,
                                c.name,
                                other.map_or("nothing".to_string(), |o| format!("`{}`", o.name))
                            ),
                        }
                    }
                }
                Ok(())
            }
            EvalDataset::Ycb { data, to_set } => {
                *to_set = std::iter::once(0)
                    .chain(data.classes().iter().map(|name| set.class_of(name).unwrap_or(0)))
                    .collect();
                if to_set.iter().all(|&c| c == 0) {
                    bail!("no YCB-Video class name matches an object of the set ({} objects)", set.len());
                }
                Ok(())
            }
        }
    }

    pub fn len(&self) -> usize {
        match self {
            EvalDataset::Bop(b) => b.len(),
            EvalDataset::Ycb { data, .. } => data.len(),
        }
    }

    /// Loads frame `index` with class ids mapped onto the bound set.
    pub fn load(&self, index: usize, num_classes: u16) -> anyhow::Result<EvalFrame> {
        let known = |c: u16| if c <= num_classes { c } else { 0 };
        match self {
            EvalDataset::Bop(b) => {
                let f = b.load(index)?;
                Ok(EvalFrame {
                    scene_id: f.id.scene_id,
                    im_id: f.id.im_id,
                    intrinsics: f.intrinsics,
                    rgb: f.rgb,
                    depth: f.depth,
                    depth_unit_m: f.depth_unit_m,
                    labels: f.labels.into_iter().map(known).collect(),
                    instance_classes: std::iter::once(0).chain(f.gt.iter().map(|g| known(g.obj_id))).collect(),
                    instances: f.instances,
                    gt: f
                        .gt
                        .iter()
                        .filter(|g| known(g.obj_id) != 0)
                        .map(|g| GtObject { class_id: g.obj_id, pose: g.pose, visible: Some(g.visib_fract) })
                        .collect(),
                })
            }
            EvalDataset::Ycb { data, to_set } => {
                let f = data.load(index)?;
                let map = |c: u16| to_set.get(c as usize).copied().unwrap_or(0);
                let (scene_id, im_id) = ycb_ids(&f.id);
                Ok(EvalFrame {
                    scene_id,
                    im_id,
                    intrinsics: f.intrinsics,
                    rgb: f.rgb,
                    depth: f.depth,
                    depth_unit_m: f.depth_unit_m,
                    instances: vec![0; f.labels.len()],
                    instance_classes: vec![0],
                    labels: f.labels.into_iter().map(map).collect(),
                    gt: f
                        .gt
                        .iter()
                        .filter(|g| map(g.class_id) != 0)
                        .map(|g| GtObject { class_id: map(g.class_id), pose: g.pose, visible: None })
                        .collect(),
                })
            }
        }
    }
}

/// `(video, frame)` numbers of a YCB-Video entry like `0048/000001`.
fn ycb_ids(entry: &str) -> (u32, u32) {
    let mut parts = entry.rsplit('/');
    let im = parts.next().and_then(|s| s.parse().ok()).unwrap_or(0);
    let scene = parts.next().and_then(|s| s.parse().ok()).unwrap_or(0);
    (scene, im)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ycb_entry_numbers() {
        assert_eq!(ycb_ids("0048/000001"), (48, 1));
        assert_eq!(ycb_ids("data/0059/000123"), (59, 123));
        assert_eq!(ycb_ids("garbage"), (0, 0));
    }
}
