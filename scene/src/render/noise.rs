//! Sensor-noise model for rendered RGB-D frames (structured-light / active
//! stereo class: Kinect v1, Xtion, RealSense D4xx), deterministic from a seed.
//!
//! Depth: axial Gaussian noise σ(z) = base + quadratic · (z − reference)²
//! (Nguyen, Izadi, Lovell 2012), disparity-style quantisation with a step
//! growing as z², missing depth at depth discontinuities, at grazing angles,
//! out of range and at random. Colour: a slight Gaussian blur and per-channel
//! Gaussian noise. Labels and coverage stay ground truth.

use super::depth_to_u16;
use super::target::RenderTarget;
use rand::{RngCore, SeedableRng};
use std::sync::OnceLock;

/// Sensor-noise parameters. [`NoiseConfig::default`] models a Kinect-v1 /
/// RealSense-class sensor; [`NoiseConfig::off`] disables everything.
#[derive(Clone, Debug, PartialEq)]
pub struct NoiseConfig {
    /// Master switch: when false, [`apply_noise`] leaves the frame untouched.
    pub enabled: bool,
    /// σ(z) = base + quadratic · (z − reference)²: base in metres (0.0012).
    pub depth_sigma_base_m: f64,
    /// Quadratic coefficient in 1/m (0.0019): σ = 1.2 mm at 0.4 m, 1.9 mm at 1.0 m, 3.1 mm at 1.4 m.
    pub depth_sigma_quadratic_per_m: f64,
    /// Reference distance of the noise minimum in metres (0.4).
    pub depth_sigma_reference_m: f64,
    /// Disparity quantisation (1/m; 0 = off): 1/z is rounded to multiples of
    /// this, so the depth step is ≈ this · z². 0.0025 ≈ a 580 px focal length,
    /// 7.5 cm baseline and 1/8 px disparity steps (2.5 mm at 1 m).
    pub depth_step_per_m: f64,
    /// A pixel lies on a depth discontinuity when a 4-neighbour's depth differs
    /// by more than this fraction of its own depth (0.03: 3 cm at 1 m) or is missing.
    pub edge_jump_relative: f64,
    /// Probability that a discontinuity pixel loses its depth (0.7).
    pub edge_dropout_prob: f64,
    /// Surfaces seen at more than this angle (degrees) between normal and
    /// view ray return no depth (78).
    pub grazing_angle_deg: f64,
    /// Probability that any other valid pixel loses its depth (0.002).
    pub random_dropout_prob: f64,
    /// Valid range in metres (0.2 .. 6.0); depth outside it is missing.
    pub min_range_m: f64,
    pub max_range_m: f64,
    /// Colour noise σ in 8-bit levels (2.0).
    pub rgb_sigma: f32,
    /// Colour blur σ in pixels (0.6; ≤ 0.3 disables the 3-tap blur).
    pub rgb_blur_sigma_px: f32,
}

impl Default for NoiseConfig {
    fn default() -> Self {
        NoiseConfig {
            enabled: true,
            depth_sigma_base_m: 0.0012,
            depth_sigma_quadratic_per_m: 0.0019,
            depth_sigma_reference_m: 0.4,
            depth_step_per_m: 0.0025,
            edge_jump_relative: 0.03,
            edge_dropout_prob: 0.7,
            grazing_angle_deg: 78.0,
            random_dropout_prob: 0.002,
            min_range_m: 0.2,
            max_range_m: 6.0,
            rgb_sigma: 2.0,
            rgb_blur_sigma_px: 0.6,
        }
    }
}

impl NoiseConfig {
    /// No noise at all: rendered frames stay exact.
    pub fn off() -> Self {
        NoiseConfig { enabled: false, ..Default::default() }
    }

    /// Axial depth noise σ (metres) at depth z (metres).
    pub fn depth_sigma(&self, z_m: f64) -> f64 {
        let d = z_m - self.depth_sigma_reference_m;
        self.depth_sigma_base_m + self.depth_sigma_quadratic_per_m * d * d
    }
}

/// Bits of the Gaussian table index.
pub const GAUSS_BITS: u32 = 12;

/// 4096 equiprobable standard-normal values (inverse CDF at bin midpoints,
/// rescaled to unit variance): a table lookup per sample instead of Box–Muller.
pub fn gauss_table() -> &'static [f32; 1 << GAUSS_BITS] {
    static T: OnceLock<[f32; 1 << GAUSS_BITS]> = OnceLock::new();
    T.get_or_init(|| {
        let n = 1usize << GAUSS_BITS;
        let mut t: [f32; 1 << GAUSS_BITS] =
            std::array::from_fn(|i| inverse_normal_cdf((i as f64 + 0.5) / n as f64) as f32);
        let var = t.iter().map(|&g| (g as f64).powi(2)).sum::<f64>() / n as f64;
        let s = (1.0 / var.sqrt()) as f32;
        t.iter_mut().for_each(|g| *g *= s);
        t
    })
}

/// Acklam's rational approximation of the standard normal quantile (|rel err| < 1.2e-9).
#[allow(clippy::excessive_precision)] // the published coefficients, verbatim
fn inverse_normal_cdf(p: f64) -> f64 {
    const A: [f64; 6] = [
        -3.969683028665376e+01,
        2.209460984245205e+02,
        -2.759285104469687e+02,
        1.383577518672690e+02,
        -3.066479806614716e+01,
        2.506628277459239e+00,
    ];
    const B: [f64; 5] = [
        -5.447609879822406e+01,
        1.615858368580409e+02,
        -1.556989798598866e+02,
        6.680131188771972e+01,
        -1.328068155288572e+01,
    ];
    const C: [f64; 6] = [
        -7.784894002430293e-03,
        -3.223964580411365e-01,
        -2.400758277161838e+00,
        -2.549732539343734e+00,
        4.374664141464968e+00,
        2.938163982698783e+00,
    ];
    const D: [f64; 4] = [7.784695709041462e-03, 3.224671290700398e-01, 2.445134137142996e+00, 3.754408661907416e+00];
    let tail = |q: f64| {
        (((((C[0] * q + C[1]) * q + C[2]) * q + C[3]) * q + C[4]) * q + C[5])
            / ((((D[0] * q + D[1]) * q + D[2]) * q + D[3]) * q + 1.0)
    };
    if p < 0.02425 {
        tail((-2.0 * p.ln()).sqrt())
    } else if p > 1.0 - 0.02425 {
        -tail((-2.0 * (1.0 - p).ln()).sqrt())
    } else {
        let q = p - 0.5;
        let r = q * q;
        (((((A[0] * r + A[1]) * r + A[2]) * r + A[3]) * r + A[4]) * r + A[5]) * q
            / (((((B[0] * r + B[1]) * r + B[2]) * r + B[3]) * r + B[4]) * r + 1.0)
    }
}

/// Applies the noise model in place to the last rendered frame (depth in
/// metres and u16, RGB). Deterministic for a given frame, config and seed.
pub fn apply_noise(target: &mut RenderTarget, cfg: &NoiseConfig, seed: u64) {
    if !cfg.enabled || target.pixel_count() == 0 {
        return;
    }
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    noise_depth(target, cfg, &mut rng);
    blur_rgb(target, cfg.rgb_blur_sigma_px);
    noise_rgb(target, cfg.rgb_sigma, &mut rng);
}

/// The depth part of [`apply_noise`] alone: the same depth as `apply_noise`
/// with the same config and seed, colour untouched.
pub fn apply_noise_depth(target: &mut RenderTarget, cfg: &NoiseConfig, seed: u64) {
    if !cfg.enabled || target.pixel_count() == 0 {
        return;
    }
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    noise_depth(target, cfg, &mut rng);
}

/// The colour part of [`apply_noise`] alone (blur, then Gaussian noise drawn
/// from `seed`); depth untouched.
pub fn apply_noise_colour(target: &mut RenderTarget, cfg: &NoiseConfig, seed: u64) {
    if !cfg.enabled || target.pixel_count() == 0 {
        return;
    }
    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
    blur_rgb(target, cfg.rgb_blur_sigma_px);
    noise_rgb(target, cfg.rgb_sigma, &mut rng);
}

fn noise_depth(t: &mut RenderTarget, cfg: &NoiseConfig, rng: &mut impl RngCore) {
    let g = gauss_table();
    let (w, h) = (t.width() as usize, t.height() as usize);
    t.scratch_f32.copy_from_slice(&t.depth_m);
    let src = &t.scratch_f32;
    let cos_min = cfg.grazing_angle_deg.to_radians().cos() as f32;
    // Incidence needs the last render's triangles and camera; without them
    // (a target filled by hand) the grazing-angle test is skipped.
    let grazing = t.intrinsics.filter(|_| cos_min > 0.0);
    let to_u16 = |p: f64| (p.clamp(0.0, 1.0) * 65536.0) as u32;
    let edge_thresh = to_u16(cfg.edge_dropout_prob);
    let random_thresh = to_u16(cfg.random_dropout_prob);
    let rel = cfg.edge_jump_relative as f32;
    let (zmin, zmax) = (cfg.min_range_m, cfg.max_range_m);
    for y in 0..h {
        for x in 0..w {
            let p = y * w + x;
            let r = rng.next_u64();
            let z = src[p];
            let out = 'px: {
                if z <= 0.0 {
                    break 'px 0.0;
                }
                let zd = z as f64;
                if zd < zmin || zd > zmax {
                    break 'px 0.0;
                }
                if let Some(k) = &grazing
                    && let Some(tri) = t.tris.get(t.tri_id[p] as usize)
                {
                    let rx = ((x as f64 - k.cx) / k.fx) as f32;
                    let ry = ((y as f64 - k.cy) / k.fy) as f32;
                    if tri.cos_incidence(rx, ry) < cos_min {
                        break 'px 0.0;
                    }
                }
                if ((r & 0xFFFF) as u32) < random_thresh {
                    break 'px 0.0;
                }
                let jump = |q: usize| {
                    let n = src[q];
                    n <= 0.0 || (n - z).abs() > rel * z
                };
                let edge = (x > 0 && jump(p - 1))
                    || (x + 1 < w && jump(p + 1))
                    || (y > 0 && jump(p - w))
                    || (y + 1 < h && jump(p + w));
                if edge && (((r >> 16) & 0xFFFF) as u32) < edge_thresh {
                    break 'px 0.0;
                }
                let n = g[((r >> 32) as usize) & ((1 << GAUSS_BITS) - 1)] as f64;
                let mut zn = zd + cfg.depth_sigma(zd) * n;
                // Disparity quantisation: 1/z on a grid of `depth_step_per_m`,
                // i.e. a depth step of about depth_step_per_m · z².
                let c = cfg.depth_step_per_m;
                if c > 0.0 && zn > 0.0 {
                    let q = (1.0 / (zn * c) + 0.5) as u64 as f64;
                    zn = if q >= 1.0 { 1.0 / (q * c) } else { 0.0 };
                }
                if zn.is_finite() && zn > 0.0 { zn } else { 0.0 }
            };
            t.depth_m[p] = out as f32;
            t.depth_u16[p] = depth_to_u16(out);
        }
    }
}

/// Separable 3-tap Gaussian blur of the RGB plane (clamped borders), in
/// 8.8 fixed point.
fn blur_rgb(t: &mut RenderTarget, sigma_px: f32) {
    if sigma_px <= 0.3 {
        return;
    }
    let side = (-1.0 / (2.0 * sigma_px * sigma_px)).exp();
    let ws = (256.0 * side / (1.0 + 2.0 * side)).round() as u32;
    let wc = 256 - 2 * ws;
    let mix = |a: u8, b: u8, c: u8| ((wc * b as u32 + ws * (a as u32 + c as u32) + 128) >> 8) as u8;
    let (w, h) = (t.width() as usize, t.height() as usize);
    let stride = w * 3;
    // Horizontal: rgb → scratch.
    for (src, dst) in t.rgb.chunks_exact(stride).zip(t.scratch_rgb.chunks_exact_mut(stride)) {
        for x in 0..w {
            let (l, r) = (x.saturating_sub(1) * 3, (x + 1).min(w - 1) * 3);
            let c = x * 3;
            for ch in 0..3 {
                dst[c + ch] = mix(src[l + ch], src[c + ch], src[r + ch]);
            }
        }
    }
    // Vertical: scratch → rgb.
    for y in 0..h {
        let (u, d) = (y.saturating_sub(1), (y + 1).min(h - 1));
        let up = &t.scratch_rgb[u * stride..(u + 1) * stride];
        let mid = &t.scratch_rgb[y * stride..(y + 1) * stride];
        let down = &t.scratch_rgb[d * stride..(d + 1) * stride];
        let out = &mut t.rgb[y * stride..(y + 1) * stride];
        for i in 0..stride {
            out[i] = mix(up[i], mid[i], down[i]);
        }
    }
}

fn noise_rgb(t: &mut RenderTarget, sigma: f32, rng: &mut impl RngCore) {
    if sigma <= 0.0 {
        return;
    }
    let g = gauss_table();
    let mask = (1usize << GAUSS_BITS) - 1;
    for px in t.rgb.chunks_exact_mut(3) {
        let r = rng.next_u64() as usize;
        for (c, v) in px.iter_mut().enumerate() {
            let n = g[(r >> (c * GAUSS_BITS as usize)) & mask];
            // Saturating cast: below 0 → 0, above 255 → 255.
            *v = (*v as f32 + sigma * n + 0.5) as u8;
        }
    }
}
