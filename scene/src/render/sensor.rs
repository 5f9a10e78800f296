//! Depth-sensor models applied to a rendered frame's depth (metres and u16),
//! deterministic from a seed: [`DepthSensor::Ideal`] (exact), `Basic` (the
//! depth part of [`super::NoiseConfig::default`], bit for bit),
//! `StructuredLight` ([`StructuredLightParams`]) and `Tof` ([`TofParams`]).
//!
//! The models read what the renderer knows besides depth: the surface's
//! incidence angle (from the last render's triangles), its albedo luminance
//! ([`RenderTarget::reflectance`], the stand-in for infrared reflectance) and
//! its specular strength ([`RenderTarget::specular`]). Colour, labels and
//! coverage are never changed (colour noise is the camera pipeline's job).

mod structured_light;
mod tof;

pub use structured_light::StructuredLightParams;
pub use tof::TofParams;

use super::DepthSensor;
use super::noise::{NoiseConfig, apply_noise_depth};
use super::target::RenderTarget;

/// A depth model with explicit parameters (for tests and tuning); the enum
/// [`DepthSensor`] names the default parameters of each.
#[derive(Clone, Debug, PartialEq)]
pub enum DepthSensorModel {
    Ideal,
    Basic(NoiseConfig),
    StructuredLight(StructuredLightParams),
    Tof(TofParams),
}

impl From<DepthSensor> for DepthSensorModel {
    fn from(s: DepthSensor) -> Self {
        match s {
            DepthSensor::Ideal => DepthSensorModel::Ideal,
            DepthSensor::Basic => DepthSensorModel::Basic(NoiseConfig::default()),
            DepthSensor::StructuredLight => DepthSensorModel::StructuredLight(StructuredLightParams::default()),
            DepthSensor::Tof => DepthSensorModel::Tof(TofParams::default()),
        }
    }
}

/// Applies `sensor` (default parameters) to the last rendered frame's depth.
pub fn apply_depth_sensor(target: &mut RenderTarget, sensor: DepthSensor, seed: u64) {
    apply_depth_sensor_model(target, &sensor.into(), seed);
}

/// Applies a depth model with explicit parameters.
pub fn apply_depth_sensor_model(target: &mut RenderTarget, model: &DepthSensorModel, seed: u64) {
    if target.pixel_count() == 0 {
        return;
    }
    match model {
        DepthSensorModel::Ideal => {}
        DepthSensorModel::Basic(cfg) => apply_noise_depth(target, cfg, seed),
        DepthSensorModel::StructuredLight(p) => structured_light::apply(target, p, seed),
        DepthSensorModel::Tof(p) => tof::apply(target, p, seed),
    }
}

/// Whether pixel `p`'s 4-neighbourhood has a depth discontinuity: a
/// neighbour that is missing or differs by more than `rel` of the depth.
/// Returns the neighbour across the largest jump (its index) if so.
#[inline]
fn discontinuity(src: &[f32], w: usize, h: usize, x: usize, y: usize, rel: f32) -> Option<usize> {
    let p = y * w + x;
    let z = src[p];
    let mut best: Option<(usize, f32)> = None;
    let mut consider = |q: usize| {
        let n = src[q];
        let jump = if n <= 0.0 { f32::INFINITY } else { (n - z).abs() };
        if jump > rel * z && best.is_none_or(|(_, j)| jump > j) {
            best = Some((q, jump));
        }
    };
    if x > 0 {
        consider(p - 1);
    }
    if x + 1 < w {
        consider(p + 1);
    }
    if y > 0 {
        consider(p - w);
    }
    if y + 1 < h {
        consider(p + w);
    }
    best.map(|(q, _)| q)
}

/// Uniform 0..1 from 16 random bits.
#[inline]
fn unit16(bits: u64) -> f32 {
    (bits & 0xFFFF) as f32 / 65536.0
}

/// The cosine of the incidence angle at every pixel of the last render (1
/// where unknown), into `out`.
fn incidence_cosines(t: &RenderTarget, out: &mut Vec<f32>) {
    let (w, h) = (t.width() as usize, t.height() as usize);
    out.clear();
    out.resize(w * h, 1.0);
    let Some(k) = t.intrinsics else {
        return;
    };
    for y in 0..h {
        let ry = ((y as f64 - k.cy) / k.fy) as f32;
        for x in 0..w {
            let p = y * w + x;
            if let Some(tri) = t.tris.get(t.tri_id[p] as usize) {
                let rx = ((x as f64 - k.cx) / k.fx) as f32;
                out[p] = tri.cos_incidence(rx, ry);
            }
        }
    }
}

#[cfg(test)]
mod tests;
