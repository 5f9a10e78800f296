//! Warm start: a network for a new object set begins from a trained file's
//! trunk (colour CNN, PointNet, fusion and refiner layers) instead of random
//! weights. Every tensor whose name and shape match is copied; tensors whose
//! shape depends on the number of classes (the per-class heads) stay freshly
//! initialised and are learned from the new objects, or, with
//! [`WarmHeads::ClassMean`], the heads whose output does not depend on the
//! object's own frame start from the mean of the source's classes.

use std::collections::{HashMap, HashSet};
use std::path::Path;

use anyhow::{Context, bail};
use burn::module::Param;
use burn::nn::Linear;
use burn::prelude::{Device, Tensor};
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
    /// Heads set to the mean of the source's classes ([`WarmHeads::ClassMean`]).
    pub class_mean: Vec<String>,
}

impl WarmStart {
    /// The training log's line for a warm start from `path`.
    pub fn log_line(&self, path: &Path) -> String {
        let mean = if self.class_mean.is_empty() {
            String::new()
        } else {
            format!("; heads from the mean of its classes: {}", self.class_mean.join(", "))
        };
        format!(
            "# warm start from {}: {} tensors copied, {} fresh ({}){mean}",
            path.display(),
            self.copied,
            self.fresh.len(),
            self.fresh.join(", ")
        )
    }
}

/// How a warm start's per-class output layers begin.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum WarmHeads {
    /// Freshly initialised, like a cold run's.
    #[default]
    Fresh,
    /// The pose net's translation and confidence heads and the refiner's
    /// translation head start, for every new class, as the mean of the
    /// source's per-class heads: a point's offset to its object's centre (in
    /// the camera frame) and how far to trust a point do not depend on which
    /// object it is, so every source class taught the same thing. The
    /// rotation heads stay fresh: a rotation is in each object's own frame.
    ClassMean,
}

impl WarmHeads {
    /// The spelling of the command line (`--warm-heads`).
    pub fn parse(s: &str) -> anyhow::Result<Self> {
        match s {
            "fresh" => Ok(Self::Fresh),
            "class-mean" => Ok(Self::ClassMean),
            _ => bail!("--warm-heads takes fresh or class-mean, not {s:?}"),
        }
    }
}

/// The config a warm-started network for `num_classes` classes uses: the
/// source file's architecture (points, crop, layer sizes) with the class count changed.
pub fn config_for(source: &NetConfig, num_classes: usize) -> NetConfig {
    NetConfig { num_classes, ..source.clone() }
}

/// A pose network for `num_classes` classes with the architecture of the
/// file `path` (read once) and every tensor of it whose name and shape fit copied.
/// The per-class heads begin as `heads` says.
pub fn warm_start(
    path: &Path,
    num_classes: usize,
    heads: WarmHeads,
    device: &Device,
) -> anyhow::Result<(FusionNet, NetConfig, WarmStart)> {
    let source =
        crate::store::load(path, device).with_context(|| format!("reading the warm-start file {}", path.display()))?;
    let cfg = config_for(&source.file.config, num_classes);
    let mut net = FusionNet::new(&cfg, device);
    let mut w = copy_fitting(&mut net, &source.net, path)?;
    if heads == WarmHeads::ClassMean {
        let (k_src, k) = (source.file.config.num_classes, num_classes);
        let (from, to) = (&source.net, &mut net);
        for (name, src, dst, width) in [
            ("pose.tra", &from.pose.tra, &mut to.pose.tra, 3),
            ("pose.conf", &from.pose.conf, &mut to.pose.conf, 1),
            ("refine.tra", &from.refine.tra, &mut to.refine.tra, 3),
        ] {
            *dst = class_mean(src, k_src, k, width);
            w.fresh.retain(|f| !f.starts_with(&format!("{name}.")));
            w.class_mean.push(name.to_owned());
        }
    }
    Ok((net, cfg, w))
}

/// A head of `k` classes × `width` outputs, each class's block the mean of
/// the `k_src` blocks of `src` (weights `[in, k_src·width]`, bias `[k_src·width]`).
fn class_mean(src: &Linear, k_src: usize, k: usize, width: usize) -> Linear {
    let weight = src.weight.val();
    let [d_in, _] = weight.dims();
    // Detached: a parameter must be a leaf of the autodiff graph.
    let weight: Tensor<2> =
        weight.reshape([d_in, k_src, width]).mean_dim(1).repeat_dim(1, k).reshape([d_in, k * width]).detach();
    let bias = src.bias.as_ref().map(|b| {
        let mean: Tensor<1> = b.val().reshape([k_src, width]).mean_dim(0).repeat_dim(0, k).reshape([k * width]);
        Param::from_tensor(mean.detach())
    });
    Linear { weight: Param::from_tensor(weight), bias }
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
    Ok(WarmStart { copied: copied.len(), fresh, class_mean: Vec::new() })
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_estimator::net::meta::TrainRecord;
    use std::path::PathBuf;

    /// A random 8-class network saved as a file in a new folder `name`: (net, config, folder, file).
    fn eight_class_file(name: &str, device: &Device) -> (FusionNet, NetConfig, PathBuf, PathBuf) {
        let eight = NetConfig::new(8);
        let source = FusionNet::new(&eight, device);
        let dir = std::env::temp_dir().join(format!("fusepose-{name}-{}", std::process::id()));
        let path = dir.join("eight.safetensors");
        let objects = fusepose_estimator::net::meta::object_entries(&fusepose_scene::builtin::builtin_objects());
        crate::store::save(&source, &eight, &objects, &TrainRecord::default(), &path).unwrap();
        (source, eight, dir, path)
    }

    #[test]
    fn trunk_tensors_are_copied_and_class_heads_stay_fresh() {
        let device = Device::default();
        let (source, eight, dir, path) = eight_class_file("warm", &device);

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

    #[test]
    fn class_mean_heads_start_as_the_mean_of_the_source_classes() {
        // The trainer's device: with autodiff, where a head made by tensor ops must be a leaf.
        let device = crate::device::TrainDevice::Cpu.autodiff().unwrap();
        let (source, _, dir, path) = eight_class_file("warm-mean", &device);
        let values = |t: Tensor<2>| t.into_data().try_to_vec::<f32>().unwrap();

        let (net, cfg, w) = warm_start(&path, 3, WarmHeads::ClassMean, &device).unwrap();
        assert_eq!(cfg.num_classes, 3);
        assert_eq!(w.class_mean, ["pose.tra", "pose.conf", "refine.tra"]);
        assert!(w.fresh.iter().all(|f| f.starts_with("pose.rot.") || f.starts_with("refine.rot.")), "{:?}", w.fresh);
        for (src, dst, width) in [
            (&source.pose.tra, &net.pose.tra, 3),
            (&source.pose.conf, &net.pose.conf, 1),
            (&source.refine.tra, &net.refine.tra, 3),
        ] {
            let (s, d) = (values(src.weight.val()), values(dst.weight.val()));
            let (s_cols, d_cols) = (8 * width, 3 * width);
            let rows = s.len() / s_cols;
            assert_eq!(d.len(), rows * d_cols);
            for r in [0, rows / 2, rows - 1] {
                for j in 0..width {
                    let mean = (0..8).map(|c| s[r * s_cols + c * width + j]).sum::<f32>() / 8.0;
                    for c in 0..3 {
                        let got = d[r * d_cols + c * width + j];
                        assert!((got - mean).abs() < 1e-6, "row {r} out {j} class {c}: {got} vs {mean}");
                    }
                }
            }
            let (sb, db) = (src.bias.as_ref().unwrap().val(), dst.bias.as_ref().unwrap().val());
            let (sb, db) = (sb.into_data().try_to_vec::<f32>().unwrap(), db.into_data().try_to_vec::<f32>().unwrap());
            for j in 0..width {
                let mean = (0..8).map(|c| sb[c * width + j]).sum::<f32>() / 8.0;
                assert!((0..3).all(|c| (db[c * width + j] - mean).abs() < 1e-6));
            }
        }
        // The rotation heads are the fresh network's, not the source's.
        let (fresh, _, _) = warm_start(&path, 3, WarmHeads::Fresh, &device).unwrap();
        assert_eq!(values(fresh.pose.tra.weight.val()).len(), values(net.pose.tra.weight.val()).len());
        assert_ne!(values(fresh.pose.tra.weight.val()), values(net.pose.tra.weight.val()));
        assert!(WarmHeads::parse("mean").unwrap_err().to_string().contains("class-mean"));
        // The new heads are parameters the optimiser can train (leaves of the graph).
        let _trainable = burn::module::Module::set_require_grad(net, true);
        let _ = std::fs::remove_dir_all(dir);
    }
}
