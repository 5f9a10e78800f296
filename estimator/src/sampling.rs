//! Per-instance network inputs: pixel sampling, back-projection and colour crops.
//!
//! Pure functions over borrowed buffers; [`crate::Workspace::prepare`] calls
//! them with its preallocated arrays, so nothing here allocates.
//!
//! - **Pixel sampling** ([`sample_pixels`]): N pixels from an instance's
//!   valid-depth pixels: a random subset without replacement (partial
//!   Fisher–Yates) when there are at least N, otherwise all of them repeated
//!   cyclically ("wrap padding") in their original raster order.
//! - **Back-projection** ([`back_project`]): pixel (u, v) at depth z (metres)
//!   → x = (u − cx)·z/fx, y = (v − cy)·z/fy, z; camera optical frame
//!   (x right, y down, z forward), metres.
//! - **Crop window** ([`crop_window`]): a square of side
//!   ceil(max(bbox w, h)·(1 + margin)) pixels centred on the bbox centre. If
//!   it sticks out of the image it is shifted inside (keeping its size); if it
//!   is larger than the image's shorter side it is shrunk to that side (then
//!   the crop can cut off part of a very large object).
//! - **Crop resampling** ([`resample_crop`]): the window → S×S, bilinear,
//!   pixel centres aligned (crop cell (r, c) samples the image at
//!   u = u0 + (c + ½)·side/S − ½), RGB normalised as (x/255 − mean)/std with
//!   the ImageNet mean and std. BGR input is swapped to RGB.
//! - **Crop cell** ([`crop_cell`]): the index row·S + col of the crop cell
//!   nearest to a pixel centre; with side == S it is exactly the pixel.

use rand::Rng;

use crate::frame::{ColorFormat, FrameView};

/// ImageNet per-channel mean of rgb/255 (R, G, B).
pub const IMAGENET_MEAN: [f32; 3] = [0.485, 0.456, 0.406];
/// ImageNet per-channel standard deviation of rgb/255 (R, G, B).
pub const IMAGENET_STD: [f32; 3] = [0.229, 0.224, 0.225];

/// Normalises an 8-bit colour value of channel `c` (0 = R, 1 = G, 2 = B).
#[inline]
pub fn normalise_channel(value: f32, c: usize) -> f32 {
    (value / 255.0 - IMAGENET_MEAN[c]) / IMAGENET_STD[c]
}

/// Fills `out` with pixel indices drawn from `candidates`.
///
/// With `candidates.len() >= out.len()`: a uniform random subset without
/// replacement (partial Fisher–Yates; `candidates` is permuted in place).
/// With fewer: `candidates` repeated cyclically in their given order. With no
/// candidates `out` is left untouched and `false` returned.
pub fn sample_pixels<R: Rng + ?Sized>(candidates: &mut [u32], out: &mut [u32], rng: &mut R) -> bool {
    let len = candidates.len();
    if len == 0 {
        return false;
    }
    let n = out.len();
    if len >= n {
        for i in 0..n {
            let j = rng.random_range(i..len);
            candidates.swap(i, j);
        }
        out.copy_from_slice(&candidates[..n]);
    } else {
        for (i, o) in out.iter_mut().enumerate() {
            *o = candidates[i % len];
        }
    }
    true
}

/// Back-projects pixel (u, v) at depth `z` metres into the camera optical
/// frame (x right, y down, z forward), metres.
#[inline]
pub fn back_project(frame: &FrameView<'_>, u: usize, v: usize, z: f32) -> [f32; 3] {
    let k = &frame.intrinsics;
    let z64 = z as f64;
    [((u as f64 - k.cx) * z64 / k.fx) as f32, ((v as f64 - k.cy) * z64 / k.fy) as f32, z]
}

/// Square crop window `[u0, v0, side]` (pixels) around `bbox`
/// (`[u_min, v_min, u_max, v_max]` inclusive) in a `width` x `height` image;
/// see the module doc for the margin, shifting and shrinking rules.
pub fn crop_window(bbox: [u16; 4], margin: f32, width: usize, height: usize) -> [u32; 3] {
    let bw = (bbox[2] as f64 - bbox[0] as f64 + 1.0).max(1.0);
    let bh = (bbox[3] as f64 - bbox[1] as f64 + 1.0).max(1.0);
    let margin = if margin.is_finite() { margin.max(0.0) as f64 } else { 0.0 };
    // The small slack keeps f32 rounding of the margin from adding a pixel.
    let wanted = (bw.max(bh) * (1.0 + margin) - 1e-6).ceil().max(1.0);
    let side = (wanted as usize).min(width.min(height)).max(1);
    let cu = (bbox[0] as f64 + bbox[2] as f64) / 2.0;
    let cv = (bbox[1] as f64 + bbox[3] as f64) / 2.0;
    let start = |centre: f64, limit: usize| -> u32 {
        let s = (centre - (side as f64 - 1.0) / 2.0).round();
        s.clamp(0.0, (limit - side) as f64) as u32
    };
    [start(cu, width), start(cv, height), side as u32]
}

/// Resamples the crop `window` of the frame's colour plane into `out`
/// (`[3, S, S]` row-major, `out.len() == 3 * S * S`), bilinear and normalised.
/// The frame must be validated; `window` must lie inside the image.
pub fn resample_crop(frame: &FrameView<'_>, window: [u32; 3], crop_size: usize, out: &mut [f32]) {
    let (w, h) = (frame.width(), frame.height());
    let s = crop_size;
    let [u0, v0, side] = window.map(|x| x as f64);
    let step = side / s as f64;
    let channel_of = match frame.color_format {
        ColorFormat::Rgb8 => [0usize, 1, 2],
        ColorFormat::Bgr8 => [2usize, 1, 0],
    };
    let color = frame.color;
    let (plane_r, rest) = out.split_at_mut(s * s);
    let (plane_g, plane_b) = rest.split_at_mut(s * s);
    for r in 0..s {
        let sv = (v0 + (r as f64 + 0.5) * step - 0.5).clamp(0.0, (h - 1) as f64);
        let v_lo = sv.floor() as usize;
        let v_hi = (v_lo + 1).min(h - 1);
        let fv = (sv - v_lo as f64) as f32;
        for c in 0..s {
            let su = (u0 + (c as f64 + 0.5) * step - 0.5).clamp(0.0, (w - 1) as f64);
            let u_lo = su.floor() as usize;
            let u_hi = (u_lo + 1).min(w - 1);
            let fu = (su - u_lo as f64) as f32;
            let px = |u: usize, v: usize, ch: usize| color[(v * w + u) * 3 + ch] as f32;
            let cell = r * s + c;
            for (dst, plane) in [&mut *plane_r, &mut *plane_g, &mut *plane_b].into_iter().enumerate() {
                let ch = channel_of[dst];
                let top = px(u_lo, v_lo, ch) * (1.0 - fu) + px(u_hi, v_lo, ch) * fu;
                let bottom = px(u_lo, v_hi, ch) * (1.0 - fu) + px(u_hi, v_hi, ch) * fu;
                plane[cell] = normalise_channel(top * (1.0 - fv) + bottom * fv, dst);
            }
        }
    }
}

/// Index `row * S + col` of the crop cell nearest to pixel (u, v)'s centre,
/// clamped to the crop.
#[inline]
pub fn crop_cell(u: usize, v: usize, window: [u32; 3], crop_size: usize) -> u32 {
    let scale = crop_size as f64 / window[2] as f64;
    let cell = |p: usize, origin: u32| -> usize {
        let x = ((p as f64 - origin as f64 + 0.5) * scale).floor();
        x.clamp(0.0, (crop_size - 1) as f64) as usize
    };
    (cell(v, window[1]) * crop_size + cell(u, window[0])) as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{DepthPlane, LabelPlane};
    use fusepose_scene::Intrinsics;
    use rand::SeedableRng;
    use rand_pcg::Pcg64Mcg;

    #[test]
    fn back_projection_matches_hand_computed_points() {
        let color = [0u8; 3 * 4];
        let depth = [0u16; 4];
        let frame = FrameView {
            intrinsics: Intrinsics { fx: 500.0, fy: 400.0, cx: 320.0, cy: 240.0, width: 2, height: 2 },
            color_format: ColorFormat::Rgb8,
            color: &color,
            depth: DepthPlane::U16 { data: &depth, scale: 0.001 },
            labels: None,
        };
        // (420 - 320) * 2 / 500 = 0.4 ; (140 - 240) * 2 / 400 = -0.5
        let p = back_project(&frame, 420, 140, 2.0);
        assert!((p[0] - 0.4).abs() < 1e-6 && (p[1] + 0.5).abs() < 1e-6 && p[2] == 2.0, "{p:?}");
        // The principal point maps onto the optical axis.
        assert_eq!(back_project(&frame, 320, 240, 0.75), [0.0, 0.0, 0.75]);
    }

    #[test]
    fn wrap_padding_repeats_candidates_cyclically() {
        let mut cand = [7u32, 3, 9];
        let mut out = [0u32; 8];
        let mut rng = Pcg64Mcg::seed_from_u64(1);
        assert!(sample_pixels(&mut cand, &mut out, &mut rng));
        assert_eq!(out, [7, 3, 9, 7, 3, 9, 7, 3]);
        assert!(!sample_pixels(&mut [], &mut out, &mut rng));
    }

    #[test]
    fn subsampling_is_without_replacement_and_seeded() {
        let mut cand: Vec<u32> = (100..200).collect();
        let mut a = [0u32; 40];
        sample_pixels(&mut cand, &mut a, &mut Pcg64Mcg::seed_from_u64(42));
        let mut sorted = a.to_vec();
        sorted.sort();
        sorted.dedup();
        assert_eq!(sorted.len(), 40, "no repeats");
        assert!(a.iter().all(|&p| (100..200).contains(&p)));
        let mut cand2: Vec<u32> = (100..200).collect();
        let mut b = [0u32; 40];
        sample_pixels(&mut cand2, &mut b, &mut Pcg64Mcg::seed_from_u64(42));
        assert_eq!(a, b, "same seed, same sample");
        let mut cand3: Vec<u32> = (100..200).collect();
        sample_pixels(&mut cand3, &mut b, &mut Pcg64Mcg::seed_from_u64(43));
        assert_ne!(a, b, "different seed, different sample");
    }

    #[test]
    fn crop_window_adds_margin_and_stays_inside() {
        // 20x10 bbox at the centre of 640x480: side = ceil(20 * 1.15) = 23.
        let win = crop_window([310, 235, 329, 244], 0.15, 640, 480);
        assert_eq!(win[2], 23);
        assert_eq!(win[0], 309); // centre 319.5 - 11 = 308.5 -> round 309
        // Near the top-left corner the square is shifted inside.
        assert_eq!(crop_window([0, 0, 9, 9], 0.5, 640, 480), [0, 0, 15]);
        // Near the bottom-right corner too.
        assert_eq!(crop_window([630, 470, 639, 479], 0.5, 640, 480), [625, 465, 15]);
        // Larger than the shorter side: shrunk to it.
        assert_eq!(crop_window([0, 0, 639, 479], 0.15, 640, 480)[2], 480);
    }

    #[test]
    fn crop_at_scale_one_reproduces_pixels_at_their_cells() {
        let (w, h) = (12usize, 10usize);
        let mut color = vec![0u8; w * h * 3];
        for (i, px) in color.chunks_mut(3).enumerate() {
            px.copy_from_slice(&[(i * 7 % 256) as u8, (i * 13 % 256) as u8, (i * 29 % 256) as u8]);
        }
        let depth = vec![0u16; w * h];
        let labels = vec![0u8; w * h];
        for format in [ColorFormat::Rgb8, ColorFormat::Bgr8] {
            let frame = FrameView {
                intrinsics: Intrinsics { fx: 100.0, fy: 100.0, cx: 6.0, cy: 5.0, width: w as u32, height: h as u32 },
                color_format: format,
                color: &color,
                depth: DepthPlane::U16 { data: &depth, scale: 0.001 },
                labels: Some(LabelPlane::U8(&labels)),
            };
            let s = 6;
            let window = [3, 2, 6];
            let mut crop = vec![0f32; 3 * s * s];
            resample_crop(&frame, window, s, &mut crop);
            for v in 2..8 {
                for u in 3..9 {
                    let cell = crop_cell(u, v, window, s) as usize;
                    assert_eq!(cell, (v - 2) * s + (u - 3));
                    let src = &color[(v * w + u) * 3..][..3];
                    for c in 0..3 {
                        let byte = if format == ColorFormat::Rgb8 { src[c] } else { src[2 - c] };
                        let want = normalise_channel(byte as f32, c);
                        assert!((crop[c * s * s + cell] - want).abs() < 1e-5);
                    }
                }
            }
        }
    }

    #[test]
    fn downscaled_crop_is_bilinear_average() {
        // A 4x4 window into 2x2 cells: each cell samples the centre of a 2x2
        // block, i.e. the mean of its four pixels.
        let (w, h) = (4usize, 4usize);
        let color: Vec<u8> = (0..w * h).flat_map(|i| [(i * 10) as u8; 3]).collect();
        let depth = vec![0f32; w * h];
        let frame = FrameView {
            intrinsics: Intrinsics { fx: 100.0, fy: 100.0, cx: 2.0, cy: 2.0, width: 4, height: 4 },
            color_format: ColorFormat::Rgb8,
            color: &color,
            depth: DepthPlane::F32(&depth),
            labels: None,
        };
        let mut crop = vec![0f32; 3 * 4];
        resample_crop(&frame, [0, 0, 4], 2, &mut crop);
        let mean = (0.0 + 10.0 + 40.0 + 50.0) / 4.0;
        assert!((crop[0] - normalise_channel(mean, 0)).abs() < 1e-5);
        assert_eq!(crop_cell(3, 3, [0, 0, 4], 2), 3);
        assert_eq!(crop_cell(1, 2, [0, 0, 4], 2), 2);
    }
}
