//! Shadow maps: per light, the caster items (their coarse `shadow_mesh` where
//! they have one) are rasterised depth-only from
//! the light (a perspective camera at a point light, or 50 m up the direction
//! of a directional light) over the casters' bounding sphere. The per-pixel
//! pass then looks each surface point up in every map (2x2 bilinear
//! percentage-closer filtering, normal offset and a depth bias).

use super::raster::{self, CamVertex};
use super::target::RenderTarget;
use super::{RenderItem, RenderSettings};
use crate::{Intrinsics, Pose};
use nalgebra::{Matrix3, Point3, Rotation3, Translation3, UnitQuaternion, Vector3};

/// Distance of a directional light's shadow camera from the casters (metres).
const DIRECTIONAL_DISTANCE_M: f64 = 50.0;

/// One light's shadow map.
#[derive(Debug)]
pub(super) struct ShadowMap {
    /// Light-camera-from-render-camera rotation (row-major) and translation.
    r: [[f32; 3]; 3],
    t: [f32; 3],
    f: f32,
    c: f32,
    size: usize,
    /// Nearest caster inverse depth per texel (0: none).
    inv_depth: Vec<f32>,
    /// Depth bias (metres) and normal offset (metres per metre of light depth).
    bias_m: f32,
    offset_per_z: f32,
}

impl ShadowMap {
    /// Map coordinates (texels) and biased light-space depth of a row of
    /// camera-frame points `(rx·z, ry·z, z)` with unit normals `n`, offset
    /// along the normal; points behind the light get u = −1 (outside).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn project_row(
        &self,
        rx: &[f32],
        ry: f32,
        z: &[f32],
        n: [&[f32]; 3],
        su: &mut [f32],
        sv: &mut [f32],
        sz: &mut [f32],
    ) {
        let r = &self.r;
        let [t0, t1, t2] = self.t;
        let [nx, ny, nz] = n;
        for i in 0..z.len() {
            let (px, py, pz) = (rx[i] * z[i], ry * z[i], z[i]);
            let mut qx = r[0][0] * px + r[0][1] * py + r[0][2] * pz + t0;
            let mut qy = r[1][0] * px + r[1][1] * py + r[1][2] * pz + t1;
            let mut qz = r[2][0] * px + r[2][1] * py + r[2][2] * pz + t2;
            let off = self.offset_per_z * qz;
            qx += off * (r[0][0] * nx[i] + r[0][1] * ny[i] + r[0][2] * nz[i]);
            qy += off * (r[1][0] * nx[i] + r[1][1] * ny[i] + r[1][2] * nz[i]);
            qz += off * (r[2][0] * nx[i] + r[2][1] * ny[i] + r[2][2] * nz[i]);
            let iz = 1.0 / qz.max(1e-6);
            su[i] = if qz > 0.0 { self.f * qx * iz + self.c } else { -1.0 };
            sv[i] = self.f * qy * iz + self.c;
            sz[i] = qz - self.bias_m;
        }
    }

    /// Fraction (0..1) of the light reaching a point at map coordinates
    /// (u, v) with biased light depth `zb` (from [`Self::project_row`]): 2x2
    /// bilinear percentage-closer filtering; 1 outside the map.
    #[inline]
    pub(super) fn lookup(&self, u: f32, v: f32, zb: f32) -> f32 {
        let last = (self.size - 1) as f32;
        if !(u >= 0.0 && v >= 0.0 && u < last && v < last) {
            return 1.0;
        }
        let (ui, vi) = (u as usize, v as usize);
        let (fu, fv) = (u - ui as f32, v - vi as f32);
        let i = vi * self.size + ui;
        // Lit when the point is not behind the nearest caster: w·(z − bias) <= 1.
        let lit = |w: f32| if w * zb <= 1.0 { 1.0 } else { 0.0 };
        let m = &self.inv_depth;
        let top = lit(m[i]) * (1.0 - fu) + lit(m[i + 1]) * fu;
        let bottom = lit(m[i + self.size]) * (1.0 - fu) + lit(m[i + self.size + 1]) * fu;
        top * (1.0 - fv) + bottom * fv
    }
}

/// Bounding sphere (camera frame) of the caster items' mesh bounding boxes.
fn caster_sphere(items: &[RenderItem<'_>]) -> Option<(Vector3<f64>, f64)> {
    let mut lo = Vector3::repeat(f64::INFINITY);
    let mut hi = Vector3::repeat(f64::NEG_INFINITY);
    for item in items {
        let mut mlo = [f32::INFINITY; 3];
        let mut mhi = [f32::NEG_INFINITY; 3];
        for p in &item.shadow_mesh.unwrap_or(item.mesh).positions {
            for c in 0..3 {
                if p[c].is_finite() {
                    mlo[c] = mlo[c].min(p[c]);
                    mhi[c] = mhi[c].max(p[c]);
                }
            }
        }
        if mlo[0] > mhi[0] {
            continue;
        }
        for corner in 0..8 {
            let q = Point3::new(
                if corner & 1 == 0 { mlo[0] } else { mhi[0] } as f64,
                if corner & 2 == 0 { mlo[1] } else { mhi[1] } as f64,
                if corner & 4 == 0 { mlo[2] } else { mhi[2] } as f64,
            );
            let c = item.pose * q;
            lo = lo.inf(&c.coords);
            hi = hi.sup(&c.coords);
        }
    }
    if lo.x > hi.x || lo.x.is_nan() {
        return None;
    }
    let centre = (lo + hi) / 2.0;
    Some((centre, (hi - centre).norm().max(1e-3)))
}

/// The light camera (light-from-render-camera pose) at `eye` looking at `centre`.
fn light_camera(eye: Vector3<f64>, centre: Vector3<f64>) -> Option<Pose> {
    let z = (centre - eye).try_normalize(1e-12)?;
    let helper = if z.x.abs() < 0.9 { Vector3::x() } else { Vector3::y() };
    let x = helper.cross(&z).normalize();
    let y = z.cross(&x);
    let cam_from_light = Rotation3::from_matrix_unchecked(Matrix3::from_columns(&[x, y, z]));
    let pose = Pose::from_parts(Translation3::from(eye), UnitQuaternion::from_rotation_matrix(&cam_from_light));
    Some(pose.inverse())
}

/// Builds one map per light (directional lights first, then point lights);
/// `None` for a light that cannot shadow (no casters, light inside them).
pub(super) fn build_maps(
    items: &[RenderItem<'_>],
    settings: &RenderSettings,
    target: &mut RenderTarget,
) -> Vec<Option<ShadowMap>> {
    let sh = &settings.shadows;
    let n_lights = settings.lighting.lights.len() + settings.lighting.points.len();
    if !sh.enabled || n_lights == 0 {
        return Vec::new();
    }
    let end = sh.end_caster.min(items.len());
    let casters = &items[sh.first_caster.min(end)..end];
    let Some((centre, radius)) = caster_sphere(casters) else {
        return Vec::new();
    };
    let size = sh.map_size as usize;
    let mut scratch: Vec<CamVertex> = Vec::new();
    let eyes =
        settings.lighting.lights.iter().map(|d| Some(centre + d.direction.normalize() * DIRECTIONAL_DISTANCE_M)).chain(
            settings.lighting.points.iter().map(|p| {
                // A point light inside (or at) the casters' sphere cannot use one map.
                ((p.position.coords - centre).norm() > radius * 1.02 + 0.02).then_some(p.position.coords)
            }),
        );
    let mut maps = Vec::with_capacity(n_lights);
    for eye in eyes {
        let Some(eye) = eye else {
            maps.push(None);
            continue;
        };
        let Some(light_from_cam) = light_camera(eye, centre) else {
            maps.push(None);
            continue;
        };
        let dist = (centre - eye).norm();
        let half_angle = (radius / dist).min(0.999).asin();
        let c = (size as f64 - 1.0) / 2.0;
        let f = (c - 1.0) / half_angle.tan();
        let k = Intrinsics { fx: f, fy: f, cx: c, cy: c, width: size as u32, height: size as u32 };
        let mut buf = target.shadow_pool.pop().unwrap_or_default();
        buf.clear();
        buf.resize(size * size, 0.0);
        let z_near = (dist - radius * 1.05).max(0.01);
        raster::rasterise_depth(casters, &light_from_cam, &k, z_near, &mut buf, &mut scratch);
        let m = light_from_cam.rotation.to_rotation_matrix();
        let m = m.matrix();
        let tv = light_from_cam.translation.vector;
        // A texel spans dist / f metres at the casters; bias by about one texel.
        let texel_at_centre = dist / f;
        maps.push(Some(ShadowMap {
            r: std::array::from_fn(|i| std::array::from_fn(|j| m[(i, j)] as f32)),
            t: [tv.x as f32, tv.y as f32, tv.z as f32],
            f: f as f32,
            c: c as f32,
            size,
            inv_depth: buf,
            bias_m: sh.depth_bias_m + texel_at_centre as f32,
            offset_per_z: sh.normal_offset_texels / f as f32,
        }));
    }
    maps
}

/// Returns the maps' buffers to the target for the next frame.
pub(super) fn recycle(maps: Vec<Option<ShadowMap>>, target: &mut RenderTarget) {
    target.shadow_pool.extend(maps.into_iter().flatten().map(|m| m.inv_depth));
}
