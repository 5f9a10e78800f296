//! `models/models_info.json` in BOP form: per obj_id the diameter, the
//! bounding box (`min_*`, `size_*`) and the symmetries, all in millimetres;
//! discrete symmetries as row-major 4x4 matrices (translation in mm),
//! continuous ones as an axis and an offset point on it (mm).
//!
//! [`BopModelInfo`] holds the same in metres with a [`Symmetry`].

use std::collections::BTreeMap;
use std::path::Path;

use nalgebra::{Isometry3, Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};
use serde::{Deserialize, Serialize};

use super::BopError;
use super::error::invalid;
use super::json::{read_json, write_json};
use crate::{ObjectSet, Symmetry};

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct ContinuousEntry {
    axis: [f64; 3],
    offset: [f64; 3],
}

/// A symmetry in BOP's `models_info.json` form (millimetres): discrete
/// symmetries as row-major 4x4 matrices, continuous ones as an axis and a
/// point on it. Weight files store object symmetries this way too.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct BopSymmetry {
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    symmetries_discrete: Vec<[f64; 16]>,
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    symmetries_continuous: Vec<ContinuousEntry>,
}

impl BopSymmetry {
    /// `symmetry` in BOP form (empty for [`Symmetry::None`]).
    pub fn of(symmetry: &Symmetry) -> Self {
        let mm = 1000.0;
        match symmetry {
            Symmetry::None => Self::default(),
            Symmetry::Discrete(v) => Self {
                symmetries_discrete: v
                    .iter()
                    .map(|t| {
                        let mut m = t.to_homogeneous();
                        for r in 0..3 {
                            m[(r, 3)] *= mm;
                        }
                        std::array::from_fn(|k| m[(k / 4, k % 4)])
                    })
                    .collect(),
                symmetries_continuous: Vec::new(),
            },
            Symmetry::Continuous { axis, origin } => {
                let a = axis.normalize();
                Self {
                    symmetries_discrete: Vec::new(),
                    symmetries_continuous: vec![ContinuousEntry {
                        axis: [a.x, a.y, a.z],
                        offset: (origin.coords * mm).into(),
                    }],
                }
            }
        }
    }

    /// Back to a [`Symmetry`] in metres: `Continuous` if any continuous
    /// symmetry is listed (the first; BOP objects list at most one), else
    /// `Discrete` if any discrete one is, else `None`. The error says what is unusable.
    pub fn to_symmetry(&self) -> Result<Symmetry, String> {
        let m = 0.001;
        if let Some(c) = self.symmetries_continuous.first() {
            let axis = Vector3::from(c.axis);
            if !(axis.norm() > 0.0 && axis.iter().chain(&c.offset).all(|v| v.is_finite())) {
                return Err(format!("continuous symmetry axis {:?} / offset {:?} is not usable", c.axis, c.offset));
            }
            return Ok(Symmetry::Continuous {
                axis: axis.normalize(),
                origin: Point3::from(Vector3::from(c.offset) * m),
            });
        }
        let mut v = Vec::with_capacity(self.symmetries_discrete.len());
        for s in &self.symmetries_discrete {
            if !s.iter().all(|x| x.is_finite()) {
                return Err("discrete symmetry is not finite".into());
            }
            let r = Matrix3::new(s[0], s[1], s[2], s[4], s[5], s[6], s[8], s[9], s[10]);
            // Taken as given when it is a rotation: the iterative `Rotation3::from_matrix`
            // starts at the identity and does not reach a half-turn.
            if (r.transpose() * r - Matrix3::identity()).abs().max() > 1e-6 || (r.determinant() - 1.0).abs() > 1e-6 {
                return Err(format!("discrete symmetry {s:?} does not hold a rotation (orthonormal, determinant 1)"));
            }
            let r = Rotation3::from_matrix_unchecked(r);
            v.push(Isometry3::from_parts(
                Translation3::new(s[3] * m, s[7] * m, s[11] * m),
                UnitQuaternion::from_rotation_matrix(&r),
            ));
        }
        Ok(if v.is_empty() { Symmetry::None } else { Symmetry::Discrete(v) })
    }
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct ModelInfoEntry {
    diameter: f64,
    min_x: f64,
    min_y: f64,
    min_z: f64,
    size_x: f64,
    size_y: f64,
    size_z: f64,
    #[serde(flatten)]
    symmetry: BopSymmetry,
}

/// One model's BOP info, converted to metres.
#[derive(Clone, Debug, PartialEq)]
pub struct BopModelInfo {
    /// Metres.
    pub diameter: f64,
    /// Bounding-box minimum corner, object frame, metres.
    pub bbox_min: Point3<f64>,
    /// Bounding-box extent, metres.
    pub bbox_size: Vector3<f64>,
    /// `Continuous` if any continuous symmetry is listed (the first; BOP
    /// objects list at most one), else `Discrete` if any discrete one is, else `None`.
    pub symmetry: Symmetry,
}

fn entry_for(model: &crate::ObjectModel) -> ModelInfoEntry {
    let mm = 1000.0;
    let size = model.bbox_max - model.bbox_min;
    ModelInfoEntry {
        diameter: model.diameter * mm,
        min_x: model.bbox_min.x * mm,
        min_y: model.bbox_min.y * mm,
        min_z: model.bbox_min.z * mm,
        size_x: size.x * mm,
        size_y: size.y * mm,
        size_z: size.z * mm,
        symmetry: BopSymmetry::of(&model.symmetry),
    }
}

/// Writes `path` (a `models_info.json`) for `set`, obj_id = class id.
pub(crate) fn write_models_info(path: &Path, set: &ObjectSet) -> Result<(), BopError> {
    let map: BTreeMap<u16, ModelInfoEntry> =
        set.objects.iter().enumerate().map(|(i, o)| (i as u16 + 1, entry_for(o))).collect();
    write_json(path, &map)
}

fn to_info(path: &Path, obj_id: u16, e: &ModelInfoEntry) -> Result<BopModelInfo, BopError> {
    let m = 0.001;
    let symmetry = e.symmetry.to_symmetry().map_err(|msg| invalid(path, format!("obj_id {obj_id}: {msg}")))?;
    Ok(BopModelInfo {
        diameter: e.diameter * m,
        bbox_min: Point3::new(e.min_x, e.min_y, e.min_z) * m,
        bbox_size: Vector3::new(e.size_x, e.size_y, e.size_z) * m,
        symmetry,
    })
}

/// Reads a BOP `models_info.json`, converting to metres, keyed by obj_id.
pub fn read_models_info(path: &Path) -> Result<BTreeMap<u16, BopModelInfo>, BopError> {
    let raw: BTreeMap<u16, ModelInfoEntry> = read_json(path)?;
    raw.iter().map(|(&id, e)| Ok((id, to_info(path, id, e)?))).collect()
}
