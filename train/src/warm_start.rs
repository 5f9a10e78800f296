//! Warm start: a network for a new object set begins from a trained file's
//! trunk (colour CNN, PointNet, fusion and refiner layers) instead of random
//! weights. Every tensor whose name and shape match is copied; tensors whose
//! shape depends on the number of classes (the per-class heads) stay freshly
//! initialised and are learned from the new objects.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use anyhow::{Context, bail};
use burn::prelude::Device;
use burn::store::ModuleSnapshot;
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

impl WarmStart {
    /// The training log's line for a warm start from `path`.
    pub fn log_line(&self, path: &Path) -> String {
        format!(
            "# warm start from {}: {} tensors copied, {} fresh ({})",
            path.display(),
            self.copied,
            self.fresh.len(),
            self.fresh.join(", ")
        )
    }
}

/// The config a warm-started network for `num_classes` classes uses: the
/// source file's architecture (points, crop, layer sizes) with the class count changed.
pub fn config_for(source: &NetConfig, num_classes: usize) -> NetConfig {
    NetConfig { num_classes, ..source.clone() }
}

/// A pose network for `num_classes` classes with the architecture of the
/// file `path` (read once) and every tensor of it whose name and shape fit copied.
pub fn warm_start(
    path: &Path,
    num_classes: usize,
    device: &Device,
) -> anyhow::Result<(FusionNet, NetConfig, WarmStart)> {
    let source =
        crate::store::load(path, device).with_context(|| format!("reading the warm-start file {}", path.display()))?;
    let cfg = config_for(&source.file.config, num_classes);
    let mut net = FusionNet::new(&cfg, device);
    let w = copy_fitting(&mut net, &source.net, path)?;
    Ok((net, cfg, w))
}

/// Copies into `target` every tensor of `source` (read from `origin`) whose
/// name and shape match one of its own; the others keep their fresh values.
pub fn copy_fitting<T: ModuleSnapshot, S: ModuleSnapshot>(
    target: &mut T,
    source: &S,
    origin: &Path,
) -> anyhow::Result<WarmStart> {
    let shapes: HashMap<String, Vec<usize>> =
        target.collect(None, None, false).iter().map(|t| (t.name.clone(), t.shape.iter().copied().collect())).collect();
    let fits: Vec<_> = source
        .collect(None, None, false)
        .into_iter()
        .filter(|t| shapes.get(&t.name).is_some_and(|s| s.iter().eq(t.shape.iter())))
        .collect();
    if fits.is_empty() {
        bail!("{}: no tensor fits the network (not a fusepose file of this kind?)", origin.display());
    }
    let copied: HashSet<String> = fits.iter().map(|t| t.name.clone()).collect();
    let result = target.apply(fits, None, None, false);
    if !result.errors.is_empty() {
        bail!("{}: warm start failed: {:?}", origin.display(), result.errors);
    }
    let mut fresh: Vec<String> = shapes.into_keys().filter(|n| !copied.contains(n)).collect();
    fresh.sort();
    Ok(WarmStart { copied: copied.len(), fresh })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_estimator::net::meta::TrainRecord;

    #[test]
    fn trunk_tensors_are_copied_and_class_heads_stay_fresh() {
        let device = Device::default();
        let eight = NetConfig::new(8);
        let source = FusionNet::new(&eight, &device);
        let dir = std::env::temp_dir().join(format!("fusepose-warm-{}", std::process::id()));
        let path = dir.join("eight.safetensors");
        let objects = fusepose_estimator::net::meta::object_entries(&fusepose_scene::builtin::builtin_objects());
        crate::store::save(&source, &eight, &objects, &TrainRecord::default(), &path).unwrap();

        let five = config_for(&eight, 5);
        let mut net = FusionNet::new(&five, &device);
        let before = net.collect(None, None, false);
        let loaded = crate::store::load(&path, &device).unwrap();
        let w = copy_fitting(&mut net, &loaded.net, &path).unwrap();
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
