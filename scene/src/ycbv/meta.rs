//! `NNNNNN-meta.mat` (MATLAB v5) of a YCB-Video frame, read with `matfile`:
//! `poses` (3x4xn, object → camera, metres), `cls_indexes` (n class ids),
//! `intrinsic_matrix` (3x3) and `factor_depth` (depth units per metre).
//! MATLAB stores arrays column-major; any numeric storage type is accepted.

use std::path::Path;

use nalgebra::{Matrix3, Rotation3, Translation3, UnitQuaternion};

use super::YcbError;
use crate::{Intrinsics, Pose};

/// The parsed meta file of one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct YcbMeta {
    /// 1-based class ids, one per pose.
    pub class_ids: Vec<u16>,
    /// Object → camera, metres, one per class id.
    pub poses: Vec<Pose>,
    /// Row-major 3x3 camera matrix.
    pub intrinsic_matrix: [f64; 9],
    /// Depth units per metre (10000 for YCB-Video).
    pub factor_depth: f64,
}

impl YcbMeta {
    /// Intrinsics from `intrinsic_matrix` for an image of `width x height`.
    pub fn intrinsics(&self, width: u32, height: u32) -> Intrinsics {
        let k = &self.intrinsic_matrix;
        Intrinsics { fx: k[0], fy: k[4], cx: k[2], cy: k[5], width, height }
    }
}

fn as_f64(data: &matfile::NumericData) -> Vec<f64> {
    use matfile::NumericData as N;
    match data {
        N::Int8 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::UInt8 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::Int16 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::UInt16 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::Int32 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::UInt32 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::Int64 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::UInt64 { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::Single { real, .. } => real.iter().map(|&v| v as f64).collect(),
        N::Double { real, .. } => real.clone(),
    }
}

/// Reads and checks a YCB-Video `-meta.mat`.
pub fn read_meta(path: &Path) -> Result<YcbMeta, YcbError> {
    let invalid = |message: String| YcbError::Invalid { path: path.to_owned(), message };
    let bytes = std::fs::read(path).map_err(|source| YcbError::Io { path: path.to_owned(), source })?;
    let mat = matfile::MatFile::parse(bytes.as_slice())
        .map_err(|e| YcbError::Mat { path: path.to_owned(), message: e.to_string() })?;
    let get = |name: &str| -> Result<(Vec<usize>, Vec<f64>), YcbError> {
        let a = mat.find_by_name(name).ok_or_else(|| invalid(format!("no numeric variable '{name}'")))?;
        let values = as_f64(a.data());
        if !values.iter().all(|v| v.is_finite()) {
            return Err(invalid(format!("'{name}' holds non-finite values")));
        }
        Ok((a.size().clone(), values))
    };

    let (_, cls) = get("cls_indexes")?;
    let mut class_ids = Vec::with_capacity(cls.len());
    for &c in &cls {
        if !(c >= 1.0 && c <= u16::MAX as f64 && c.fract() == 0.0) {
            return Err(invalid(format!("cls_indexes holds {c}, not a class id >= 1")));
        }
        class_ids.push(c as u16);
    }

    let (size, p) = get("poses")?;
    let n = class_ids.len();
    let shape_ok = size.len() >= 2 && size[0] == 3 && size[1] == 4 && p.len() == 12 * n;
    if !shape_ok {
        return Err(invalid(format!("poses is {size:?} ({} values), expected 3x4x{n} for {n} classes", p.len())));
    }
    let mut poses = Vec::with_capacity(n);
    for k in 0..n {
        // Column-major: element (r, c, k) at r + 3 c + 12 k.
        let at = |r: usize, c: usize| p[r + 3 * c + 12 * k];
        let m = Matrix3::from_fn(at);
        if (m.determinant() - 1.0).abs() > 0.05 {
            return Err(invalid(format!("poses(:, 1:3, {}) is not a rotation (det {})", k + 1, m.determinant())));
        }
        let r = Rotation3::from_matrix_eps(&m, 1e-12, 100, Rotation3::identity());
        poses.push(Pose::from_parts(
            Translation3::new(at(0, 3), at(1, 3), at(2, 3)),
            UnitQuaternion::from_rotation_matrix(&r),
        ));
    }

    let (size, k) = get("intrinsic_matrix")?;
    if k.len() != 9 || size.iter().take(2).ne([3usize, 3].iter()) {
        return Err(invalid(format!("intrinsic_matrix is {size:?}, expected 3x3")));
    }
    // Column-major (r, c) at r + 3 c -> row-major.
    let intrinsic_matrix: [f64; 9] = std::array::from_fn(|i| k[(i / 3) + 3 * (i % 3)]);
    if !(intrinsic_matrix[0] > 0.0 && intrinsic_matrix[4] > 0.0) {
        return Err(invalid("intrinsic_matrix has non-positive focal lengths".into()));
    }

    let (_, f) = get("factor_depth")?;
    let factor_depth = match f.as_slice() {
        [v] if *v > 0.0 => *v,
        _ => return Err(invalid(format!("factor_depth is {f:?}, expected one positive number"))),
    };
    Ok(YcbMeta { class_ids, poses, intrinsic_matrix, factor_depth })
}
