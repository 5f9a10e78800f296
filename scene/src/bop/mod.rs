//! BOP-format datasets (<https://github.com/thodan/bop_toolkit>, `docs/bop_datasets_format.md`):
//! a writer for the datasets `fusepose render` produces and a reader for any
//! BOP split (ours, or e.g. YCB-V in BOP form).
//!
//! Layout, under a dataset root:
//! ```text
//! fusepose_dataset.json            ours: object source + class ids (obj_id = class id)
//! camera.json                      the camera of the first frame written
//! models/models_info.json          diameter, bbox, symmetries (millimetres)
//! models/obj_NNNNNN.ply            meshes in millimetres (vertex colours)
//! <split>/NNNNNN/scene_camera.json cam_K (row-major), depth_scale
//! <split>/NNNNNN/scene_gt.json     cam_R_m2c (row-major), cam_t_m2c (mm), obj_id
//! <split>/NNNNNN/scene_gt_info.json bbox_obj, bbox_visib, px_count_*, visib_fract
//! <split>/NNNNNN/rgb/IIIIII.png    RGB8 (the reader also takes .jpg)
//! <split>/NNNNNN/depth/IIIIII.png  u16; depth in mm = value * depth_scale
//! <split>/NNNNNN/mask_visib/IIIIII_KKKKKK.png  visible mask of GT instance K
//! ```
//! BOP stores millimetres; this module converts to and from metres at the
//! boundary, so every pose and length in its API is in metres. Our depth
//! convention (u16 in units of 0.1 mm) is `depth_scale = 0.1`.

mod error;
pub(crate) mod images;
mod json;
mod manifest;
mod model_ply;
mod models_info;
mod pseudo_labels;
mod reader;
mod writer;

pub use error::BopError;
pub use manifest::{ClassEntry, DatasetManifest, MANIFEST_FILE, ObjectSource};
pub use models_info::{BopModelInfo, BopSymmetry, read_models_info};
pub use pseudo_labels::{
    PSEUDO_MANIFEST_FILE, PseudoLabelFrame, PseudoLabelManifest, PseudoLabelWriter, UNKNOWN_LABEL, read_pseudo_labels,
    read_pseudo_manifest,
};
pub use reader::{BopDataset, BopFrame, BopGt, FrameId};
pub use writer::{BopWriter, FrameToWrite, InstanceToWrite};

#[cfg(test)]
pub(crate) mod tests;
