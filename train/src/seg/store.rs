//! Segmenter weight files (shipped file and checkpoints share the format):
//! burn's safetensors export of [`SegNet`] (F32, conv `[O, I, k, k]`) plus
//! metadata — format tag `fusepose-seg-v1`, [`SegConfig`] JSON, the object
//! list with mesh/sample hashes, the training record (steps, metrics) and the
//! trainer's hyper-parameters. So `resume` accepts either, and also a
//! pose-network file with the segmenter embedded (tensors `seg.*`).

use std::path::Path;

use anyhow::{Context, bail};
use burn::prelude::Device;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use fusepose_estimator::net::meta::{self, ObjectEntry, TrainRecord};
use fusepose_estimator::seg::file::{FORMAT, KEY_CONFIG, KEY_HYPER};
use fusepose_estimator::seg::{SegConfig, SegFile};

use super::model::SegNet;

/// Writes `net` with its metadata to `path` (via a temporary file and a rename).
pub fn save(
    net: &SegNet,
    config: &SegConfig,
    objects: &[ObjectEntry],
    record: &TrainRecord,
    hyper: &serde_json::Value,
    path: &Path,
) -> anyhow::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let tmp = path.with_extension("safetensors.tmp");
    let mut store = SafetensorsStore::from_file(&tmp)
        .overwrite(true)
        .metadata(meta::KEY_FORMAT, FORMAT)
        .metadata(KEY_CONFIG, serde_json::to_string(config)?)
        .metadata(meta::KEY_OBJECTS, serde_json::to_string(objects)?)
        .metadata(meta::KEY_TRAIN, serde_json::to_string(record)?)
        .metadata(KEY_HYPER, hyper.to_string());
    net.save_into(&mut store).map_err(|e| anyhow::anyhow!("saving {}: {e:?}", tmp.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("renaming {} to {}", tmp.display(), path.display()))?;
    Ok(())
}

/// A segmenter loaded from a file, with what the file says about it.
pub struct LoadedSeg {
    pub net: SegNet,
    pub file: SegFile,
}

/// Reads a file (checked by the engine's reader: format, config, shapes) and
/// loads it into a fresh network on `device`.
pub fn load(path: &Path, device: &Device) -> anyhow::Result<LoadedSeg> {
    let file = SegFile::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut net = SegNet::new(&file.config, device);
    let mut store = SafetensorsStore::from_file(path);
    if fusepose_estimator::seg::file::has_embedded(&file.metadata) {
        // A pose-network file with the segmenter embedded: tensors `seg.*`.
        store = store.with_key_remapping(r"^seg\.", "");
    }
    let result = net.load_from(&mut store).map_err(|e| anyhow::anyhow!("loading {}: {e:?}", path.display()))?;
    if !result.missing.is_empty() || !result.errors.is_empty() {
        bail!("{}: missing tensors {:?}, errors {:?}", path.display(), result.missing, result.errors);
    }
    Ok(LoadedSeg { net, file })
}
