//! JPEG compression artefacts: the lossy half of baseline JPEG (JFIF YCbCr,
//! 4:2:0 chroma subsampling, 8x8 DCT, quantisation with the ITU-T T.81
//! Annex K tables scaled by the IJG quality rule, inverse DCT, nearest
//! chroma upsampling). The entropy coding is lossless, so it is skipped:
//! same artefacts (blocking, ringing, chroma bleeding) at a fraction of an
//! encoder's and decoder's cost.

/// Annex K.1 luminance quantisation table (row-major, natural order).
const LUMA_Q: [u8; 64] = [
    16, 11, 10, 16, 24, 40, 51, 61, 12, 12, 14, 19, 26, 58, 60, 55, 14, 13, 16, 24, 40, 57, 69, 56, 14, 17, 22, 29, 51,
    87, 80, 62, 18, 22, 37, 56, 68, 109, 103, 77, 24, 35, 55, 64, 81, 104, 113, 92, 49, 64, 78, 87, 103, 121, 120, 101,
    72, 92, 95, 98, 112, 100, 103, 99,
];

/// Annex K.2 chrominance quantisation table.
const CHROMA_Q: [u8; 64] = [
    17, 18, 24, 47, 99, 99, 99, 99, 18, 21, 26, 66, 99, 99, 99, 99, 24, 26, 56, 99, 99, 99, 99, 99, 47, 66, 99, 99, 99,
    99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99, 99,
    99, 99, 99, 99, 99, 99,
];

/// A base table scaled to `quality` (1..=100) by the IJG rule.
fn scaled_table(base: &[u8; 64], quality: u8) -> [f32; 64] {
    let q = quality.clamp(1, 100) as u32;
    let scale = if q < 50 { 5000 / q } else { 200 - 2 * q };
    std::array::from_fn(|i| ((base[i] as u32 * scale + 50) / 100).clamp(1, 255) as f32)
}

/// The orthonormal 8-point DCT-II matrix: `C[u][x] = a(u) cos((2x + 1) u π / 16)`.
fn dct_matrix() -> [[f32; 8]; 8] {
    std::array::from_fn(|u| {
        let a = if u == 0 { (1.0f64 / 8.0).sqrt() } else { (2.0f64 / 8.0).sqrt() };
        std::array::from_fn(|x| (a * ((2 * x + 1) as f64 * u as f64 * std::f64::consts::PI / 16.0).cos()) as f32)
    })
}

/// `out = a · b` for 8x8 matrices (rows of `b` combined, so it vectorises).
#[inline]
fn mul(a: &[[f32; 8]; 8], b: &[[f32; 8]; 8]) -> [[f32; 8]; 8] {
    let mut out = [[0.0f32; 8]; 8];
    for i in 0..8 {
        for k in 0..8 {
            let s = a[i][k];
            for j in 0..8 {
                out[i][j] += s * b[k][j];
            }
        }
    }
    out
}

fn transpose(m: &[[f32; 8]; 8]) -> [[f32; 8]; 8] {
    std::array::from_fn(|i| std::array::from_fn(|j| m[j][i]))
}

/// Round to nearest (ties to even) for |x| < 2^22 without a libm call
/// (baseline x86-64 has no rounding instruction), so loops vectorise.
#[inline(always)]
fn round(x: f32) -> f32 {
    const MAGIC: f32 = 12_582_912.0; // 1.5 · 2^23
    (x + MAGIC) - MAGIC
}

/// Quantises every 8x8 block of a plane (`w x h`, level-shifted) in place;
/// edge blocks replicate the last row and column.
fn quantise_plane(plane: &mut [f32], w: usize, h: usize, q: &[f32; 64], c: &[[f32; 8]; 8], ct: &[[f32; 8]; 8]) {
    let inv_q: [f32; 64] = std::array::from_fn(|i| 1.0 / q[i]);
    for by in (0..h).step_by(8) {
        for bx in (0..w).step_by(8) {
            let block: [[f32; 8]; 8] =
                std::array::from_fn(|y| std::array::from_fn(|x| plane[(by + y).min(h - 1) * w + (bx + x).min(w - 1)]));
            let mut f = mul(&mul(c, &block), ct);
            for (i, row) in f.iter_mut().enumerate() {
                for (j, v) in row.iter_mut().enumerate() {
                    let k = i * 8 + j;
                    *v = round(*v * inv_q[k]) * q[k];
                }
            }
            let back = mul(&mul(ct, &f), c);
            for (y, row) in back.iter().enumerate().take((h - by).min(8)) {
                for (x, &v) in row.iter().enumerate().take((w - bx).min(8)) {
                    plane[(by + y) * w + bx + x] = v;
                }
            }
        }
    }
}

/// Applies JPEG artefacts of the given quality (1..=100) to an RGB8 image in place.
pub(super) fn jpeg_artefacts(rgb: &mut [u8], w: usize, h: usize, quality: u8) {
    if w == 0 || h == 0 || rgb.len() != w * h * 3 {
        return;
    }
    let (cw, ch) = (w.div_ceil(2), h.div_ceil(2));
    let mut yp = vec![0.0f32; w * h];
    let mut cb = vec![0.0f32; cw * ch];
    let mut cr = vec![0.0f32; cw * ch];
    for y in 0..h {
        let crow = (y / 2) * cw;
        for x in 0..w {
            let i = y * w + x;
            let (r, g, b) = (rgb[i * 3] as f32, rgb[i * 3 + 1] as f32, rgb[i * 3 + 2] as f32);
            yp[i] = 0.299 * r + 0.587 * g + 0.114 * b - 128.0;
            let j = crow + x / 2;
            cb[j] += -0.168_736 * r - 0.331_264 * g + 0.5 * b;
            cr[j] += 0.5 * r - 0.418_688 * g - 0.081_312 * b;
        }
    }
    // 2x2 averages (edge cells may hold fewer pixels).
    for cy in 0..ch {
        let ny = if 2 * cy + 1 < h { 2.0 } else { 1.0 };
        for cx in 0..cw {
            let nx = if 2 * cx + 1 < w { 2.0 } else { 1.0 };
            let j = cy * cw + cx;
            cb[j] /= nx * ny;
            cr[j] /= nx * ny;
        }
    }
    let c = dct_matrix();
    let ct = transpose(&c);
    quantise_plane(&mut yp, w, h, &scaled_table(&LUMA_Q, quality), &c, &ct);
    let cq = scaled_table(&CHROMA_Q, quality);
    quantise_plane(&mut cb, cw, ch, &cq, &c, &ct);
    quantise_plane(&mut cr, cw, ch, &cq, &c, &ct);
    let to_u8 = |x: f32| (x + 0.5).clamp(0.0, 255.0) as u8;
    for y in 0..h {
        let crow = (y / 2) * cw;
        for x in 0..w {
            let i = y * w + x;
            let yv = yp[i] + 128.0;
            let j = crow + x / 2;
            let (u, v) = (cb[j], cr[j]);
            rgb[i * 3] = to_u8(yv + 1.402 * v);
            rgb[i * 3 + 1] = to_u8(yv - 0.344_136 * u - 0.714_136 * v);
            rgb[i * 3 + 2] = to_u8(yv + 1.772 * u);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flat_colours_survive_and_low_quality_blocks_a_gradient() {
        // A flat image is a DC-only signal: it comes back within the DC
        // quantisation step (27 at quality 30, ≤ 1.7 levels per channel in
        // YCbCr, ≤ 4 in RGB).
        let (w, h) = (40, 24);
        let mut flat = [90u8, 140, 200].repeat(w * h);
        jpeg_artefacts(&mut flat, w, h, 30);
        assert!(flat.chunks_exact(3).all(|p| p.iter().zip([90, 140, 200]).all(|(&a, b)| (a as i32 - b).abs() <= 4)));
        // A smooth diagonal gradient at quality 10 gets 8x8 blocks: pixels
        // inside a block differ from the original, and more at quality 10
        // than at 95.
        let grad: Vec<u8> = (0..w * h)
            .flat_map(|i| [((i % w) * 6) as u8, ((i / w) * 10) as u8, (((i % w) + (i / w)) * 3) as u8])
            .collect();
        let err = |q: u8| {
            let mut img = grad.clone();
            jpeg_artefacts(&mut img, w, h, q);
            img.iter().zip(&grad).map(|(&a, &b)| (a as i32 - b as i32).unsigned_abs() as u64).sum::<u64>()
        };
        let (lo, hi) = (err(10), err(95));
        assert!(lo > 3 * hi.max(1), "quality 10 error {lo}, quality 95 error {hi}");
        assert!(
            hi < (w * h * 3) as u64 * 3,
            "quality 95 should be close: mean error {}",
            hi as f64 / (w * h * 3) as f64
        );
    }
}
