//! Reading a weight file: safetensors parsing, metadata and shape checks,
//! object-set matching. Every failure is a typed [`NetLoadError`]; nothing panics.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use fusepose_scene::ObjectSet;
use safetensors::{Dtype, SafeTensors};

use super::config::NetConfig;
use super::meta::{self, ObjectEntry, TrainRecord};

/// Why a weight file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum NetLoadError {
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    #[error("not a readable safetensors file (truncated or corrupt): {0}")]
    Format(String),
    #[error("metadata key `{0}` is missing (not a fusepose network file?)")]
    MissingMetadata(&'static str),
    #[error("metadata `{key}` is invalid: {message}")]
    BadMetadata { key: &'static str, message: String },
    #[error("file format `{found}` is not supported (expected `{expected}`)")]
    UnsupportedFormat { found: String, expected: &'static str },
    #[error("tensor `{0}` is missing")]
    MissingTensor(String),
    #[error("the network file has no segmenter embedded (train one: `fusepose train --stage seg`)")]
    NoSegmenter,
    #[error("tensor `{name}` has shape {got:?}, expected {expected:?}")]
    WrongShape { name: String, expected: Vec<usize>, got: Vec<usize> },
    #[error("tensor `{name}` has dtype {dtype}, expected F32")]
    WrongDtype { name: String, dtype: String },
    #[error("the network was trained for {file} objects, the object set has {set}")]
    ObjectCount { file: usize, set: usize },
    #[error("class {class}: the network's object `{file_name}` differs from the set's `{set_name}` in {what}")]
    ObjectMismatch { class: usize, file_name: String, set_name: String, what: &'static str },
}

/// A parsed, checked weight file.
#[derive(Clone, Debug)]
pub struct WeightFile {
    pub config: NetConfig,
    pub objects: Vec<ObjectEntry>,
    pub train: Option<TrainRecord>,
    /// All metadata as stored.
    pub metadata: HashMap<String, String>,
    tensors: HashMap<String, (Vec<usize>, Vec<f32>)>,
}

impl WeightFile {
    /// Reads and checks a file (format tag, config, every tensor's presence, dtype and shape).
    pub fn read(path: &Path) -> Result<Self, NetLoadError> {
        let bytes = std::fs::read(path).map_err(|source| NetLoadError::Io { path: path.to_path_buf(), source })?;
        Self::from_bytes(&bytes)
    }

    pub fn from_bytes(bytes: &[u8]) -> Result<Self, NetLoadError> {
        let (_, header) = SafeTensors::read_metadata(bytes).map_err(|e| NetLoadError::Format(e.to_string()))?;
        let metadata = header.metadata().clone().unwrap_or_default();
        let st = SafeTensors::deserialize(bytes).map_err(|e| NetLoadError::Format(e.to_string()))?;
        let get = |key: &'static str| metadata.get(key).ok_or(NetLoadError::MissingMetadata(key));
        let format = get(meta::KEY_FORMAT)?;
        if format != meta::FORMAT {
            return Err(NetLoadError::UnsupportedFormat { found: format.clone(), expected: meta::FORMAT });
        }
        let config: NetConfig = serde_json::from_str(get(meta::KEY_CONFIG)?)
            .map_err(|e| NetLoadError::BadMetadata { key: meta::KEY_CONFIG, message: e.to_string() })?;
        config.validate().map_err(|message| NetLoadError::BadMetadata { key: meta::KEY_CONFIG, message })?;
        let objects: Vec<ObjectEntry> = serde_json::from_str(get(meta::KEY_OBJECTS)?)
            .map_err(|e| NetLoadError::BadMetadata { key: meta::KEY_OBJECTS, message: e.to_string() })?;
        if objects.len() != config.num_classes {
            return Err(NetLoadError::BadMetadata {
                key: meta::KEY_OBJECTS,
                message: format!("{} objects for {} classes", objects.len(), config.num_classes),
            });
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
            tensors.insert(name, (shape, data));
        }
        Ok(Self { config, objects, train, metadata, tensors })
    }

    /// Gives the objects of `set` that declare no symmetry the one this file
    /// was trained with ([`crate::net::meta::adopt_symmetries`]); returns their names.
    /// Call before [`WeightFile::check_objects`] on a set loaded from a bare mesh folder.
    pub fn adopt_symmetries(&self, set: &mut ObjectSet) -> Vec<String> {
        crate::net::meta::adopt_symmetries(&self.objects, set)
    }

    /// Checks that the file was trained for exactly this object set (names, symmetries,
    /// diameters and mesh/sample hashes, in class order).
    pub fn check_objects(&self, set: &ObjectSet) -> Result<(), NetLoadError> {
        if set.len() != self.objects.len() {
            return Err(NetLoadError::ObjectCount { file: self.objects.len(), set: set.len() });
        }
        for (i, (f, m)) in self.objects.iter().zip(&set.objects).enumerate() {
            let s = ObjectEntry::of(m);
            let what = if f.name != s.name {
                Some("name")
            } else if f.symmetry != s.symmetry {
                Some("symmetry")
            } else if (f.diameter - s.diameter).abs() > 1e-6 * f.diameter.abs().max(1e-3) {
                Some("diameter")
            } else if f.hash != s.hash {
                Some("mesh or sample points (hash)")
            } else {
                None
            };
            if let Some(what) = what {
                return Err(NetLoadError::ObjectMismatch {
                    class: i + 1,
                    file_name: f.name.clone(),
                    set_name: s.name,
                    what,
                });
            }
        }
        Ok(())
    }

    /// A tensor's data (row-major); present by construction for every name of
    /// [`NetConfig::tensor_shapes`].
    pub fn tensor(&self, name: &str) -> Result<&[f32], NetLoadError> {
        self.tensors.get(name).map(|(_, d)| d.as_slice()).ok_or_else(|| NetLoadError::MissingTensor(name.to_string()))
    }
}
