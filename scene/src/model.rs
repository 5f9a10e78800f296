//! Object models: triangle meshes with materials, declared symmetries, and what
//! the estimator precomputes per object (surface samples, diameter, bounding box).
//!
//! Loading (OBJ/PLY) lives in `mesh_io`; the built-in set in `builtin`.

use nalgebra::{Isometry3, Point3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

/// A rigid pose mapping object coordinates into camera coordinates (metres).
pub type Pose = Isometry3<f64>;

/// An RGB8 texture, row-major, top row first (v = 1 at the top row, OBJ convention).
#[derive(Clone, Debug, PartialEq)]
pub struct Texture {
    pub width: u32,
    pub height: u32,
    pub rgb: Vec<u8>,
}

/// A material: a diffuse colour (linear 0..1) and an optional diffuse texture
/// that replaces the colour where present.
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    pub name: String,
    pub diffuse: [f32; 3],
    pub texture: Option<Texture>,
}

/// An indexed triangle mesh in object coordinates (metres).
///
/// `normals`, `uvs` and `colors` are per vertex and either empty or as long as
/// `positions`. `triangle_materials` is empty (material 0 everywhere) or one
/// index into `materials` per triangle.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Mesh {
    pub positions: Vec<[f32; 3]>,
    pub normals: Vec<[f32; 3]>,
    pub uvs: Vec<[f32; 2]>,
    pub colors: Vec<[u8; 3]>,
    pub triangles: Vec<[u32; 3]>,
    pub triangle_materials: Vec<u32>,
    pub materials: Vec<Material>,
}

/// The symmetries an object declares; metrics and losses use them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Symmetry {
    /// No symmetry: ADD applies.
    None,
    /// A finite set of object-frame rigid transforms (identity excluded) that
    /// leave the object's appearance unchanged.
    Discrete(Vec<Isometry3<f64>>),
    /// Invariance under any rotation about `axis` through `origin` (object frame).
    Continuous { axis: Vector3<f64>, origin: Point3<f64> },
}

impl Symmetry {
    pub fn is_symmetric(&self) -> bool {
        !matches!(self, Symmetry::None)
    }

    /// A finite set of symmetry transforms including the identity: the
    /// discrete set, or `steps` rotations about a continuous axis.
    pub fn sampled(&self, steps: usize) -> Vec<Isometry3<f64>> {
        let mut out = vec![Isometry3::identity()];
        match self {
            Symmetry::None => {}
            Symmetry::Discrete(s) => out.extend(s.iter().copied()),
            Symmetry::Continuous { axis, origin } => {
                let axis = nalgebra::Unit::new_normalize(*axis);
                for i in 1..steps.max(1) {
                    let angle = std::f64::consts::TAU * i as f64 / steps as f64;
                    let r = UnitQuaternion::from_axis_angle(&axis, angle);
                    // Rotate about the axis through `origin`: p -> R (p - o) + o.
                    let t = origin.coords - r * origin.coords;
                    out.push(Isometry3::from_parts(t.into(), r));
                }
            }
        }
        out
    }
}

/// One object class: its mesh plus everything precomputed from it.
#[derive(Clone, Debug)]
pub struct ObjectModel {
    /// Short identifier, e.g. `soup_can` or `YcbBanana`.
    pub name: String,
    pub mesh: Mesh,
    pub symmetry: Symmetry,
    /// Points sampled uniformly (area-weighted) on the surface, object frame,
    /// metres; a fixed count per object (used by ADD/ADD-S and the losses).
    pub samples: Vec<Point3<f64>>,
    /// Largest distance between two surface points (metres).
    pub diameter: f64,
    /// Axis-aligned bounding box in the object frame (metres).
    pub bbox_min: Point3<f64>,
    pub bbox_max: Point3<f64>,
    /// A coarse copy of `mesh` its shadow maps use, when the mesh is fine
    /// enough to be worth one ([`crate::shadow_mesh`]).
    pub shadow_mesh: Option<Mesh>,
}

/// An ordered set of objects. Class id `i + 1` names `objects[i]`; class id 0
/// is background in every label map.
#[derive(Clone, Debug, Default)]
pub struct ObjectSet {
    pub objects: Vec<ObjectModel>,
}

impl ObjectSet {
    /// The object of a class id (1-based); `None` for background or unknown ids.
    pub fn by_class(&self, class_id: u16) -> Option<&ObjectModel> {
        (class_id as usize).checked_sub(1).and_then(|i| self.objects.get(i))
    }

    pub fn class_of(&self, name: &str) -> Option<u16> {
        self.objects.iter().position(|o| o.name == name).map(|i| i as u16 + 1)
    }

    pub fn len(&self) -> usize {
        self.objects.len()
    }

    pub fn is_empty(&self) -> bool {
        self.objects.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn continuous_symmetry_samples_keep_axis_points_fixed() {
        let s = Symmetry::Continuous { axis: Vector3::z(), origin: Point3::new(0.01, 0.0, 0.0) };
        let set = s.sampled(8);
        assert_eq!(set.len(), 8);
        let on_axis = Point3::new(0.01, 0.0, 0.3);
        for t in &set {
            assert!((t * on_axis - on_axis).norm() < 1e-12);
        }
    }
}
