//! Dense layers and 3x3 convolutions on preallocated buffers, with an
//! allocation-free GEMM.
//!
//! `out = act(x · W + b)`: the bias is written into `out` first, the GEMM
//! accumulates onto it, then ReLU runs over the same cache-hot rows.
//! The GEMM (`C += A · B`, all row-major with unit column stride) uses an
//! AVX2/FMA register-blocked kernel (6 rows × 16 columns; each 256-row block
//! of B packed into a 16 KB stack buffer that stays in L1 while the row tiles
//! pass over it; the last 1–7 columns through a lane mask) when the CPU has
//! it, a scalar loop otherwise; it never allocates (matrixmultiply allocates
//! a packing buffer per call, which the per-frame no-allocation rule
//! forbids). Convolutions use im2col into a caller-provided buffer, then one
//! GEMM.

use ndarray::{ArrayView1, ArrayView2, ArrayViewMut2, Axis, ShapeBuilder};

/// Whether the AVX2/FMA kernel can run on this CPU (checked once per call site; cheap).
#[inline]
fn simd_ok() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    {
        false
    }
}

/// `C[m,n] += A[m,k] · B[k,n]` on views with unit column stride (falls back to
/// an index loop for any other layout).
pub fn gemm_acc(a: ArrayView2<f32>, b: ArrayView2<f32>, c: &mut ArrayViewMut2<f32>) {
    let (m, k) = a.dim();
    let (k2, n) = b.dim();
    assert_eq!(k, k2, "gemm inner dimensions");
    assert_eq!(c.dim(), (m, n), "gemm output shape");
    if m == 0 || n == 0 || k == 0 {
        return;
    }
    let unit = |s: &[isize]| s[1] == 1 && s[0] >= 0;
    if !(unit(a.strides()) && unit(b.strides()) && unit(c.strides())) {
        for i in 0..m {
            for p in 0..k {
                let av = a[[i, p]];
                for j in 0..n {
                    c[[i, j]] += av * b[[p, j]];
                }
            }
        }
        return;
    }
    let (lda, ldb, ldc) = (a.strides()[0] as usize, b.strides()[0] as usize, c.strides()[0] as usize);
    let (pa, pb, pc) = (a.as_ptr(), b.as_ptr(), c.as_mut_ptr());
    // SAFETY: the views cover rows*stride elements with unit column stride, so every
    // (i, p), (p, j), (i, j) offset used below lies inside its view.
    unsafe {
        let mut j0 = 0;
        #[cfg(target_arch = "x86_64")]
        if simd_ok() {
            while j0 + 16 <= n {
                simd::panel::<2, false>(m, k, pa, lda, pb.add(j0), ldb, pc.add(j0), ldc, 16);
                j0 += 16;
            }
            // Then 8 columns, and the last 1-7 (the pose heads have 4, 3 and
            // 1) through a lane mask: the scalar loop below was 4 % of the
            // estimator's CPU time on the heads alone.
            while j0 + 8 <= n {
                simd::panel::<1, false>(m, k, pa, lda, pb.add(j0), ldb, pc.add(j0), ldc, 8);
                j0 += 8;
            }
            if j0 < n {
                simd::panel::<1, true>(m, k, pa, lda, pb.add(j0), ldb, pc.add(j0), ldc, n - j0);
                j0 = n;
            }
        }
        if j0 < n {
            for i in 0..m {
                for p in 0..k {
                    let av = *pa.add(i * lda + p);
                    let brow = pb.add(p * ldb);
                    let crow = pc.add(i * ldc);
                    for j in j0..n {
                        *crow.add(j) += av * *brow.add(j);
                    }
                }
            }
        }
    }
}

#[cfg(target_arch = "x86_64")]
mod simd {
    use std::arch::x86_64::*;

    /// Rows of the inner dimension per block, so a 16-column block of B
    /// (256 × 16 × 4 B = 16 KB) stays in L1 while every row tile passes over it.
    const KC: usize = 256;

    /// Rows of A from which a K block of B is packed first (two 6-row tiles and more).
    const PACK_MIN_ROWS: usize = 12;

    /// All rows of a `W*8`-column panel: for each K block, 6-row tiles, then
    /// the remainder. `MASKED` (with `W = 1`): the panel is the last `cols`
    /// (1-7) columns, B and C read and written through a lane mask, so no
    /// element past column `cols` is touched.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn panel<const W: usize, const MASKED: bool>(
        m: usize,
        k: usize,
        a: *const f32,
        lda: usize,
        b: *const f32,
        ldb: usize,
        c: *mut f32,
        ldc: usize,
        cols: usize,
    ) {
        debug_assert!(if MASKED { W == 1 && (1..8).contains(&cols) } else { cols == W * 8 });
        let lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
        let mask = _mm256_cmpgt_epi32(_mm256_set1_epi32(cols as i32), lanes);
        // The K block of B, copied into consecutive rows when enough row
        // tiles reuse it: B's own rows are often a multiple of 1 KiB apart
        // (weights of 256 or 512 outputs), so its 256 lines fell into a few
        // L1 sets and evicted each other between tiles (256×256×512 ran at
        // 67 GFLOP/s, 256×384×256 at 91).
        let pack = !MASKED && m >= PACK_MIN_ROWS;
        let mut packed = std::mem::MaybeUninit::<[f32; KC * 16]>::uninit();
        let packed = packed.as_mut_ptr().cast::<f32>();
        unsafe {
            let mut k0 = 0;
            while k0 < k {
                let kc = KC.min(k - k0);
                let (a, mut b) = (a.add(k0), b.add(k0 * ldb));
                let mut ldb = ldb;
                if pack {
                    for p in 0..kc {
                        std::ptr::copy_nonoverlapping(b.add(p * ldb), packed.add(p * W * 8), W * 8);
                    }
                    (b, ldb) = (packed.cast_const(), W * 8);
                }
                let mut i = 0;
                while i + 6 <= m {
                    tile::<6, W, MASKED>(kc, a.add(i * lda), lda, b, ldb, c.add(i * ldc), ldc, mask);
                    i += 6;
                }
                let (ar, cr) = (a.add(i * lda), c.add(i * ldc));
                match m - i {
                    5 => tile::<5, W, MASKED>(kc, ar, lda, b, ldb, cr, ldc, mask),
                    4 => tile::<4, W, MASKED>(kc, ar, lda, b, ldb, cr, ldc, mask),
                    3 => tile::<3, W, MASKED>(kc, ar, lda, b, ldb, cr, ldc, mask),
                    2 => tile::<2, W, MASKED>(kc, ar, lda, b, ldb, cr, ldc, mask),
                    1 => tile::<1, W, MASKED>(kc, ar, lda, b, ldb, cr, ldc, mask),
                    _ => {}
                }
                k0 += kc;
            }
        }
    }

    /// `C[R, W*8] += A[R, k] · B[k, W*8]`, accumulators in registers.
    #[allow(clippy::too_many_arguments)]
    #[target_feature(enable = "avx2,fma")]
    #[inline]
    unsafe fn tile<const R: usize, const W: usize, const MASKED: bool>(
        k: usize,
        a: *const f32,
        lda: usize,
        b: *const f32,
        ldb: usize,
        c: *mut f32,
        ldc: usize,
        mask: __m256i,
    ) {
        unsafe {
            let mut acc = [[_mm256_setzero_ps(); W]; R];
            for p in 0..k {
                let brow = b.add(p * ldb);
                let mut bv = [_mm256_setzero_ps(); W];
                for (w, v) in bv.iter_mut().enumerate() {
                    *v = if MASKED { _mm256_maskload_ps(brow, mask) } else { _mm256_loadu_ps(brow.add(8 * w)) };
                }
                for (r, accr) in acc.iter_mut().enumerate() {
                    let av = _mm256_broadcast_ss(&*a.add(r * lda + p));
                    for w in 0..W {
                        accr[w] = _mm256_fmadd_ps(av, bv[w], accr[w]);
                    }
                }
            }
            for (r, accr) in acc.iter().enumerate() {
                let crow = c.add(r * ldc);
                for (w, v) in accr.iter().enumerate() {
                    let p = crow.add(8 * w);
                    if MASKED {
                        _mm256_maskstore_ps(p, mask, _mm256_add_ps(_mm256_maskload_ps(p, mask), *v));
                    } else {
                        _mm256_storeu_ps(p, _mm256_add_ps(_mm256_loadu_ps(p), *v));
                    }
                }
            }
        }
    }
}

/// `out[r, :] = relu?(x[r, :] · w + b)` for every row r. Shapes: x `[R, I]`, w `[I, O]`, out `[R, O]`.
pub fn dense(
    x: ArrayView2<f32>,
    w: ArrayView2<f32>,
    b: Option<ArrayView1<f32>>,
    relu: bool,
    mut out: ArrayViewMut2<f32>,
) {
    match b {
        Some(b) => out.rows_mut().into_iter().for_each(|mut r| r.assign(&b)),
        None => out.fill(0.0),
    }
    gemm_acc(x, w, &mut out);
    if relu {
        out.mapv_inplace(|v| v.max(0.0));
    }
}

/// Row stride of the im2col matrix for `hw` output pixels. Rows a multiple
/// of 1 KiB apart fall into the same L1 sets and the GEMM kernel, walking B
/// row by row, evicts its own lines: a 32×864×1024 conv ran at 65 GFLOP/s,
/// the same shape with 1040 columns at 116 (`fusepose-bench estimator`).
pub fn cols_stride(hw: usize) -> usize {
    if hw >= 256 && (hw * 4).is_multiple_of(1024) { hw + 16 } else { hw }
}

/// One im2col row: `dst[ox] = src[ox * stride + kx - 1]`, zero where that
/// falls outside `src` (the padding). The interior is a plain copy at stride 1
/// and a branch-free gather at stride 2; this loop was an eighth of the
/// estimator's CPU time when it tested the bounds per element.
fn im2col_row(src: &[f32], stride: usize, kx: usize, dst: &mut [f32]) {
    let wo = dst.len();
    // Valid outputs: ox * stride + kx >= 1 and ox * stride + kx - 1 < src.len().
    let lo = usize::from(kx == 0).min(wo);
    let hi = (src.len() + 1 - kx).div_ceil(stride).clamp(lo, wo);
    dst[..lo].fill(0.0);
    dst[hi..].fill(0.0);
    if hi == lo {
        return;
    }
    let start = lo * stride + kx - 1;
    let dst = &mut dst[lo..hi];
    if stride == 1 {
        dst.copy_from_slice(&src[start..start + dst.len()]);
    } else {
        for (d, s) in dst.iter_mut().zip(src[start..].iter().step_by(stride)) {
            *d = *s;
        }
    }
}

/// Length of the im2col buffer [`conv3x3`] needs for `c_in` channels and `hw` output pixels.
pub fn cols_len(c_in: usize, hw: usize) -> usize {
    c_in * 9 * cols_stride(hw)
}

/// A 3x3 convolution with padding 1 and the given stride, channel-major.
///
/// `input`: `[C_in, H, W]` flattened; `w`: `[C_out, C_in*9]` (PyTorch `[O, I, 3, 3]` flattened);
/// `cols`: scratch of at least `C_in*9*Ho*Wo`; `out`: `[C_out, Ho*Wo]`. Bias and ReLU fused.
#[allow(clippy::too_many_arguments)] // the shapes of a preallocated conv call: input, weights, output, dims
pub fn conv3x3(
    input: &[f32],
    c_in: usize,
    h: usize,
    w_in: usize,
    stride: usize,
    weight: ArrayView2<f32>,
    bias: ArrayView1<f32>,
    cols: &mut [f32],
    mut out: ArrayViewMut2<f32>,
) {
    let ho = (h + 2 - 3) / stride + 1;
    let wo = (w_in + 2 - 3) / stride + 1;
    let hw = ho * wo;
    let hs = cols_stride(hw);
    let cols = &mut cols[..cols_len(c_in, hw)];
    for c in 0..c_in {
        let plane = &input[c * h * w_in..(c + 1) * h * w_in];
        for ky in 0..3 {
            for kx in 0..3 {
                let r0 = ((c * 9) + ky * 3 + kx) * hs;
                let row = &mut cols[r0..r0 + hw];
                for oy in 0..ho {
                    let iy = (oy * stride + ky) as isize - 1;
                    let dst = &mut row[oy * wo..(oy + 1) * wo];
                    if iy < 0 || iy >= h as isize {
                        dst.fill(0.0);
                        continue;
                    }
                    let src = &plane[iy as usize * w_in..(iy as usize + 1) * w_in];
                    im2col_row(src, stride, kx, dst);
                }
            }
        }
    }
    let cols = ArrayView2::from_shape((c_in * 9, hw).strides((hs, 1)), cols).expect("cols shape");
    for (mut r, &bv) in out.axis_iter_mut(Axis(0)).zip(bias.iter()) {
        r.fill(bv);
    }
    gemm_acc(weight, cols, &mut out);
    out.mapv_inplace(|v| v.max(0.0));
}

#[cfg(test)]
mod tests {
    use super::*;
    use ndarray::{Array1, Array2, s};

    #[test]
    fn dense_adds_bias_and_clamps() {
        let x = Array2::from_shape_vec((2, 2), vec![1.0, 2.0, -1.0, 0.0]).unwrap();
        let w = Array2::from_shape_vec((2, 1), vec![1.0, 1.0]).unwrap();
        let b = Array1::from_vec(vec![0.5]);
        let mut out = Array2::zeros((2, 1));
        dense(x.view(), w.view(), Some(b.view()), true, out.view_mut());
        assert_eq!(out.as_slice().unwrap(), &[3.5, 0.0]);
    }

    #[test]
    fn gemm_matches_naive_for_odd_shapes_and_strided_views() {
        // Column tails of 1-7 (masked), k past one 256-row block, every row remainder.
        let shapes = [
            (1, 1, 1),
            (7, 5, 3),
            (13, 27, 40),
            (6, 64, 16),
            (257, 33, 25),
            (5, 9, 8),
            (11, 300, 7),
            (14, 300, 23),
            (4, 3, 20),
        ];
        for &(m, k, n) in &shapes {
            let a = Array2::from_shape_fn((m, k + 3), |(i, j)| ((i * 31 + j * 7) % 13) as f32 * 0.1 - 0.6);
            let b = Array2::from_shape_fn((k, n + 4), |(i, j)| ((i * 11 + j * 5) % 17) as f32 * 0.05 - 0.4);
            let av = a.slice(s![.., 1..k + 1]);
            // B's view ends 2 columns short of its rows and C's 4 short: a
            // masked tail must neither read nor write past its columns.
            let bv = b.slice(s![.., 2..n + 2]);
            let mut c = Array2::from_elem((m, n + 8), 1.0f32);
            let mut cv = c.slice_mut(s![.., 4..n + 4]);
            gemm_acc(av, bv, &mut cv);
            let expect = av.dot(&bv);
            for i in 0..m {
                for j in 0..n {
                    assert!((c[[i, j + 4]] - 1.0 - expect[[i, j]]).abs() < 1e-4, "{m}x{k}x{n} at {i},{j}");
                }
                for j in (0..4).chain(n + 4..n + 8) {
                    assert_eq!(c[[i, j]], 1.0, "untouched columns");
                }
            }
        }
    }

    #[test]
    fn conv_matches_direct_sum() {
        // 16×16 at stride 1 has a padded im2col row stride (`cols_stride`).
        for (c_in, h, wd) in [(2, 5, 4), (2, 16, 16), (1, 1, 1), (1, 2, 3), (3, 7, 5), (1, 4, 2), (2, 3, 1)] {
            conv_case(c_in, h, wd);
        }
    }

    fn conv_case(c_in: usize, h: usize, wd: usize) {
        let input: Vec<f32> = (0..c_in * h * wd).map(|i| ((i * 7) % 11) as f32 - 5.0).collect();
        let weight = Array2::from_shape_fn((3, c_in * 9), |(o, k)| ((o * 13 + k * 5) % 7) as f32 * 0.1 - 0.3);
        let bias = Array1::from_vec(vec![0.1, -0.2, 0.3]);
        for stride in [1usize, 2] {
            let ho = (h - 1) / stride + 1;
            let wo = (wd - 1) / stride + 1;
            let mut cols = vec![0.0; cols_len(c_in, ho * wo)];
            let mut out = Array2::zeros((3, ho * wo));
            conv3x3(&input, c_in, h, wd, stride, weight.view(), bias.view(), &mut cols, out.view_mut());
            for o in 0..3 {
                for oy in 0..ho {
                    for ox in 0..wo {
                        let mut s = bias[o];
                        for c in 0..c_in {
                            for ky in 0..3 {
                                for kx in 0..3 {
                                    let iy = (oy * stride + ky) as isize - 1;
                                    let ix = (ox * stride + kx) as isize - 1;
                                    if iy >= 0 && ix >= 0 && (iy as usize) < h && (ix as usize) < wd {
                                        s += weight[[o, c * 9 + ky * 3 + kx]]
                                            * input[c * h * wd + iy as usize * wd + ix as usize];
                                    }
                                }
                            }
                        }
                        assert!((out[[o, oy * wo + ox]] - s.max(0.0)).abs() < 1e-4);
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod speed {
    use super::*;
    use ndarray::Array2;

    /// `cargo test --release -p fusepose-estimator gemm_speed -- --ignored --nocapture`
    #[test]
    #[ignore]
    fn gemm_speed() {
        for &(m, k, n) in
            &[(256, 256, 512), (256, 384, 256), (256, 64, 128), (32, 864, 1040), (256, 3, 64), (256, 128, 4)]
        {
            let a = Array2::from_shape_fn((m, k), |(i, j)| ((i + j) % 7) as f32 * 0.1);
            let b = Array2::from_shape_fn((k, n), |(i, j)| ((i * j) % 5) as f32 * 0.1);
            let mut c = Array2::zeros((m, n));
            let reps = 400;
            let t = std::time::Instant::now();
            for _ in 0..reps {
                gemm_acc(a.view(), b.view(), &mut c.view_mut());
            }
            let s = t.elapsed().as_secs_f64() / reps as f64;
            println!("{m}x{k}x{n}: {:.3} ms, {:.1} GFLOP/s", s * 1e3, 2.0 * (m * k * n) as f64 / s / 1e9);
        }
        // The colour branch's convolutions (crop 64): e1, e2, d1.
        for &(c_in, hw_in, stride, c_out) in &[(3, 64, 1, 16), (16, 64, 2, 32), (96, 32, 1, 32)] {
            let input: Vec<f32> = (0..c_in * hw_in * hw_in).map(|i| (i % 13) as f32 * 0.1).collect();
            let weight = Array2::from_shape_fn((c_out, c_in * 9), |(i, j)| ((i + j) % 7) as f32 * 0.01);
            let bias = ndarray::Array1::zeros(c_out);
            let ho = (hw_in - 1) / stride + 1;
            let mut cols = vec![0.0; cols_len(c_in, ho * ho)];
            let mut out = Array2::zeros((c_out, ho * ho));
            let reps = 400;
            let t = std::time::Instant::now();
            for _ in 0..reps {
                conv3x3(&input, c_in, hw_in, hw_in, stride, weight.view(), bias.view(), &mut cols, out.view_mut());
            }
            let s = t.elapsed().as_secs_f64() / reps as f64;
            let flops = 2.0 * (c_out * c_in * 9 * ho * ho) as f64;
            println!(
                "conv {c_in}x{hw_in}x{hw_in}/{stride} -> {c_out}: {:.3} ms, {:.1} GFLOP/s",
                s * 1e3,
                flops / s / 1e9
            );
        }
    }
}
