//! What a weight file says about itself: the safetensors metadata keys, the
//! object list the network was trained for (with a hash of each object's mesh
//! and sample points), and the training record.
//!
//! All values are strings (safetensors metadata is a string → string map);
//! structured values are JSON.

use fusepose_scene::bop::BopSymmetry;
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
    /// The symmetry itself, in BOP `models_info.json` form (mm), for symmetric
    /// objects (absent in files written before it was stored), so that a mesh
    /// folder without a `models_info.json` gets the symmetry it was trained
    /// with ([`adopt_symmetries`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub symmetries: Option<BopSymmetry>,
}

impl ObjectEntry {
    pub fn of(model: &ObjectModel) -> Self {
        Self {
            name: model.name.clone(),
            symmetry: symmetry_tag(&model.symmetry),
            diameter: model.diameter,
            hash: format!("{:016x}", object_hash(model)),
            symmetries: model.symmetry.is_symmetric().then(|| BopSymmetry::of(&model.symmetry)),
        }
    }
}

impl ObjectEntry {
    /// Whether both describe the same object: name, symmetry tag, diameter
    /// and hash; the stored symmetry too when both files carry it (files
    /// written before it was stored have none).
    pub fn same_object(&self, other: &ObjectEntry) -> bool {
        self.name == other.name
            && self.symmetry == other.symmetry
            && self.diameter == other.diameter
            && self.hash == other.hash
            && (self.symmetries.is_none() || other.symmetries.is_none() || self.symmetries == other.symmetries)
    }
}

/// The object list of an object set, in class order.
pub fn object_entries(set: &ObjectSet) -> Vec<ObjectEntry> {
    set.objects.iter().map(ObjectEntry::of).collect()
}

/// Gives each object of `set` that declares no symmetry the one its entry in
/// `entries` (a weight file's object list, same class order) was trained
/// with — e.g. from `fusepose train --symmetry` on a folder of bare meshes.
/// Objects are matched by position and name; a declared symmetry is never
/// replaced (the weight check then reports any disagreement). Returns the
/// names of the objects that took one.
pub fn adopt_symmetries(entries: &[ObjectEntry], set: &mut ObjectSet) -> Vec<String> {
    let mut adopted = Vec::new();
    for (entry, object) in entries.iter().zip(&mut set.objects) {
        if entry.name != object.name || object.symmetry.is_symmetric() {
            continue;
        }
        if let Some(symmetry) = entry.symmetries.as_ref().and_then(|s| s.to_symmetry().ok())
            && symmetry.is_symmetric()
        {
            object.symmetry = symmetry;
            adopted.push(object.name.clone());
        }
    }
    adopted
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
            shadow_mesh: None,
        }
    }

    #[test]
    fn hash_changes_with_samples() {
        assert_eq!(object_hash(&model(0.01)), object_hash(&model(0.01)));
        assert_ne!(object_hash(&model(0.01)), object_hash(&model(0.02)));
        assert_eq!(ObjectEntry::of(&model(0.0)).symmetry, "none");
    }

    /// A mesh folder without a models_info.json loads every object without
    /// symmetry; the weight file's list gives back what training used.
    #[test]
    fn symmetries_travel_in_the_object_list_and_are_adopted() {
        let trained = fusepose_scene::builtin::builtin_objects();
        let json = serde_json::to_string(&object_entries(&trained)).unwrap();
        let entries: Vec<ObjectEntry> = serde_json::from_str(&json).unwrap();
        assert_eq!(entries, object_entries(&trained));
        let mut bare = trained.clone();
        for o in &mut bare.objects {
            o.symmetry = Symmetry::None;
        }
        let adopted = adopt_symmetries(&entries, &mut bare);
        let symmetric: Vec<String> =
            trained.objects.iter().filter(|o| o.symmetry.is_symmetric()).map(|o| o.name.clone()).collect();
        assert!(!symmetric.is_empty());
        assert_eq!(adopted, symmetric);
        for (a, b) in trained.objects.iter().zip(&bare.objects) {
            assert_eq!(symmetry_tag(&a.symmetry), symmetry_tag(&b.symmetry), "{}", a.name);
            for (x, y) in a.symmetry.sampled(4).iter().zip(b.symmetry.sampled(4).iter()) {
                let d = (x.to_homogeneous() - y.to_homogeneous()).abs().max();
                assert!(d < 1e-9, "{}: {d}", a.name);
            }
        }
        // A declared symmetry is kept, and a list from before symmetries were stored adopts nothing.
        let mut old = entries.clone();
        for e in &mut old {
            e.symmetries = None;
        }
        let old: Vec<ObjectEntry> =
            serde_json::from_str(&serde_json::to_string(&old).unwrap().replace(",\"symmetries\":null", "")).unwrap();
        let mut bare2 = bare.clone();
        for o in &mut bare2.objects {
            o.symmetry = Symmetry::None;
        }
        assert!(adopt_symmetries(&old, &mut bare2).is_empty());
        assert!(adopt_symmetries(&entries, &mut bare).is_empty());
        // A file from before symmetries were stored still describes the same objects.
        assert!(old.iter().zip(&entries).all(|(a, b)| a.same_object(b) && b.same_object(a)));
        let mut other = entries.clone();
        other[6].diameter *= 1.01;
        assert!(!other[6].same_object(&entries[6]));
    }
}
