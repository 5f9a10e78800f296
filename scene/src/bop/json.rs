//! Serde shapes of the per-scene BOP annotation files, in BOP units
//! (millimetres, row-major matrices), plus atomic JSON file I/O.

use std::collections::BTreeMap;
use std::path::Path;

use serde::de::DeserializeOwned;
use serde::{Deserialize, Serialize};

use super::error::{BopError, io_err, json_err};

/// One image's entry of `scene_camera.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct CameraEntry {
    /// Row-major 3x3 intrinsic matrix (pixels).
    #[serde(rename = "cam_K")]
    pub cam_k: [f64; 9],
    /// Depth in millimetres = depth PNG value * depth_scale.
    pub depth_scale: f64,
}

/// One GT instance of `scene_gt.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct GtEntry {
    /// Row-major rotation, model → camera.
    #[serde(rename = "cam_R_m2c")]
    pub cam_r_m2c: [f64; 9],
    /// Translation, model → camera, millimetres.
    pub cam_t_m2c: [f64; 3],
    pub obj_id: u16,
}

/// One GT instance of `scene_gt_info.json`. Boxes are `[x, y, width, height]`
/// in pixels; `[-1, -1, -1, -1]` when empty.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub(crate) struct GtInfoEntry {
    pub bbox_obj: [i64; 4],
    pub bbox_visib: [i64; 4],
    pub px_count_all: i64,
    #[serde(default)]
    pub px_count_valid: i64,
    pub px_count_visib: i64,
    pub visib_fract: f64,
}

pub(crate) type SceneCamera = BTreeMap<u32, CameraEntry>;
pub(crate) type SceneGt = BTreeMap<u32, Vec<GtEntry>>;
pub(crate) type SceneGtInfo = BTreeMap<u32, Vec<GtInfoEntry>>;

/// Reads and parses a JSON file.
pub(crate) fn read_json<T: DeserializeOwned>(path: &Path) -> Result<T, BopError> {
    let text = std::fs::read_to_string(path).map_err(io_err(path))?;
    serde_json::from_str(&text).map_err(json_err(path))
}

/// Writes `value` as pretty JSON via a temporary file and a rename, so a
/// reader never sees a half-written file.
pub(crate) fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<(), BopError> {
    let text = serde_json::to_string_pretty(value).map_err(json_err(path))?;
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    let tmp = std::path::PathBuf::from(tmp);
    std::fs::write(&tmp, text).map_err(io_err(&tmp))?;
    std::fs::rename(&tmp, path).map_err(io_err(path))
}
