//! Reading a segmenter weight file: safetensors parsing, metadata (format tag,
//! [`SegConfig`], object list, training record), every tensor's dtype and shape,
//! and matching against an object set. Errors are the network loader's typed
//! [`NetLoadError`]; nothing panics on a bad file.

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

/// A parsed, checked segmenter file.
#[derive(Clone, Debug)]
pub struct SegFile {
    pub config: SegConfig,
    pub objects: Vec<ObjectEntry>,
    pub train: Option<TrainRecord>,
    /// All metadata as stored.
    pub metadata: HashMap<String, String>,
    tensors: HashMap<String, Vec<f32>>,
}

fn bad(key: &'static str, message: impl ToString) -> NetLoadError {
    NetLoadError::BadMetadata { key, message: message.to_string() }
}

impl SegFile {
    /// Reads and checks a file.
    pub fn read(path: &Path) -> Result<Self, NetLoadError> {
        let bytes =
            std::fs::read(path).map_err(|source| NetLoadError::Io { path: path.to_path_buf(), source })?;
        Self::from_bytes(&bytes)
    }

    /// Parses and checks a file's bytes (format, config, objects, every tensor).
    pub fn from_bytes(bytes: &[u8]) -> Result<Self, NetLoadError> {
        let (_, header) = SafeTensors::read_metadata(bytes).map_err(|e| NetLoadError::Format(e.to_string()))?;
        let metadata = header.metadata().clone().unwrap_or_default();
        let st = SafeTensors::deserialize(bytes).map_err(|e| NetLoadError::Format(e.to_string()))?;
        let get = |key: &'static str| metadata.get(key).ok_or(NetLoadError::MissingMetadata(key));
        let format = get(meta::KEY_FORMAT)?;
        if format != FORMAT {
            return Err(NetLoadError::UnsupportedFormat { found: format.clone(), expected: FORMAT });
        }
        let config: SegConfig = serde_json::from_str(get(KEY_CONFIG)?).map_err(|e| bad(KEY_CONFIG, e))?;
        config.validate().map_err(|m| bad(KEY_CONFIG, m))?;
        let objects: Vec<ObjectEntry> =
            serde_json::from_str(get(meta::KEY_OBJECTS)?).map_err(|e| bad(meta::KEY_OBJECTS, e))?;
        if objects.len() != config.num_classes {
            return Err(bad(
                meta::KEY_OBJECTS,
                format!("{} objects for {} classes", objects.len(), config.num_classes),
            ));
        }
        let train = metadata.get(meta::KEY_TRAIN).and_then(|s| serde_json::from_str(s).ok());
        let mut tensors = HashMap::new();
        for (name, shape) in config.tensor_shapes() {
            let view = st.tensor(&name).map_err(|_| NetLoadError::MissingTensor(name.clone()))?;
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
        Ok(Self { config, objects, train, metadata, tensors })
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
            return Err(NetLoadError::ObjectMismatch { class: i + 1, file_name: f.name.clone(), set_name: s.name, what });
        }
        Ok(())
    }

    /// A tensor's data (row-major); present for every name of [`SegConfig::tensor_shapes`].
    pub fn tensor(&self, name: &str) -> Result<&[f32], NetLoadError> {
        self.tensors.get(name).map(Vec::as_slice).ok_or_else(|| NetLoadError::MissingTensor(name.to_string()))
    }
}
