//! Weight files: the shipped model and training checkpoints share one format —
//! burn's safetensors export of [`FusionNet`] (F32; conv `[O, I, 3, 3]`, linear
//! `[in, out]`) plus string metadata: format tag, [`NetConfig`] JSON, object
//! list with mesh/sample hashes, and the [`TrainRecord`] (seed, steps,
//! validation metrics). So `--resume` accepts either.

use std::path::Path;

use anyhow::{Context, bail};
use burn::prelude::Device;
use burn::store::{ModuleSnapshot, SafetensorsStore};
use fusepose_estimator::net::meta::{self, ObjectEntry, TrainRecord};
use fusepose_estimator::net::{NetConfig, WeightFile};

use crate::model::FusionNet;

/// Writes `net` with its metadata to `path` (atomically replacing it).
pub fn save(
    net: &FusionNet,
    config: &NetConfig,
    objects: &[ObjectEntry],
    record: &TrainRecord,
    path: &Path,
) -> anyhow::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let mut store = SafetensorsStore::from_file(path)
        .overwrite(true)
        .metadata(meta::KEY_FORMAT, meta::FORMAT)
        .metadata(meta::KEY_CONFIG, serde_json::to_string(config)?)
        .metadata(meta::KEY_OBJECTS, serde_json::to_string(objects)?)
        .metadata(meta::KEY_TRAIN, serde_json::to_string(record)?);
    net.save_into(&mut store).map_err(|e| anyhow::anyhow!("saving {}: {e:?}", path.display()))?;
    Ok(())
}

/// A network loaded from a weight file, with what the file says about it.
pub struct Loaded {
    pub net: FusionNet,
    pub file: WeightFile,
}

/// Reads a weight file (checked by the engine's reader: format, config, shapes)
/// and loads it into a fresh network on `device`.
pub fn load(path: &Path, device: &Device) -> anyhow::Result<Loaded> {
    let file = WeightFile::read(path).with_context(|| format!("reading {}", path.display()))?;
    let mut net = FusionNet::new(&file.config, device);
    let mut store = SafetensorsStore::from_file(path);
    let result = net.load_from(&mut store).map_err(|e| anyhow::anyhow!("loading {}: {e:?}", path.display()))?;
    if !result.missing.is_empty() || !result.errors.is_empty() {
        bail!("{}: missing tensors {:?}, errors {:?}", path.display(), result.missing, result.errors);
    }
    Ok(Loaded { net, file })
}
