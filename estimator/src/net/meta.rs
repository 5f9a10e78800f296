//! What a weight file says about itself: the safetensors metadata keys, the
//! object list the network was trained for (with a hash of each object's mesh
//! and sample points), and the training record.
//!
//! All values are strings (safetensors metadata is a string → string map);
//! structured values are JSON.

use fusepose_scene::{ObjectModel, ObjectSet, Symmetry};
use serde::{Deserialize, Serialize};

/// File format tag; bumped when the tensor layout changes.
pub const FORMAT: &str = "fusepose-net-v1";
/// Metadata key of the format tag.
pub const KEY_FORMAT: &str = "fusepose.format";
/// Metadata key of the [`crate::net::NetConfig`] JSON.
pub const KEY_CONFIG: &str = "fusepose.config";
/// Metadata key of the object list JSON (`Vec<ObjectEntry>`).
pub const KEY_OBJECTS: &str = "fusepose.objects";
/// Metadata key of the training record JSON ([`TrainRecord`]).
pub const KEY_TRAIN: &str = "fusepose.train";

/// One object as the network knows it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ObjectEntry {
    pub name: String,
    /// `none`, `discrete:<n transforms>` or `continuous`.
    pub symmetry: String,
    /// Metres.
    pub diameter: f64,
    /// FNV-1a 64 over mesh positions, triangles and sample points (hex).
    pub hash: String,
}

impl ObjectEntry {
    pub fn of(model: &ObjectModel) -> Self {
        Self {
            name: model.name.clone(),
            symmetry: symmetry_tag(&model.symmetry),
            diameter: model.diameter,
            hash: format!("{:016x}", object_hash(model)),
        }
    }
}

/// The object list of an object set, in class order.
pub fn object_entries(set: &ObjectSet) -> Vec<ObjectEntry> {
    set.objects.iter().map(ObjectEntry::of).collect()
}

/// How training went; informative only (never checked at load).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct TrainRecord {
    pub seed: u64,
    pub steps: u64,
    pub samples: u64,
    pub seconds: f64,
    pub batch: usize,
    /// Free-form description of the data (e.g. `builtin, rendered on the fly`).
    pub data: String,
    /// Validation metrics by name, e.g. `pose.adds_auc`, `refined.add_s_auc`, `refined.lt2cm` (percent).
    pub metrics: std::collections::BTreeMap<String, f64>,
}

fn symmetry_tag(s: &Symmetry) -> String {
    match s {
        Symmetry::None => "none".into(),
        Symmetry::Discrete(v) => format!("discrete:{}", v.len()),
        Symmetry::Continuous { .. } => "continuous".into(),
    }
}

/// FNV-1a 64 over the mesh positions, triangle indices and surface samples
/// (as f32 bit patterns), so a changed mesh or sample set changes the hash.
pub fn object_hash(model: &ObjectModel) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    let mut eat = |bytes: &[u8]| {
        for &b in bytes {
            h ^= b as u64;
            h = h.wrapping_mul(0x0100_0000_01b3);
        }
    };
    for p in &model.mesh.positions {
        for c in p {
            eat(&c.to_bits().to_le_bytes());
        }
    }
    for t in &model.mesh.triangles {
        for i in t {
            eat(&i.to_le_bytes());
        }
    }
    for p in &model.samples {
        for c in [p.x, p.y, p.z] {
            eat(&(c as f32).to_bits().to_le_bytes());
        }
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use fusepose_scene::Mesh;
    use nalgebra::Point3;

    fn model(x: f64) -> ObjectModel {
        ObjectModel {
            name: "a".into(),
            mesh: Mesh::default(),
            symmetry: Symmetry::None,
            samples: vec![Point3::new(x, 0.0, 0.0)],
            diameter: 0.1,
            bbox_min: Point3::origin(),
            bbox_max: Point3::origin(),
        }
    }

    #[test]
    fn hash_changes_with_samples() {
        assert_eq!(object_hash(&model(0.01)), object_hash(&model(0.01)));
        assert_ne!(object_hash(&model(0.01)), object_hash(&model(0.02)));
        assert_eq!(ObjectEntry::of(&model(0.0)).symmetry, "none");
    }
}
