//! `fusepose_dataset.json`: our own file at a BOP dataset root naming the
//! object set the dataset was rendered from and the class-id mapping
//! (BOP `obj_id` = our class id, `i + 1` for `ObjectSet::objects[i]`).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

/// The manifest's file name at the dataset root.
pub const MANIFEST_FILE: &str = "fusepose_dataset.json";

/// Where the object set came from: the built-in set, or a directory of meshes.
/// Serialised as the string `"builtin"` or the directory path.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(from = "String", into = "String")]
pub enum ObjectSource {
    Builtin,
    Directory(PathBuf),
}

impl From<String> for ObjectSource {
    fn from(s: String) -> Self {
        if s == "builtin" { ObjectSource::Builtin } else { ObjectSource::Directory(PathBuf::from(s)) }
    }
}

impl From<ObjectSource> for String {
    fn from(s: ObjectSource) -> Self {
        s.to_string()
    }
}

impl std::fmt::Display for ObjectSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ObjectSource::Builtin => f.write_str("builtin"),
            ObjectSource::Directory(p) => write!(f, "{}", p.display()),
        }
    }
}

impl std::str::FromStr for ObjectSource {
    type Err = std::convert::Infallible;
    /// `"builtin"` or a directory path (as `--objects builtin|DIR` takes it).
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Ok(ObjectSource::from(s.to_string()))
    }
}

/// One class of the dataset.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ClassEntry {
    /// BOP obj_id, equal to our class id (1-based).
    pub obj_id: u16,
    pub name: String,
}

/// The contents of `fusepose_dataset.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DatasetManifest {
    /// Always `"fusepose-bop"`.
    pub format: String,
    pub version: u32,
    /// The object set the frames were rendered from.
    pub objects: ObjectSource,
    /// Class ids and names, in class-id order.
    pub classes: Vec<ClassEntry>,
    /// Each written split with the generator's parameters (free-form JSON,
    /// e.g. seed, scene count, noise).
    #[serde(default)]
    pub splits: BTreeMap<String, serde_json::Value>,
}

impl DatasetManifest {
    /// The manifest for an object set, with no splits yet.
    pub fn new(objects: ObjectSource, set: &crate::ObjectSet) -> Self {
        DatasetManifest {
            format: "fusepose-bop".into(),
            version: 1,
            objects,
            classes: set
                .objects
                .iter()
                .enumerate()
                .map(|(i, o)| ClassEntry { obj_id: i as u16 + 1, name: o.name.clone() })
                .collect(),
            splits: BTreeMap::new(),
        }
    }

    /// The class name of a BOP obj_id.
    pub fn name_of(&self, obj_id: u16) -> Option<&str> {
        self.classes.iter().find(|c| c.obj_id == obj_id).map(|c| c.name.as_str())
    }

    /// Reads `root/fusepose_dataset.json`; `Ok(None)` when absent (a BOP dataset not written by fusepose).
    pub fn read(root: &Path) -> Result<Option<Self>, super::BopError> {
        let path = root.join(MANIFEST_FILE);
        if !path.is_file() {
            return Ok(None);
        }
        super::json::read_json(&path).map(Some)
    }
}
