//! Reading a segmenter weight file: safetensors parsing, metadata (format tag,
//! [`SegConfig`], object list, training record), every tensor's dtype and shape,
//! and matching against an object set. Errors are the network loader's typed
//! [`NetLoadError`]; nothing panics on a bad file.
//!
//! Two layouts: a segmenter-only file (format `fusepose-seg-v1`, tensors
//! `e1.weight` …, the usual object/train keys) and a pose-network file with
//! the segmenter embedded (format `fusepose-net-v1`, tensors `seg.e1.weight` …,
//! keys `fusepose.seg.*`), so one shipped file holds one object set's networks.
//! [`embed`] writes the second from the first.

use std::collections::HashMap;
use std::path::Path;

use fusepose_scene::ObjectSet;
use safetensors::{Dtype, SafeTensors};

use super::config::SegConfig;
use crate::net::NetLoadError;
use crate::net::meta::{self, ObjectEntry, TrainRecord};

/// File format tag of segmenter files (the `fusepose.format` metadata value).
pub const FORMAT: &str = "fusepose-seg-v1";
/// Metadata key of the [`SegConfig`] JSON.
pub const KEY_CONFIG: &str = "fusepose.seg.config";
/// Metadata key of the trainer's hyper-parameters (free-form JSON, informative only).
pub const KEY_HYPER: &str = "fusepose.seg.hyper";
/// Embedded in a pose-network file: the segmenter's object list and training record
/// (the file's own `fusepose.objects` / `fusepose.train` describe the pose network).
pub const KEY_EMBEDDED_OBJECTS: &str = "fusepose.seg.objects";
pub const KEY_EMBEDDED_TRAIN: &str = "fusepose.seg.train";
/// Metadata key of the segmenter's measured [`Certainty`] of real objects
/// (same key in both layouts; absent in files calibrated by no one).
pub const KEY_CERTAINTY: &str = "fusepose.seg.certainty";
/// The quantile of a segmenter's [`Certainty`] below which the daemon and
/// `fusepose eval` fail a pose on its region by default (docs/BENCHMARKS.md,
/// "Session 20": 5 % cut ghosts by a fifth on the tuning splits of the
/// shipped segmenter and cost nothing on those of a 14-minute one; 10 %
/// cost 2.7 ADD(S) on path-traced images).
pub const DEFAULT_CERTAINTY_QUANTILE: f32 = 0.05;
/// Tensor name prefix of an embedded segmenter.
pub const EMBEDDED_PREFIX: &str = "seg.";

/// Whether a pose-network file's metadata says it has a segmenter embedded.
pub fn has_embedded(metadata: &HashMap<String, String>) -> bool {
    metadata.get(meta::KEY_FORMAT).is_some_and(|f| f == meta::FORMAT) && metadata.contains_key(KEY_CONFIG)
}

/// A parsed, checked segmenter file.
#[derive(Clone, Debug)]
pub struct SegFile {
    pub config: SegConfig,
    pub objects: Vec<ObjectEntry>,
    pub train: Option<TrainRecord>,
    /// How sure the segmenter is of real objects, when measured.
    pub certainty: Option<Certainty>,
    /// All metadata as stored.
    pub metadata: HashMap<String, String>,
    tensors: HashMap<String, Vec<f32>>,
}

/// How sure a segmenter is of real objects: percentiles 1..=50 of its peak
/// probability of an object's class over the object's true region
/// (`SegEngine::region_probability`), measured on rendered frames after
/// training (`fusepose train --stage calibrate`). The verifier's certainty
/// term takes its threshold from a low percentile, so that each model is
/// judged against how sure it is of real objects.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Certainty {
    /// `percentiles[i]`: the (i + 1) % percentile of the peaks, ascending.
    pub percentiles: Vec<f32>,
    /// Object regions measured.
    pub regions: usize,
    /// Frames they came from.
    pub frames: usize,
    /// What the frames were (seeds, sampler, camera).
    pub data: String,
}

impl Certainty {
    /// Percentiles 1..=50 of `peaks` (sorted in place; non-empty, finite).
    pub fn from_peaks(peaks: &mut [f32], frames: usize, data: &str) -> Self {
        peaks.sort_by(f32::total_cmp);
        let n = peaks.len();
        let percentiles = (1..=50).map(|p| peaks[((p * n) / 100).min(n - 1)]).collect();
        Self { percentiles, regions: n, frames, data: data.to_owned() }
    }

    /// The `q` quantile (0.01..=0.5, rounded down to a whole percent) of
    /// the peaks; None outside that range.
    pub fn quantile(&self, q: f32) -> Option<f32> {
        let p = (q * 100.0 + 1e-3).floor() as usize;
        (1..=self.percentiles.len()).contains(&p).then(|| self.percentiles[p - 1])
    }

    fn check(&self) -> Result<(), String> {
        if self.percentiles.len() != 50 {
            return Err(format!("{} percentiles, expected 50", self.percentiles.len()));
        }
        if self.percentiles.iter().any(|p| !(0.0..=1.0).contains(p)) || !self.percentiles.is_sorted() {
            return Err("percentiles must be probabilities in ascending order".into());
        }
        Ok(())
    }
}

/// `bytes` (a safetensors file) with metadata `key` set to `value`, tensors unchanged.
pub fn with_metadata(bytes: &[u8], key: &str, value: String) -> Result<Vec<u8>, NetLoadError> {
    let (_, header) = SafeTensors::read_metadata(bytes).map_err(|e| NetLoadError::Format(e.to_string()))?;
    let mut metadata = header.metadata().clone().unwrap_or_default();
    metadata.insert(key.to_owned(), value);
    let st = SafeTensors::deserialize(bytes).map_err(|e| NetLoadError::Format(e.to_string()))?;
    safetensors::serialize(st.tensors(), Some(metadata)).map_err(|e| NetLoadError::Format(e.to_string()))
}

/// Writes `certainty` into the weight file at `path` (either layout), in
/// place through a temporary file; the file is read back and checked first.
pub fn store_certainty(path: &Path, certainty: &Certainty) -> Result<(), NetLoadError> {
    let io = |source| NetLoadError::Io { path: path.to_path_buf(), source };
    let bytes = std::fs::read(path).map_err(io)?;
    SegFile::from_bytes(&bytes)?;
    let json = serde_json::to_string(certainty).map_err(|e| NetLoadError::Format(e.to_string()))?;
    let out = with_metadata(&bytes, KEY_CERTAINTY, json)?;
    let partial = path.with_extension("safetensors.part");
    std::fs::write(&partial, out).map_err(io)?;
    std::fs::rename(&partial, path).map_err(io)
}

fn bad(key: &'static str, message: impl ToString) -> NetLoadError {
    NetLoadError::BadMetadata { key, message: message.to_string() }
}

impl SegFile {
    /// Reads and checks a file.
    pub fn read(path: &Path) -> Result<Self, NetLoadError> {
        let bytes = std::fs::read(path).map_err(|source| NetLoadError::Io { path: path.to_path_buf(), source })?;
        Self::from_bytes(&bytes)
    }

    /// Parses and checks a file's bytes (format, config, objects, every tensor).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, NetLoadError> {
        let (_, header) = SafeTensors::read_metadata(bytes).map_err(|e| NetLoadError::Format(e.to_string()))?;
        let metadata = header.metadata().clone().unwrap_or_default();
        let st = SafeTensors::deserialize(bytes).map_err(|e| NetLoadError::Format(e.to_string()))?;
        let get = |key: &'static str| metadata.get(key).ok_or(NetLoadError::MissingMetadata(key));
        let format = get(meta::KEY_FORMAT)?;
        // (objects key, train key, tensor prefix) of the two layouts.
        let (key_objects, key_train, prefix) = if format == FORMAT {
            (meta::KEY_OBJECTS, meta::KEY_TRAIN, "")
        } else if format == meta::FORMAT {
            if !metadata.contains_key(KEY_CONFIG) {
                return Err(NetLoadError::NoSegmenter);
            }
            (KEY_EMBEDDED_OBJECTS, KEY_EMBEDDED_TRAIN, EMBEDDED_PREFIX)
        } else {
            return Err(NetLoadError::UnsupportedFormat { found: format.clone(), expected: FORMAT });
        };
        let config: SegConfig = serde_json::from_str(get(KEY_CONFIG)?).map_err(|e| bad(KEY_CONFIG, e))?;
        config.validate().map_err(|m| bad(KEY_CONFIG, m))?;
        let objects: Vec<ObjectEntry> = serde_json::from_str(get(key_objects)?).map_err(|e| bad(key_objects, e))?;
        if objects.len() != config.num_classes {
            return Err(bad(key_objects, format!("{} objects for {} classes", objects.len(), config.num_classes)));
        }
        let train = metadata.get(key_train).and_then(|s| serde_json::from_str(s).ok());
        let certainty = match metadata.get(KEY_CERTAINTY) {
            Some(s) => {
                let c: Certainty = serde_json::from_str(s).map_err(|e| bad(KEY_CERTAINTY, e))?;
                c.check().map_err(|m| bad(KEY_CERTAINTY, m))?;
                Some(c)
            }
            None => None,
        };
        let mut tensors = HashMap::new();
        for (name, shape) in config.tensor_shapes() {
            let view = st
                .tensor(&format!("{prefix}{name}"))
                .map_err(|_| NetLoadError::MissingTensor(format!("{prefix}{name}")))?;
            if view.dtype() != Dtype::F32 {
                return Err(NetLoadError::WrongDtype { name, dtype: format!("{:?}", view.dtype()) });
            }
            if view.shape() != shape.as_slice() {
                return Err(NetLoadError::WrongShape { name, expected: shape, got: view.shape().to_vec() });
            }
            let data: Vec<f32> =
                view.data().chunks_exact(4).map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]])).collect();
            if data.iter().any(|v| !v.is_finite()) {
                return Err(NetLoadError::Format(format!("tensor `{name}` holds non-finite values")));
            }
            tensors.insert(name, data);
        }
        Ok(Self { config, objects, train, certainty, metadata, tensors })
    }

    /// Checks that the file was trained for exactly this object set (names,
    /// symmetries, diameters and mesh/sample hashes, in class order).
    pub fn check_objects(&self, set: &ObjectSet) -> Result<(), NetLoadError> {
        if set.len() != self.objects.len() {
            return Err(NetLoadError::ObjectCount { file: self.objects.len(), set: set.len() });
        }
        for (i, (f, m)) in self.objects.iter().zip(&set.objects).enumerate() {
            let s = ObjectEntry::of(m);
            let what = if f.name != s.name {
                "name"
            } else if f.symmetry != s.symmetry {
                "symmetry"
            } else if (f.diameter - s.diameter).abs() > 1e-6 * f.diameter.abs().max(1e-3) {
                "diameter"
            } else if f.hash != s.hash {
                "mesh or sample points (hash)"
            } else {
                continue;
            };
            return Err(NetLoadError::ObjectMismatch {
                class: i + 1,
                file_name: f.name.clone(),
                set_name: s.name,
                what,
            });
        }
        Ok(())
    }

    /// A tensor's data (row-major); present for every name of [`SegConfig::tensor_shapes`].
    pub fn tensor(&self, name: &str) -> Result<&[f32], NetLoadError> {
        self.tensors.get(name).map(Vec::as_slice).ok_or_else(|| NetLoadError::MissingTensor(name.to_string()))
    }
}

/// Returns the bytes of the pose-network file `pose` with `seg` embedded
/// (replacing an embedded segmenter it already has). Both must be for the same
/// objects in the same order; otherwise [`NetLoadError::ObjectMismatch`] /
/// [`NetLoadError::ObjectCount`] says where they differ.
pub fn embed(pose: &[u8], seg: &SegFile) -> Result<Vec<u8>, NetLoadError> {
    let net = crate::net::WeightFile::from_bytes(pose)?;
    if net.objects.len() != seg.objects.len() {
        return Err(NetLoadError::ObjectCount { file: seg.objects.len(), set: net.objects.len() });
    }
    for (i, (s, n)) in seg.objects.iter().zip(&net.objects).enumerate() {
        if !s.same_object(n) {
            let what = if s.name != n.name {
                "name"
            } else if s.hash != n.hash {
                "mesh or sample points (hash)"
            } else {
                "symmetry or diameter"
            };
            return Err(NetLoadError::ObjectMismatch {
                class: i + 1,
                file_name: s.name.clone(),
                set_name: n.name.clone(),
                what,
            });
        }
    }
    let st = SafeTensors::deserialize(pose).map_err(|e| NetLoadError::Format(e.to_string()))?;
    let mut tensors: Vec<(String, safetensors::tensor::TensorView<'_>)> =
        st.tensors().into_iter().filter(|(name, _)| !name.starts_with(EMBEDDED_PREFIX)).collect();
    let seg_bytes: Vec<(String, Vec<usize>, Vec<u8>)> = seg
        .config
        .tensor_shapes()
        .into_iter()
        .map(|(name, shape)| {
            let data = seg.tensor(&name)?.iter().flat_map(|v| v.to_le_bytes()).collect();
            Ok((format!("{EMBEDDED_PREFIX}{name}"), shape, data))
        })
        .collect::<Result<_, NetLoadError>>()?;
    for (name, shape, data) in &seg_bytes {
        let view = safetensors::tensor::TensorView::new(Dtype::F32, shape.clone(), data)
            .map_err(|e| NetLoadError::Format(e.to_string()))?;
        tensors.push((name.clone(), view));
    }
    let mut metadata: HashMap<String, String> =
        net.metadata.into_iter().filter(|(k, _)| !k.starts_with("fusepose.seg.")).collect();
    let json = |r: serde_json::Result<String>| r.map_err(|e| NetLoadError::Format(e.to_string()));
    metadata.insert(KEY_CONFIG.into(), json(serde_json::to_string(&seg.config))?);
    metadata.insert(KEY_EMBEDDED_OBJECTS.into(), json(serde_json::to_string(&seg.objects))?);
    if let Some(t) = &seg.train {
        metadata.insert(KEY_EMBEDDED_TRAIN.into(), json(serde_json::to_string(t))?);
    }
    if let Some(h) = seg.metadata.get(KEY_HYPER) {
        metadata.insert(KEY_HYPER.into(), h.clone());
    }
    if let Some(c) = seg.metadata.get(KEY_CERTAINTY) {
        metadata.insert(KEY_CERTAINTY.into(), c.clone());
    }
    safetensors::serialize(tensors, Some(metadata)).map_err(|e| NetLoadError::Format(e.to_string()))
}
