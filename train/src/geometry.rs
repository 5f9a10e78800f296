//! Rotation algebra on burn tensors (differentiable) and on plain arrays.
//!
//! Quaternions are `[x, y, z, w]` (Hamilton, scalar last); they are normalised
//! with `q / sqrt(|q|² + 1e-12)` before use, exactly as the inference engine does.

use burn::prelude::Tensor;
use nalgebra::{Isometry3, Matrix3, Quaternion, Translation3, UnitQuaternion, Vector3};

/// Guard against a zero quaternion.
pub const QUAT_EPS: f32 = 1e-12;

/// `[M,4]` quaternions → `[M,3,3]` rotation matrices (row-major, acting on column vectors).
pub fn quat_to_rot(q: Tensor<2>) -> Tensor<3> {
    let [m, _] = q.dims();
    let norm = (q.clone().powi_scalar(2).sum_dim(1).add_scalar(QUAT_EPS)).sqrt();
    let q = q / norm;
    let x = q.clone().narrow(1, 0, 1);
    let y = q.clone().narrow(1, 1, 1);
    let z = q.clone().narrow(1, 2, 1);
    let w = q.narrow(1, 3, 1);
    let xx = x.clone() * x.clone();
    let yy = y.clone() * y.clone();
    let zz = z.clone() * z.clone();
    let xy = x.clone() * y.clone();
    let xz = x.clone() * z.clone();
    let yz = y.clone() * z.clone();
    let wx = w.clone() * x;
    let wy = w.clone() * y;
    let wz = w * z;
    let one = |t: Tensor<2>| t.mul_scalar(-2.0).add_scalar(1.0);
    let two = |t: Tensor<2>| t.mul_scalar(2.0);
    let entries = vec![
        one(yy.clone() + zz.clone()),
        two(xy.clone() - wz.clone()),
        two(xz.clone() + wy.clone()),
        two(xy + wz),
        one(xx.clone() + zz),
        two(yz.clone() - wx.clone()),
        two(xz - wy),
        two(yz + wx),
        one(xx + yy),
    ];
    Tensor::cat(entries, 1).reshape([m, 3, 3])
}

/// A pose from a raw (unnormalised) `[x, y, z, w]` quaternion and a translation.
pub fn pose_from_parts(q: [f32; 4], t: [f32; 3]) -> Isometry3<f64> {
    let q = UnitQuaternion::from_quaternion(Quaternion::new(q[3] as f64, q[0] as f64, q[1] as f64, q[2] as f64));
    Isometry3::from_parts(Translation3::new(t[0] as f64, t[1] as f64, t[2] as f64), q)
}

/// A pose from a row-major rotation matrix and a translation.
pub fn pose_from_matrix(r: &[f32], t: &[f32]) -> Isometry3<f64> {
    let m = Matrix3::from_row_slice(&r[..9].iter().map(|&v| v as f64).collect::<Vec<_>>());
    let rot = UnitQuaternion::from_matrix(&m);
    Isometry3::from_parts(Translation3::from(Vector3::new(t[0] as f64, t[1] as f64, t[2] as f64)), rot)
}

/// Row-major rotation matrix of a pose, as f32.
pub fn rot_rows(p: &Isometry3<f64>) -> [f32; 9] {
    let m = p.rotation.to_rotation_matrix();
    let m = m.matrix();
    std::array::from_fn(|i| m[(i / 3, i % 3)] as f32)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::prelude::{Device, TensorData};

    #[test]
    fn tensor_rotation_matches_nalgebra() {
        let q = UnitQuaternion::from_euler_angles(0.3, -1.1, 2.0);
        let c = q.coords; // [x, y, z, w]
        let raw = [c.x as f32 * 2.0, c.y as f32 * 2.0, c.z as f32 * 2.0, c.w as f32 * 2.0];
        let t = Tensor::<2>::from_data(TensorData::new(raw.to_vec(), [1, 4]), &Device::flex());
        let r = quat_to_rot(t).into_data().try_to_vec::<f32>().unwrap();
        let expect = rot_rows(&Isometry3::from_parts(Translation3::identity(), q));
        for i in 0..9 {
            assert!((r[i] - expect[i]).abs() < 1e-5, "{i}: {} vs {}", r[i], expect[i]);
        }
        let p = pose_from_parts(raw, [0.0; 3]);
        assert!(p.rotation.angle_to(&q) < 1e-6);
    }
}
