//! Structured light / active stereo (RealSense D4xx, Kinect v1 class).
//!
//! Axial noise after Nguyen, Izadi & Lovell, "Modeling Kinect sensor noise
//! for improved 3D reconstruction and tracking" (3DIMPVT 2012):
//! `σ_z(z, θ) = 0.0012 + 0.0019 (z − 0.4)²` metres, plus
//! `0.0001 / √z · θ² / (π/2 − θ)²` metres at incidence θ beyond 60°; lateral noise
//! `σ_L(θ) = 0.8 + 0.035 θ / (π/2 − θ)` pixels (applied at depth edges, where
//! it makes them ragged). Depth comes from disparity `d = f·b / z`, quantised
//! to `subpixel_step_px`. The projector sits `baseline_m` along +x of the
//! camera: surfaces it cannot see (its shadow, on the −x side of foreground
//! objects) get no depth, found by a visibility sweep along each image row
//! (rows are the epipolar lines). Also: holes and flying pixels at depth
//! discontinuities, dropouts on dark (low infrared reflectance), specular
//! and steep surfaces, and at random.

use super::{discontinuity, incidence_cosines, unit16};
use crate::render::depth_to_u16;
use crate::render::noise::{GAUSS_BITS, gauss_table};
use crate::render::target::RenderTarget;
use rand::{RngCore, SeedableRng};

/// Structured-light parameters; [`Default`] is a RealSense D4xx-class sensor
/// with the Kinect noise curve of Nguyen et al.
#[derive(Clone, Debug, PartialEq)]
pub struct StructuredLightParams {
    /// Axial σ at the reference distance, metres (0.0012).
    pub sigma_base_m: f64,
    /// Quadratic growth of axial σ, 1/m (0.0019): σ = base + quadratic · (z − reference)².
    pub sigma_quadratic_per_m: f64,
    /// Distance of the σ minimum, metres (0.4).
    pub sigma_reference_m: f64,
    /// Steep-incidence term, m^1.5 (0.0001): beyond θ = 60° adds `this / √z · θ² / (π/2 − θ)²`.
    pub sigma_angle_m: f64,
    /// Lateral σ at normal incidence, pixels (0.8).
    pub lateral_sigma_px: f64,
    /// Lateral growth with incidence, pixels (0.035): `σ_L = 0.8 + this · θ / (π/2 − θ)`.
    pub lateral_angle_px: f64,
    /// Projector–camera baseline, metres, projector along +x (0.05).
    pub baseline_m: f64,
    /// Disparity quantisation step in pixels (0.125; 0 = off). The depth
    /// step is `z² · step / (f · baseline)`: 2.3 mm at 1 m for f = 1067 px.
    pub subpixel_step_px: f64,
    /// Drop pixels the projector cannot see (true).
    pub projector_shadows: bool,
    /// A depth discontinuity: a 4-neighbour missing or differing by more than
    /// this fraction of the depth (0.03).
    pub edge_jump_relative: f64,
    /// Probability that a discontinuity pixel loses its depth (0.5).
    pub edge_hole_prob: f64,
    /// Probability that a remaining discontinuity pixel becomes a flying
    /// pixel between the two surfaces (0.25).
    pub flying_pixel_prob: f64,
    /// Steeper incidence (degrees from the normal) returns no depth (75).
    pub grazing_angle_deg: f64,
    /// Albedo luminance (linear) below which the pattern is lost more and
    /// more (0.03, about sRGB 48).
    pub dark_reflectance: f64,
    /// Dropout probability at zero reflectance (0.7), falling linearly to 0
    /// at `dark_reflectance`.
    pub dark_dropout_prob: f64,
    /// Specular strength (0..1) above which glare washes the pattern out (0.3).
    pub specular_threshold: f64,
    /// Dropout probability on glare (0.85).
    pub specular_dropout_prob: f64,
    /// Dropout probability of any other pixel (0.002).
    pub random_dropout_prob: f64,
    /// Valid range, metres (0.2 .. 6.0).
    pub min_range_m: f64,
    pub max_range_m: f64,
}

impl Default for StructuredLightParams {
    fn default() -> Self {
        StructuredLightParams {
            sigma_base_m: 0.0012,
            sigma_quadratic_per_m: 0.0019,
            sigma_reference_m: 0.4,
            sigma_angle_m: 0.0001,
            lateral_sigma_px: 0.8,
            lateral_angle_px: 0.035,
            baseline_m: 0.05,
            subpixel_step_px: 0.125,
            projector_shadows: true,
            edge_jump_relative: 0.03,
            edge_hole_prob: 0.5,
            flying_pixel_prob: 0.25,
            grazing_angle_deg: 75.0,
            dark_reflectance: 0.03,
            dark_dropout_prob: 0.7,
            specular_threshold: 0.3,
            specular_dropout_prob: 0.85,
            random_dropout_prob: 0.002,
            min_range_m: 0.2,
            max_range_m: 6.0,
        }
    }
}

impl StructuredLightParams {
    /// Axial noise σ (metres) at depth `z_m` at normal incidence:
    /// `sigma_base_m + sigma_quadratic_per_m · (z − sigma_reference_m)²`.
    pub fn axial_sigma_m(&self, z_m: f64) -> f64 {
        let d = z_m - self.sigma_reference_m;
        self.sigma_base_m + self.sigma_quadratic_per_m * d * d
    }

    /// Axial σ (metres) at depth `z_m` and incidence `theta_rad` (from the
    /// normal): the angle term applies beyond 60°, as in the paper.
    pub fn sigma_m(&self, z_m: f64, theta_rad: f64) -> f64 {
        if theta_rad <= std::f64::consts::FRAC_PI_3 {
            return self.axial_sigma_m(z_m);
        }
        let room = (std::f64::consts::FRAC_PI_2 - theta_rad).max(0.05);
        self.axial_sigma_m(z_m) + self.sigma_angle_m / z_m.max(1e-3).sqrt() * theta_rad * theta_rad / (room * room)
    }

    /// Lateral σ (pixels) at incidence `theta_rad`.
    pub fn lateral_sigma_px(&self, theta_rad: f64) -> f64 {
        let room = (std::f64::consts::FRAC_PI_2 - theta_rad).max(0.05);
        self.lateral_sigma_px + self.lateral_angle_px * theta_rad / room
    }
}

/// Marks (1) pixels the projector at `baseline` along +x cannot see: sweeping
/// each row from the right, a pixel is shadowed when a pixel to its right
/// projects further left in the projector image (`u − f·b/z` smaller), i.e.
/// a nearer surface lies on its projector ray.
pub(super) fn projector_shadow_mask(src: &[f32], w: usize, h: usize, fb: f32, mask: &mut [u8]) {
    // Tolerance in projector pixels against rounding on slanted planes.
    const EPS_PX: f32 = 0.02;
    for y in 0..h {
        let row = &src[y * w..(y + 1) * w];
        let out = &mut mask[y * w..(y + 1) * w];
        let mut min_up = f32::INFINITY;
        for x in (0..w).rev() {
            let z = row[x];
            if z <= 0.0 {
                out[x] = 0;
                continue;
            }
            let up = x as f32 - fb / z;
            if up > min_up + EPS_PX {
                out[x] = 1;
            } else {
                out[x] = 0;
                min_up = min_up.min(up);
            }
        }
    }
}

pub(super) fn apply(t: &mut RenderTarget, prm: &StructuredLightParams, seed: u64) {
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    let g = gauss_table();
    let gmask = (1usize << GAUSS_BITS) - 1;
    let (w, h) = (t.width() as usize, t.height() as usize);
    let fx = t.intrinsics.map_or(1000.0, |k| k.fx);
    t.scratch_f32.copy_from_slice(&t.depth_m);
    let mut cosines = std::mem::take(&mut t.scratch_f32b);
    incidence_cosines(t, &mut cosines);
    let mut shadow = std::mem::take(&mut t.scratch_u8);
    shadow.resize(w * h, 0);
    if prm.projector_shadows && prm.baseline_m > 0.0 {
        projector_shadow_mask(&t.scratch_f32, w, h, (fx * prm.baseline_m) as f32, &mut shadow);
    } else {
        shadow.fill(0);
    }
    let src = std::mem::take(&mut t.scratch_f32);
    let cos_min = prm.grazing_angle_deg.to_radians().cos() as f32;
    let rel = prm.edge_jump_relative as f32;
    let p16 = |p: f64| (p.clamp(0.0, 1.0) * 65536.0) as u32;
    let (random_t, hole_t, flying_t) =
        (p16(prm.random_dropout_prob), p16(prm.edge_hole_prob), p16(prm.flying_pixel_prob));
    let dark_ref = prm.dark_reflectance as f32;
    let spec_t = (prm.specular_threshold * 255.0) as u8;
    let spec_p = p16(prm.specular_dropout_prob);
    // Disparity quantisation: 1/z on a grid of step / (f · b).
    let inv_step = if prm.subpixel_step_px > 0.0 && prm.baseline_m > 0.0 {
        prm.subpixel_step_px / (fx * prm.baseline_m)
    } else {
        0.0
    };
    for y in 0..h {
        for x in 0..w {
            let p = y * w + x;
            let r = rng.next_u64();
            let z0 = src[p];
            let out = 'px: {
                if z0 <= 0.0 || shadow[p] != 0 {
                    break 'px 0.0;
                }
                let zd = z0 as f64;
                if zd < prm.min_range_m || zd > prm.max_range_m {
                    break 'px 0.0;
                }
                let cos = cosines[p];
                if cos < cos_min {
                    break 'px 0.0;
                }
                if ((r & 0xFFFF) as u32) < random_t {
                    break 'px 0.0;
                }
                let refl = t.reflectance[p] as f32 / 255.0;
                if refl < dark_ref {
                    let prob = prm.dark_dropout_prob as f32 * (1.0 - refl / dark_ref);
                    if unit16(r >> 16) < prob {
                        break 'px 0.0;
                    }
                }
                if t.specular[p] > spec_t && (((r >> 32) & 0xFFFF) as u32) < spec_p {
                    break 'px 0.0;
                }
                // acos only where it matters (steep surfaces, edges).
                let theta = || (cos.clamp(0.0, 1.0) as f64).acos();
                let steep = cos < 0.5;
                let mut z = zd;
                if let Some(q) = discontinuity(&src, w, h, x, y, rel) {
                    let r2 = rng.next_u64();
                    if ((r2 & 0xFFFF) as u32) < hole_t {
                        break 'px 0.0;
                    }
                    if (((r2 >> 16) & 0xFFFF) as u32) < flying_t && src[q] > 0.0 {
                        // Flying pixel: somewhere between the two surfaces.
                        let a = 0.15 + 0.7 * unit16(r2 >> 32) as f64;
                        z = zd + a * (src[q] as f64 - zd);
                    } else {
                        // Lateral noise makes the edge ragged: take the depth
                        // of a pixel displaced by N(0, σ_L) in x and y.
                        let sl = prm.lateral_sigma_px(theta());
                        let dx = (sl * g[((r2 >> 32) as usize) & gmask] as f64).round() as isize;
                        let dy = (sl * g[((r2 >> 44) as usize) & gmask] as f64).round() as isize;
                        let sx = (x as isize + dx).clamp(0, w as isize - 1) as usize;
                        let sy = (y as isize + dy).clamp(0, h as isize - 1) as usize;
                        let zs = src[sy * w + sx];
                        if zs <= 0.0 {
                            break 'px 0.0;
                        }
                        z = zs as f64;
                    }
                }
                let n = g[((r >> 48) as usize) & gmask] as f64;
                let sigma = if steep { prm.sigma_m(z, theta()) } else { prm.axial_sigma_m(z) };
                let mut zn = z + sigma * n;
                if inv_step > 0.0 && zn > 0.0 {
                    let q = (1.0 / (zn * inv_step) + 0.5) as u64 as f64;
                    zn = if q >= 1.0 { 1.0 / (q * inv_step) } else { 0.0 };
                }
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
    t.scratch_u8 = shadow;
}
