//! The colour camera's post-processing after the per-pixel response
//! ([`super::CameraResponse`]: white balance, exposure, vignetting, gamma):
//! optical blur (defocus or motion), sensor noise (read + shot) and JPEG
//! compression artefacts (see `jpeg_artefacts`). Operates on the RGB8 plane
//! in place; depth, labels and coverage are untouched.

use super::noise::{GAUSS_BITS, gauss_table};
use super::target::RenderTarget;
use rand::{RngCore, SeedableRng};

/// Optical blur of the colour image.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Blur {
    #[default]
    None,
    /// Out of focus: Gaussian with this σ in pixels.
    Defocus { sigma_px: f32 },
    /// Camera or object motion during exposure: a line kernel of this length
    /// (pixels) at this angle (radians from the image x axis, y down).
    Motion { length_px: f32, angle_rad: f32 },
}

/// Camera effects applied by [`apply_camera_effects`]; `Default` does nothing.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CameraEffects {
    pub blur: Blur,
    /// Read noise σ in 8-bit levels (signal independent).
    pub read_noise: f32,
    /// Shot noise: variance in levels² per level of signal (σ² = read² + shot · v).
    pub shot_noise: f32,
    /// JPEG quality 1..=100 (IJG scale) of the compression artefacts; `None`: none.
    pub jpeg_quality: Option<u8>,
}

/// Applies blur, then sensor noise (drawn from `seed`), then JPEG artefacts.
pub fn apply_camera_effects(target: &mut RenderTarget, fx: &CameraEffects, seed: u64) {
    if target.pixel_count() == 0 {
        return;
    }
    match fx.blur {
        Blur::None => {}
        Blur::Defocus { sigma_px } => gaussian_blur(target, sigma_px),
        Blur::Motion { length_px, angle_rad } => motion_blur(target, length_px, angle_rad),
    }
    if fx.read_noise > 0.0 || fx.shot_noise > 0.0 {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(seed);
        sensor_noise(target, fx.read_noise, fx.shot_noise, &mut rng);
    }
    if let Some(q) = fx.jpeg_quality {
        let (w, h) = (target.width() as usize, target.height() as usize);
        super::jpeg_artefacts::jpeg_artefacts(&mut target.rgb, w, h, q.clamp(1, 100));
    }
}

/// Separable Gaussian blur (8-bit fixed-point weights, clamped borders).
fn gaussian_blur(t: &mut RenderTarget, sigma: f32) {
    if sigma < 0.2 {
        return;
    }
    let radius = ((2.5 * sigma).ceil() as usize).clamp(1, 12);
    let raw: Vec<f32> = (0..=2 * radius)
        .map(|i| {
            let d = i as f32 - radius as f32;
            (-d * d / (2.0 * sigma * sigma)).exp()
        })
        .collect();
    let sum: f32 = raw.iter().sum();
    let mut weights: Vec<u16> = raw.iter().map(|w| (w / sum * 256.0).round() as u16).collect();
    // Make the weights sum to exactly 256 (brightness preserved).
    let total: u16 = weights.iter().sum();
    weights[radius] = (weights[radius] + 256).saturating_sub(total);
    let taps: Vec<(isize, isize, u16)> = weights
        .iter()
        .enumerate()
        .filter(|(_, w)| **w > 0)
        .map(|(i, &w)| (i as isize - radius as isize, 0, w))
        .collect();
    convolve(t, &taps);
    let taps: Vec<(isize, isize, u16)> = taps.iter().map(|&(d, _, w)| (0, d, w)).collect();
    convolve(t, &taps);
}

/// `rgb = Σ w · rgb shifted by (dx, dy)` (weights sum to 256), borders
/// clamped, via a padded copy so each tap is a contiguous slice (vectorised).
fn convolve(t: &mut RenderTarget, taps: &[(isize, isize, u16)]) {
    let (w, h) = (t.width() as usize, t.height() as usize);
    let px = taps.iter().map(|&(dx, _, _)| dx.unsigned_abs()).max().unwrap_or(0).min(w);
    let py = taps.iter().map(|&(_, dy, _)| dy.unsigned_abs()).max().unwrap_or(0).min(h);
    let (pw, ph) = (w + 2 * px, h + 2 * py);
    let mut padded = vec![0u8; pw * ph * 3];
    for yy in 0..ph {
        let sy = yy.saturating_sub(py).min(h - 1);
        let src = &t.rgb[sy * w * 3..(sy + 1) * w * 3];
        let dst = &mut padded[yy * pw * 3..(yy + 1) * pw * 3];
        dst[px * 3..(px + w) * 3].copy_from_slice(src);
        for x in 0..px {
            dst[x * 3..x * 3 + 3].copy_from_slice(&src[..3]);
            let r = (px + w + x) * 3;
            dst[r..r + 3].copy_from_slice(&src[(w - 1) * 3..]);
        }
    }
    let stride = w * 3;
    let mut acc = vec![0u16; stride];
    for y in 0..h {
        acc.fill(128);
        for &(dx, dy, wt) in taps {
            let sy = (y as isize + dy + py as isize) as usize;
            let sx = (dx + px as isize) as usize;
            let row = &padded[(sy * pw + sx) * 3..(sy * pw + sx) * 3 + stride];
            for (a, &v) in acc.iter_mut().zip(row) {
                *a = a.wrapping_add(wt * v as u16);
            }
        }
        for (o, a) in t.rgb[y * stride..(y + 1) * stride].iter_mut().zip(&acc) {
            *o = (a >> 8) as u8;
        }
    }
}

/// Average of taps along a line through each pixel (nearest-pixel taps).
fn motion_blur(t: &mut RenderTarget, length_px: f32, angle: f32) {
    if length_px < 0.5 {
        return;
    }
    let n = (length_px.round() as usize + 1).clamp(2, 16);
    let (s, c) = angle.sin_cos();
    let mut taps: Vec<(isize, isize, u16)> = (0..n)
        .map(|i| {
            let d = (i as f32 / (n - 1) as f32 - 0.5) * length_px;
            ((d * c).round() as isize, (d * s).round() as isize, (256 / n) as u16)
        })
        .collect();
    let total: u16 = taps.iter().map(|t| t.2).sum();
    taps[n / 2].2 += 256 - total;
    convolve(t, &taps);
}

/// Gaussian read + shot noise, σ(v) = sqrt(read² + shot · v) per level v.
fn sensor_noise(t: &mut RenderTarget, read: f32, shot: f32, rng: &mut impl RngCore) {
    let g = gauss_table();
    let mask = (1usize << GAUSS_BITS) - 1;
    let sigma: [f32; 256] = std::array::from_fn(|v| (read * read + shot.max(0.0) * v as f32).sqrt());
    for px in t.rgb.chunks_exact_mut(3) {
        let r = rng.next_u64() as usize;
        for (c, v) in px.iter_mut().enumerate() {
            let n = g[(r >> (c * GAUSS_BITS as usize)) & mask];
            *v = (*v as f32 + sigma[*v as usize] * n + 0.5) as u8;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> [u8; 3]) -> RenderTarget {
        let mut t = RenderTarget::new(w, h);
        for y in 0..h {
            for x in 0..w {
                let i = ((y * w + x) * 3) as usize;
                t.rgb_mut()[i..i + 3].copy_from_slice(&f(x, y));
            }
        }
        t
    }

    #[test]
    fn blurs_keep_flat_images_and_spread_along_their_direction() {
        let flat = image(33, 21, |_, _| [17, 130, 250]);
        for blur in [Blur::Defocus { sigma_px: 1.7 }, Blur::Motion { length_px: 6.0, angle_rad: 0.7 }] {
            let mut t = flat.clone();
            apply_camera_effects(&mut t, &CameraEffects { blur, ..Default::default() }, 1);
            assert_eq!(t.rgb(), flat.rgb(), "{blur:?} changed a flat image");
        }
        // A bright dot: defocus spreads it symmetrically in x and y.
        let dot = image(21, 21, |x, y| if (x, y) == (10, 10) { [255; 3] } else { [0; 3] });
        let mut t = dot.clone();
        apply_camera_effects(&mut t, &CameraEffects { blur: Blur::Defocus { sigma_px: 1.0 }, ..Default::default() }, 1);
        let at = |t: &RenderTarget, x: u32, y: u32| t.rgb()[((y * 21 + x) * 3) as usize];
        assert!(at(&t, 10, 10) < 80 && at(&t, 10, 10) > at(&t, 11, 10));
        assert_eq!(at(&t, 11, 10), at(&t, 9, 10));
        assert_eq!(at(&t, 10, 11), at(&t, 11, 10));
        assert_eq!(at(&t, 10, 15), 0);
        // Horizontal motion: only the dot's row gets light.
        let mut t = dot.clone();
        let motion = Blur::Motion { length_px: 6.0, angle_rad: 0.0 };
        apply_camera_effects(&mut t, &CameraEffects { blur: motion, ..Default::default() }, 1);
        assert!((7..=13).all(|x| at(&t, x, 10) > 20), "{:?}", (0..21).map(|x| at(&t, x, 10)).collect::<Vec<_>>());
        assert!((0..21).all(|x| at(&t, x, 9) == 0 && at(&t, x, 11) == 0));
    }

    #[test]
    fn sensor_noise_has_the_read_plus_shot_sigma_and_is_seeded() {
        let flat = image(200, 150, |_, _| [128; 3]);
        let fx = CameraEffects { read_noise: 2.0, shot_noise: 0.1, ..Default::default() };
        let mut a = flat.clone();
        apply_camera_effects(&mut a, &fx, 9);
        let mut b = flat.clone();
        apply_camera_effects(&mut b, &fx, 9);
        let mut c = flat.clone();
        apply_camera_effects(&mut c, &fx, 10);
        assert_eq!(a.rgb(), b.rgb());
        assert_ne!(a.rgb(), c.rgb());
        let n = a.rgb().len() as f64;
        let mean = a.rgb().iter().map(|&v| v as f64).sum::<f64>() / n;
        let sd = (a.rgb().iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / n).sqrt();
        let expect = (2.0f64 * 2.0 + 0.1 * 128.0).sqrt();
        // Rounding to integers adds 1/12 of a level² of variance.
        let expect = (expect * expect + 1.0 / 12.0).sqrt();
        assert!((sd / expect - 1.0).abs() < 0.04, "sd {sd} vs {expect}");
        assert!((mean - 128.0).abs() < 0.1, "mean {mean}");
        let mut none = flat.clone();
        apply_camera_effects(&mut none, &CameraEffects::default(), 3);
        assert_eq!(none.rgb(), flat.rgb());
    }
}
