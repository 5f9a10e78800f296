//! Continuous-wave time of flight (Kinect v2 / Azure Kinect class).
//!
//! Noise: `σ = sigma_at_1m_m · z / a`, with the amplitude `a = ρ · cos θ`
//! (albedo luminance times incidence cosine, 1 for a white wall facing the
//! camera): phase noise grows with distance and with a weaker return.
//! Returns below `min_amplitude` are dropped. Multipath: light bouncing off a
//! nearby surface arrives late, so depth reads longer in concave corners.
//! The concavity is the second difference of inverse depth across
//! ±`multipath_radius_m` (zero on any plane, positive in a concave corner),
//! measured on a 4-pixel grid in four directions; the bias is
//! `multipath_gain · concavity · z`, capped. Edge mixing: a pixel on a depth
//! discontinuity integrates both surfaces and reads a depth in between.

use super::{discontinuity, incidence_cosines, unit16};
use crate::render::depth_to_u16;
use crate::render::noise::{GAUSS_BITS, gauss_table};
use crate::render::target::RenderTarget;
use rand::{RngCore, SeedableRng};

/// Time-of-flight parameters; [`Default`] is an Azure-Kinect-class sensor.
#[derive(Clone, Debug, PartialEq)]
pub struct TofParams {
    /// Axial σ at 1 m for amplitude 1 (white, facing the camera), metres (0.0015).
    pub sigma_at_1m_m: f64,
    /// Returns weaker than this amplitude (ρ · cos θ) are dropped (0.03).
    pub min_amplitude: f64,
    /// Multipath bias per unit of relative concavity (dimensionless, 0.3).
    pub multipath_gain: f64,
    /// Largest multipath bias, metres (0.02).
    pub multipath_max_m: f64,
    /// Distance over which the concavity is measured, metres (0.03).
    pub multipath_radius_m: f64,
    /// A depth discontinuity: a 4-neighbour missing or differing by more than
    /// this fraction of the depth (0.03).
    pub edge_jump_relative: f64,
    /// Probability that a discontinuity pixel reads a mix of the two depths (0.8).
    pub edge_mix_prob: f64,
    /// Probability that another discontinuity pixel is dropped (0.5).
    pub edge_dropout_prob: f64,
    /// Dropout probability of any other pixel (0.001).
    pub random_dropout_prob: f64,
    /// Valid range, metres (0.25 .. 5.0).
    pub min_range_m: f64,
    pub max_range_m: f64,
}

impl Default for TofParams {
    fn default() -> Self {
        TofParams {
            sigma_at_1m_m: 0.0015,
            min_amplitude: 0.03,
            multipath_gain: 0.3,
            multipath_max_m: 0.02,
            multipath_radius_m: 0.03,
            edge_jump_relative: 0.03,
            edge_mix_prob: 0.8,
            edge_dropout_prob: 0.5,
            random_dropout_prob: 0.001,
            min_range_m: 0.25,
            max_range_m: 5.0,
        }
    }
}

impl TofParams {
    /// Axial σ (metres) at depth `z_m` for amplitude 1: `sigma_at_1m_m · z`.
    pub fn axial_sigma_m(&self, z_m: f64) -> f64 {
        self.sigma_m(z_m, 1.0)
    }

    /// Axial σ (metres) at depth `z_m` and amplitude `a` (ρ · cos θ, 0..1).
    pub fn sigma_m(&self, z_m: f64, amplitude: f64) -> f64 {
        self.sigma_at_1m_m * z_m / amplitude.max(1e-3)
    }
}

/// Grid step (pixels) of the concavity estimate.
const GRID: usize = 4;

/// Relative concavity on a `GRID`-pixel grid (row-major, `gw x gh`).
fn concavity_grid(src: &[f32], w: usize, h: usize, fx: f64, prm: &TofParams) -> (Vec<f32>, usize, usize) {
    let (gw, gh) = (w.div_ceil(GRID), h.div_ceil(GRID));
    let mut out = vec![0.0f32; gw * gh];
    // Neighbours farther off than this are another surface, not a corner.
    const SAME_SURFACE: f32 = 0.12;
    const D: f32 = std::f32::consts::FRAC_1_SQRT_2;
    let dirs: [(f32, f32); 4] = [(1.0, 0.0), (0.0, 1.0), (D, D), (D, -D)];
    for gy in 0..gh {
        for gx in 0..gw {
            let (x, y) = ((gx * GRID).min(w - 1), (gy * GRID).min(h - 1));
            let z = src[y * w + x];
            if z <= 0.0 {
                continue;
            }
            let r = ((prm.multipath_radius_m * fx / z as f64) as f32).clamp(2.0, 60.0);
            let w0 = 1.0 / z;
            let (mut sum, mut n) = (0.0f32, 0);
            for (dx, dy) in dirs {
                let at = |s: f32| -> Option<f32> {
                    let qx = (x as f32 + s * dx * r).round();
                    let qy = (y as f32 + s * dy * r).round();
                    if qx < 0.0 || qy < 0.0 || qx >= w as f32 || qy >= h as f32 {
                        return None;
                    }
                    let zq = src[qy as usize * w + qx as usize];
                    (zq > 0.0 && (zq - z).abs() < SAME_SURFACE * z).then_some(1.0 / zq)
                };
                if let (Some(a), Some(b)) = (at(1.0), at(-1.0)) {
                    sum += 0.5 * (a + b) - w0;
                    n += 1;
                }
            }
            if n > 0 {
                out[gy * gw + gx] = (sum / n as f32 / w0).max(0.0);
            }
        }
    }
    (out, gw, gh)
}

pub(super) fn apply(t: &mut RenderTarget, prm: &TofParams, seed: u64) {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let g = gauss_table();
    let gmask = (1usize << GAUSS_BITS) - 1;
    let (w, h) = (t.width() as usize, t.height() as usize);
    let fx = t.intrinsics.map_or(1000.0, |k| k.fx);
    t.scratch_f32.copy_from_slice(&t.depth_m);
    let mut cosines = std::mem::take(&mut t.scratch_f32b);
    incidence_cosines(t, &mut cosines);
    let src = std::mem::take(&mut t.scratch_f32);
    let (conc, gw, gh) =
        if prm.multipath_gain > 0.0 { concavity_grid(&src, w, h, fx, prm) } else { (Vec::new(), 0, 0) };
    let rel = prm.edge_jump_relative as f32;
    let p16 = |p: f64| (p.clamp(0.0, 1.0) * 65536.0) as u32;
    let (random_t, mix_t, drop_t) = (p16(prm.random_dropout_prob), p16(prm.edge_mix_prob), p16(prm.edge_dropout_prob));
    for y in 0..h {
        let gyf = y as f32 / GRID as f32;
        let gy0 = (gyf as usize).min(gh.saturating_sub(1));
        let gy1 = (gy0 + 1).min(gh.saturating_sub(1));
        let ty = gyf - gy0 as f32;
        for x in 0..w {
            let p = y * w + x;
            let r = rng.next_u64();
            let z0 = src[p];
            let out = 'px: {
                if z0 <= 0.0 {
                    break 'px 0.0;
                }
                let zd = z0 as f64;
                if zd < prm.min_range_m || zd > prm.max_range_m {
                    break 'px 0.0;
                }
                if ((r & 0xFFFF) as u32) < random_t {
                    break 'px 0.0;
                }
                let amplitude = (t.reflectance[p] as f64 / 255.0) * cosines[p].clamp(0.0, 1.0) as f64;
                if amplitude < prm.min_amplitude {
                    break 'px 0.0;
                }
                let mut z = zd;
                if let Some(q) = discontinuity(&src, w, h, x, y, rel) {
                    if (((r >> 16) & 0xFFFF) as u32) < mix_t && src[q] > 0.0 {
                        let a = unit16(r >> 32) as f64;
                        z = zd + a * (src[q] as f64 - zd);
                    } else if (((r >> 32) & 0xFFFF) as u32) < drop_t {
                        break 'px 0.0;
                    }
                }
                if gw > 0 {
                    let gxf = x as f32 / GRID as f32;
                    let gx0 = (gxf as usize).min(gw - 1);
                    let gx1 = (gx0 + 1).min(gw - 1);
                    let tx = gxf - gx0 as f32;
                    let c = (conc[gy0 * gw + gx0] * (1.0 - tx) + conc[gy0 * gw + gx1] * tx) * (1.0 - ty)
                        + (conc[gy1 * gw + gx0] * (1.0 - tx) + conc[gy1 * gw + gx1] * tx) * ty;
                    z += (prm.multipath_gain * c as f64 * z).min(prm.multipath_max_m);
                }
                let n = g[((r >> 48) as usize) & gmask] as f64;
                let zn = z + prm.sigma_m(z, amplitude) * n;
                if zn.is_finite() && zn > 0.0 { zn } else { 0.0 }
            };
            // u16 from the stored f32, so the two planes always agree.
            let out = out as f32;
            t.depth_m[p] = out;
            t.depth_u16[p] = depth_to_u16(out as f64);
        }
    }
    t.scratch_f32 = src;
    t.scratch_f32b = cosines;
}
