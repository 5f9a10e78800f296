//! Warm start: a network for a new object set begins from a trained file's
//! trunk (colour CNN, PointNet, fusion and refiner layers) instead of random
//! weights. Every tensor whose name and shape match is copied; tensors whose
//! shape depends on the number of classes (the per-class heads) stay freshly
//! initialised and are learned from the new objects.

use std::collections::HashMap;
use std::path::Path;

use anyhow::{Context, bail};
use burn::store::{ModuleSnapshot, SafetensorsStore};
use fusepose_estimator::net::NetConfig;

use crate::model::FusionNet;

/// What [`warm_start`] copied.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct WarmStart {
    /// Tensors copied from the file.
    pub copied: usize,
    /// Tensors left at their fresh initialisation (shape differs or absent).
    pub fresh: Vec<String>,
}

/// The config a warm-started network for `num_classes` classes uses: the
/// source file's architecture (points, crop, layer sizes) with the class count changed.
pub fn config_for(source: &NetConfig, num_classes: usize) -> NetConfig {
    NetConfig { num_classes, ..source.clone() }
}

/// Copies every tensor of `path` whose name and shape match one of `net`'s.
pub fn warm_start(net: &mut FusionNet, path: &Path) -> anyhow::Result<WarmStart> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    let (_, meta) = safetensors::SafeTensors::read_metadata(&bytes)
        .map_err(|e| anyhow::anyhow!("{}: not a safetensors file ({e})", path.display()))?;
    let source: HashMap<String, Vec<usize>> = meta.tensors().into_iter().map(|(n, i)| (n, i.shape.clone())).collect();
    let mut matching = Vec::new();
    let mut fresh = Vec::new();
    for t in net.collect(None, None, false) {
        let dims: Vec<usize> = t.shape.iter().copied().collect();
        if source.get(&t.name) == Some(&dims) {
            matching.push(t.name);
        } else {
            fresh.push(t.name);
        }
    }
    if matching.is_empty() {
        bail!("{}: no tensor matches the network (not a fusepose pose-network file?)", path.display());
    }
    let patterns: Vec<String> = matching.iter().map(|n| format!("^{}$", n.replace('.', r"\."))).collect();
    let mut store = SafetensorsStore::from_file(path).with_regexes(patterns).allow_partial(true);
    let result = net.load_from(&mut store).map_err(|e| anyhow::anyhow!("loading {}: {e:?}", path.display()))?;
    if !result.errors.is_empty() {
        bail!("{}: warm start failed: {:?}", path.display(), result.errors);
    }
    Ok(WarmStart { copied: result.applied.len(), fresh })
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::prelude::Device;
    use fusepose_estimator::net::meta::TrainRecord;

    #[test]
    fn trunk_tensors_are_copied_and_class_heads_stay_fresh() {
        let device = Device::default();
        let eight = NetConfig::new(8);
        let source = FusionNet::new(&eight, &device);
        let dir = std::env::temp_dir().join(format!("fusepose-warm-{}", std::process::id()));
        let path = dir.join("eight.safetensors");
        crate::store::save(&source, &eight, &[], &TrainRecord::default(), &path).unwrap();

        let five = config_for(&eight, 5);
        let mut net = FusionNet::new(&five, &device);
        let before = net.collect(None, None, false);
        let w = warm_start(&mut net, &path).unwrap();
        let after = net.collect(None, None, false);
        let src: HashMap<String, Vec<u8>> = source
            .collect(None, None, false)
            .into_iter()
            .map(|t| (t.name.clone(), t.to_bytes().unwrap().to_vec()))
            .collect();
        assert!(w.copied > 0 && !w.fresh.is_empty(), "{w:?}");
        assert_eq!(w.copied + w.fresh.len(), after.len());
        for (b, a) in before.iter().zip(&after) {
            let now = a.to_bytes().unwrap().to_vec();
            if w.fresh.contains(&a.name) {
                assert_eq!(now, b.to_bytes().unwrap().to_vec(), "{} kept its init", a.name);
                assert_ne!(src.get(&a.name).map(Vec::len), Some(now.len()), "{} has a class-sized shape", a.name);
            } else {
                assert_eq!(Some(&now), src.get(&a.name), "{} copied", a.name);
            }
        }
        let _ = std::fs::remove_dir_all(dir);
    }
}
