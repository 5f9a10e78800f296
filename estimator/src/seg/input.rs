//! Between a frame and the segmenter's grids: the network input (box-filtered
//! RGB normalised like the pose net's crops, plus mean valid depth in metres,
//! 0 where a box has none), the nearest upsampling of the per-cell labels back
//! to the frame, and the training target (the frame label at each cell's centre).
//!
//! A [`FrameMap`] holds the index tables for one frame size and one config; it
//! allocates only when built, so per-frame use is allocation-free.

use crate::frame::{ColorFormat, DepthPlane, FrameView};
use crate::sampling::normalise_channel;

use super::config::{INPUT_CHANNELS, SegConfig};

/// `[start, end)` of each of `n` boxes tiling `len` pixels (each at least one pixel).
fn boxes(len: usize, n: usize) -> Vec<(usize, usize)> {
    (0..n)
        .map(|i| {
            let start = (i * len / n).min(len - 1);
            let end = ((i + 1) * len / n).max(start + 1).min(len);
            (start, end)
        })
        .collect()
}

/// Byte offsets of red and blue within a pixel of `format` (green is byte 1).
fn red_blue_bytes(format: ColorFormat) -> (usize, usize) {
    match format {
        ColorFormat::Rgb8 => (0, 2),
        ColorFormat::Bgr8 => (2, 0),
    }
}

/// Writes input cell `i` (of `plane` per channel) from one box's colour sums
/// over its `area` pixels and the sum and count of its valid depths.
fn write_box(out: &mut [f32], plane: usize, i: usize, rgb: [u32; 3], area: usize, zsum: f32, zn: u32) {
    for (c, &sum) in rgb.iter().enumerate() {
        out[c * plane + i] = normalise_channel(sum as f32 / area as f32, c);
    }
    out[3 * plane + i] = if zn > 0 { zsum / zn as f32 } else { 0.0 };
}

/// Pixel `i` of `len` on a grid of `n` cells (cell c's centre at pixel
/// coordinate (c + ½)·len/n): the cells either side and the weight of the
/// second, clamped at the ends.
fn interp(i: usize, len: usize, n: usize) -> (usize, usize, f32) {
    let x = ((i as f64 + 0.5) * n as f64 / len as f64 - 0.5).clamp(0.0, (n - 1) as f64);
    let x0 = x.floor() as usize;
    (x0, (x0 + 1).min(n - 1), (x - x0 as f64) as f32)
}

/// Index tables between a `width` x `height` frame and a config's input and output grids.
#[derive(Clone, Debug)]
pub struct FrameMap {
    width: usize,
    height: usize,
    in_w: usize,
    in_h: usize,
    out_w: usize,
    out_h: usize,
    /// Input-grid boxes along x and y.
    in_x: Vec<(usize, usize)>,
    in_y: Vec<(usize, usize)>,
    /// Output cell of each frame column / row (nearest upsampling).
    up_x: Vec<u32>,
    up_y: Vec<u32>,
    /// Frame column / row sampled for each output cell's training target.
    centre_x: Vec<u32>,
    centre_y: Vec<u32>,
    /// Frame columns / rows `[start, end)` that upsample to each cell (may be empty).
    span_x: Vec<(u32, u32)>,
    span_y: Vec<(u32, u32)>,
    /// Per frame column / row: bilinear cells and weight ([`interp`]).
    interp_x: Vec<(u32, u32, f32)>,
    interp_y: Vec<(u32, u32, f32)>,
}

impl FrameMap {
    /// Tables for frames of `width` x `height` (both >= 1).
    pub fn new(width: usize, height: usize, cfg: &SegConfig) -> Self {
        let (width, height) = (width.max(1), height.max(1));
        let (out_h, out_w) = cfg.output_size();
        let up = |len: usize, n: usize| -> Vec<u32> { (0..len).map(|u| (u * n / len) as u32).collect() };
        let up_x = up(width, out_w);
        let up_y = up(height, out_h);
        // The centre of the frame pixels that upsample to each cell (its box if none do).
        let centre = |map: &[u32], n: usize, len: usize| -> Vec<u32> {
            (0..n)
                .map(|c| {
                    let lo = map.partition_point(|&m| (m as usize) < c);
                    let hi = map.partition_point(|&m| (m as usize) <= c);
                    if hi > lo { ((lo + hi - 1) / 2) as u32 } else { (c * len / n).min(len - 1) as u32 }
                })
                .collect()
        };
        let centre_x = centre(&up_x, out_w, width);
        let centre_y = centre(&up_y, out_h, height);
        let span = |map: &[u32], n: usize| -> Vec<(u32, u32)> {
            (0..n)
                .map(|c| {
                    let lo = map.partition_point(|&m| (m as usize) < c);
                    let hi = map.partition_point(|&m| (m as usize) <= c);
                    (lo as u32, hi as u32)
                })
                .collect()
        };
        let table = |len: usize, n: usize| -> Vec<(u32, u32, f32)> {
            (0..len)
                .map(|i| {
                    let (a, b, f) = interp(i, len, n);
                    (a as u32, b as u32, f)
                })
                .collect()
        };
        let span_x = span(&up_x, out_w);
        let span_y = span(&up_y, out_h);
        Self {
            width,
            height,
            in_w: cfg.input_width,
            in_h: cfg.input_height,
            out_w,
            out_h,
            in_x: boxes(width, cfg.input_width),
            in_y: boxes(height, cfg.input_height),
            up_x,
            up_y,
            centre_x,
            centre_y,
            span_x,
            span_y,
            interp_x: table(width, out_w),
            interp_y: table(height, out_h),
        }
    }

    /// Whether the tables fit this frame size and config.
    pub fn fits(&self, width: usize, height: usize, cfg: &SegConfig) -> bool {
        let (oh, ow) = cfg.output_size();
        self.width == width
            && self.height == height
            && self.in_w == cfg.input_width
            && self.in_h == cfg.input_height
            && self.out_w == ow
            && self.out_h == oh
    }

    /// Length of the network input, `4 * input_height * input_width`.
    pub fn input_len(&self) -> usize {
        INPUT_CHANNELS * self.in_w * self.in_h
    }

    /// Number of output cells, `out_height * out_width`.
    pub fn cells(&self) -> usize {
        self.out_w * self.out_h
    }

    /// Writes the network input `[4, in_h, in_w]` (channel-major) for `frame`,
    /// which must be valid and of this map's size (checked by the caller).
    pub fn fill_input(&self, frame: &FrameView<'_>, out: &mut [f32]) {
        let pixels = self.width * self.height;
        let tiled = self.width >= self.in_w && self.height >= self.in_h;
        if !tiled || frame.color.len() < 3 * pixels || frame.depth.len() < pixels {
            return self.fill_input_per_box(frame, out);
        }
        match frame.depth {
            DepthPlane::U16 { data, scale } => self.fill_input_rows(frame, out, |p| data[p] as f32 * scale),
            DepthPlane::F32(data) => self.fill_input_rows(frame, out, |p| data[p]),
        }
    }

    /// [`FrameMap::fill_input`] where the boxes tile the frame: row by row
    /// over the frame, a band of boxes at a time, so that reads run along
    /// memory and the boxes' sums are independent chains. Each box still sums
    /// its pixels row by row, left to right, as [`FrameMap::fill_input_per_box`]
    /// does, so the input is the same to the bit. `raw_depth(p)`: the depth
    /// value in metres before the validity test of `DepthPlane::metres`.
    fn fill_input_rows(&self, frame: &FrameView<'_>, out: &mut [f32], raw_depth: impl Fn(usize) -> f32) {
        const BAND: usize = 256;
        let plane = self.in_w * self.in_h;
        let (rc, bc) = red_blue_bytes(frame.color_format);
        let w = self.width;
        for (iy, &(y0, y1)) in self.in_y.iter().enumerate() {
            for (band, boxes) in self.in_x.chunks(BAND).enumerate() {
                let mut rgb = [[0u32; 3]; BAND];
                let mut zsum = [0.0f32; BAND];
                let mut zn = [0u32; BAND];
                for v in y0..y1 {
                    let row = v * w;
                    for (b, &(x0, x1)) in boxes.iter().enumerate() {
                        // In registers for the box's row (the arrays would make every add a store and a load).
                        let ([mut s0, mut s1, mut s2], mut zs, mut n) = (rgb[b], zsum[b], zn[b]);
                        for (u, px) in (x0..x1).zip(frame.color[3 * (row + x0)..3 * (row + x1)].chunks_exact(3)) {
                            s0 += px[rc] as u32;
                            s1 += px[1] as u32;
                            s2 += px[bc] as u32;
                            let z = raw_depth(row + u);
                            // Adding +0.0 for a missing reading leaves the sum's bits as
                            // they are (the sum is never -0.0), and needs no branch.
                            let valid = z.is_finite() && z > 0.0;
                            zs += if valid { z } else { 0.0 };
                            n += valid as u32;
                        }
                        (rgb[b], zsum[b], zn[b]) = ([s0, s1, s2], zs, n);
                    }
                }
                for (b, &(x0, x1)) in boxes.iter().enumerate() {
                    let area = (y1 - y0) * (x1 - x0);
                    write_box(out, plane, iy * self.in_w + band * BAND + b, rgb[b], area, zsum[b], zn[b]);
                }
            }
        }
    }

    /// [`FrameMap::fill_input`] box by box, pixel by pixel; for frames smaller
    /// than the input grid (boxes overlap) and planes shorter than the frame.
    fn fill_input_per_box(&self, frame: &FrameView<'_>, out: &mut [f32]) {
        let plane = self.in_w * self.in_h;
        let (rc, bc) = red_blue_bytes(frame.color_format);
        let w = self.width;
        for (iy, &(y0, y1)) in self.in_y.iter().enumerate() {
            for (ix, &(x0, x1)) in self.in_x.iter().enumerate() {
                let mut sum = [0u32; 3];
                let mut zsum = 0.0f32;
                let mut zn = 0u32;
                for v in y0..y1 {
                    let row = v * w;
                    for u in x0..x1 {
                        let p = row + u;
                        if let Some(px) = frame.color.get(3 * p..3 * p + 3) {
                            sum[0] += px[rc] as u32;
                            sum[1] += px[1] as u32;
                            sum[2] += px[bc] as u32;
                        }
                        if let Some(z) = frame.depth.metres(p) {
                            zsum += z;
                            zn += 1;
                        }
                    }
                }
                write_box(out, plane, iy * self.in_w + ix, sum, (y1 - y0) * (x1 - x0), zsum, zn);
            }
        }
    }

    /// `(out_w, out_h)`: the output grid in cells.
    pub fn grid_size(&self) -> (usize, usize) {
        (self.out_w, self.out_h)
    }

    /// `(width, height)` of the frame in pixels.
    pub fn frame_size(&self) -> (usize, usize) {
        (self.width, self.height)
    }

    /// Frame columns `[start, end)` of cell column `cx` (empty when the frame is narrower than the grid).
    pub fn span_x(&self, cx: usize) -> std::ops::Range<usize> {
        let (a, b) = self.span_x[cx];
        a as usize..b as usize
    }

    /// Frame rows `[start, end)` of cell row `cy`.
    pub fn span_y(&self, cy: usize) -> std::ops::Range<usize> {
        let (a, b) = self.span_y[cy];
        a as usize..b as usize
    }

    /// Bilinear interpolation between cell centres for frame column `u`:
    /// the cell columns left and right of the pixel centre and the weight of the right one.
    pub fn interp_x(&self, u: usize) -> (usize, usize, f32) {
        let (a, b, f) = self.interp_x[u];
        (a as usize, b as usize, f)
    }

    /// As [`FrameMap::interp_x`] for frame row `v`.
    pub fn interp_y(&self, v: usize) -> (usize, usize, f32) {
        let (a, b, f) = self.interp_y[v];
        (a as usize, b as usize, f)
    }

    /// The output cell `(cx, cy)` that frame pixel `(u, v)` upsamples from.
    #[inline]
    pub fn cell_of(&self, u: usize, v: usize) -> (usize, usize) {
        (self.up_x[u] as usize, self.up_y[v] as usize)
    }

    /// Nearest upsampling of per-cell labels `[out_h * out_w]` to the frame (`labels_out`: width * height).
    pub fn upsample(&self, cells: &[u16], labels_out: &mut [u16]) {
        for (v, row) in labels_out.chunks_exact_mut(self.width).enumerate().take(self.height) {
            let crow = &cells[self.up_y[v] as usize * self.out_w..][..self.out_w];
            for (l, &cx) in row.iter_mut().zip(&self.up_x) {
                *l = crow[cx as usize];
            }
        }
    }

    /// The centre pixel `(u, v)` of the frame pixels that upsample to cell `(cx, cy)`.
    #[inline]
    pub fn centre(&self, cx: usize, cy: usize) -> (usize, usize) {
        (self.centre_x[cx] as usize, self.centre_y[cy] as usize)
    }

    /// The training target: the frame label (`label_at(pixel index)`) at each
    /// output cell's centre pixel, into `out` (`out_h * out_w`).
    pub fn target(&self, label_at: impl Fn(usize) -> u16, out: &mut [u16]) {
        for cy in 0..self.out_h {
            for cx in 0..self.out_w {
                let (u, v) = self.centre(cx, cy);
                out[cy * self.out_w + cx] = label_at(v * self.width + u);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::{DepthPlane, LabelPlane};
    use fusepose_scene::Intrinsics;

    fn k(w: u32, h: u32) -> Intrinsics {
        Intrinsics { fx: 500.0, fy: 500.0, cx: w as f64 / 2.0, cy: h as f64 / 2.0, width: w, height: h }
    }

    #[test]
    fn boxes_tile_the_frame() {
        for (len, n) in [(640, 160), (641, 160), (100, 160), (480, 120)] {
            let b = boxes(len, n);
            assert_eq!(b.len(), n);
            assert!(b.iter().all(|&(s, e)| s < e && e <= len));
            if len >= n {
                assert_eq!(b[0].0, 0);
                assert_eq!(b[n - 1].1, len);
                assert!(b.windows(2).all(|w| w[0].1 == w[1].0));
            }
        }
    }

    #[test]
    fn input_averages_boxes_and_ignores_missing_depth() {
        let cfg = SegConfig::new(2);
        let (w, h) = (640usize, 480usize);
        let mut color = vec![0u8; w * h * 3];
        let mut depth = vec![0u16; w * h];
        // Input cell (0, 0) covers pixels 0..4 x 0..4: red 100, half the depth valid at 1 m and 2 m.
        for v in 0..4 {
            for u in 0..4 {
                let p = v * w + u;
                color[3 * p] = 100;
                color[3 * p + 2] = 7;
                depth[p] = if u < 2 {
                    10_000
                } else if v < 2 {
                    20_000
                } else {
                    0
                };
            }
        }
        let frame = FrameView {
            intrinsics: k(w as u32, h as u32),
            color_format: ColorFormat::Bgr8,
            color: &color,
            depth: DepthPlane::U16 { data: &depth, scale: 1e-4 },
            labels: None,
        };
        let map = FrameMap::new(w, h, &cfg);
        let mut input = vec![f32::NAN; map.input_len()];
        map.fill_input(&frame, &mut input);
        let plane = 160 * 120;
        // Bgr8: byte 0 is blue.
        assert!((input[2 * plane] - normalise_channel(100.0, 2)).abs() < 1e-6);
        assert!((input[0] - normalise_channel(7.0, 0)).abs() < 1e-6);
        assert!((input[3 * plane] - (4.0 * 1.0 + 2.0 * 2.0) / 6.0).abs() < 1e-6);
        assert_eq!(input[3 * plane + 1], 0.0);
        assert!(input.iter().all(|v| v.is_finite()));
    }

    /// The row-wise input equals the box-by-box one to the bit, for both
    /// depth formats (with zeros, NaN, infinities and negatives in f32),
    /// both colour orders and frame sizes that do not divide the grid.
    #[test]
    fn rowwise_input_is_the_per_box_input_to_the_bit() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_pcg::Pcg64::seed_from_u64(5);
        let cfg = SegConfig::new(2);
        for (w, h) in [(640usize, 480usize), (641, 479), (1280, 720), (163, 121)] {
            let map = FrameMap::new(w, h, &cfg);
            let color: Vec<u8> = (0..w * h * 3).map(|_| rng.random()).collect();
            let d16: Vec<u16> = (0..w * h).map(|_| if rng.random_bool(0.2) { 0 } else { rng.random() }).collect();
            let d32: Vec<f32> = (0..w * h)
                .map(|_| match rng.random_range(0..10) {
                    0 => 0.0,
                    1 => f32::NAN,
                    2 => f32::INFINITY,
                    3 => -0.5,
                    _ => rng.random_range(0.2f32..3.0),
                })
                .collect();
            for depth in [DepthPlane::U16 { data: &d16, scale: 1e-4 }, DepthPlane::F32(&d32)] {
                for color_format in [ColorFormat::Rgb8, ColorFormat::Bgr8] {
                    let frame = FrameView {
                        intrinsics: k(w as u32, h as u32),
                        color_format,
                        color: &color,
                        depth,
                        labels: None,
                    };
                    let (mut fast, mut slow) = (vec![f32::NAN; map.input_len()], vec![f32::NAN; map.input_len()]);
                    map.fill_input(&frame, &mut fast);
                    map.fill_input_per_box(&frame, &mut slow);
                    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                    assert_eq!(bits(&fast), bits(&slow), "{w}x{h} {color_format:?}");
                }
            }
        }
    }

    /// `cargo test --release -p fusepose-estimator fill_input_speed -- --ignored --nocapture`:
    /// the row-wise input against the box-by-box one on a 640x480 frame, alternated, best of 7 × 50.
    #[test]
    #[ignore = "timing; prints numbers"]
    fn fill_input_speed() {
        let cfg = SegConfig::new(8);
        let (w, h) = (640usize, 480usize);
        let map = FrameMap::new(w, h, &cfg);
        let color: Vec<u8> = (0..w * h * 3).map(|i| (i * 7 % 251) as u8).collect();
        // A tenth of the depth missing, in runs (as at edges and shadows).
        let depth: Vec<u16> =
            (0..w * h).map(|p| if (p / 37) % 10 == 0 { 0 } else { 5000 + (p % 3000) as u16 }).collect();
        let frame = FrameView {
            intrinsics: k(w as u32, h as u32),
            color_format: ColorFormat::Rgb8,
            color: &color,
            depth: DepthPlane::U16 { data: &depth, scale: 1e-4 },
            labels: None,
        };
        let mut out = vec![0.0f32; map.input_len()];
        let (mut rows, mut boxes) = (f64::MAX, f64::MAX);
        for _ in 0..7 {
            let t = std::time::Instant::now();
            (0..50).for_each(|_| map.fill_input(&frame, &mut out));
            rows = rows.min(t.elapsed().as_secs_f64() * 1e3 / 50.0);
            let t = std::time::Instant::now();
            (0..50).for_each(|_| map.fill_input_per_box(&frame, &mut out));
            boxes = boxes.min(t.elapsed().as_secs_f64() * 1e3 / 50.0);
        }
        println!("fill_input 640x480: row-wise {rows:.3} ms, box by box {boxes:.3} ms");
    }

    #[test]
    fn upsample_and_target_are_consistent() {
        let cfg = SegConfig::new(3);
        let (w, h) = (333usize, 250usize);
        let map = FrameMap::new(w, h, &cfg);
        let cells: Vec<u16> = (0..map.cells()).map(|i| (i % 4) as u16).collect();
        let mut full = vec![0u16; w * h];
        map.upsample(&cells, &mut full);
        // Sampling the upsampled plane at the cell centres gives the cells back.
        let plane = LabelPlane::U16(&full);
        let mut back = vec![9u16; map.cells()];
        map.target(|i| plane.class_at(i), &mut back);
        assert_eq!(back, cells);
    }
}
