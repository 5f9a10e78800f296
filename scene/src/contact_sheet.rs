//! Contact sheets: a PNG grid with one row per frame showing RGB, depth
//! colour-mapped with turbo (black = missing) beside its metre scale, and the
//! label map in distinct colours (black = background).

use crate::render::RenderTarget;
use image::{Rgb, RgbImage};
use std::path::Path;

/// A borrowed frame: row-major planes of `width * height` pixels.
#[derive(Clone, Copy, Debug)]
pub struct FrameView<'a> {
    pub width: u32,
    pub height: u32,
    /// RGB8, 3 bytes per pixel.
    pub rgb: &'a [u8],
    /// Depth in metres, 0 = missing.
    pub depth_m: &'a [f32],
    /// Label map, 0 = background.
    pub labels: &'a [u16],
}

impl<'a> From<&'a RenderTarget> for FrameView<'a> {
    fn from(t: &'a RenderTarget) -> Self {
        FrameView { width: t.width(), height: t.height(), rgb: t.rgb(), depth_m: t.depth_m(), labels: t.labels() }
    }
}

/// Why a contact sheet could not be built or written.
#[derive(Debug, thiserror::Error)]
pub enum SheetError {
    #[error("frame planes do not match {width}x{height}: rgb {rgb} bytes, depth {depth}, labels {labels}")]
    PlaneSize { width: u32, height: u32, rgb: usize, depth: usize, labels: usize },
    #[error("empty frame or zero thumbnail width")]
    Empty,
    #[error("no frames to write")]
    NoFrames,
    #[error("writing the PNG: {0}")]
    Write(#[from] image::ImageError),
}

const PAD: u32 = 4;
const BAR_W: u32 = 10;
const GLYPH_SCALE: u32 = 2;
/// Room for the scale's bar and a label such as "12.34m".
const SCALE_W: u32 = BAR_W + 4 + 6 * 4 * GLYPH_SCALE;

/// Collects frame thumbnails and writes them as one PNG grid.
#[derive(Clone, Debug)]
pub struct ContactSheet {
    thumb_width: u32,
    depth_range_m: Option<(f32, f32)>,
    rows: Vec<Row>,
}

#[derive(Clone, Debug)]
struct Row {
    rgb: RgbImage,
    depth: RgbImage,
    labels: RgbImage,
    range: (f32, f32),
}

impl ContactSheet {
    /// A sheet whose thumbnails are `thumb_width` pixels wide (height keeps the aspect).
    pub fn new(thumb_width: u32) -> ContactSheet {
        ContactSheet { thumb_width, depth_range_m: None, rows: Vec::new() }
    }

    /// Colour-map depth over a fixed range (metres) instead of each frame's min..max.
    pub fn with_depth_range(mut self, min_m: f32, max_m: f32) -> ContactSheet {
        self.depth_range_m = Some((min_m, max_m.max(min_m + 1e-3)));
        self
    }

    pub fn len(&self) -> usize {
        self.rows.len()
    }

    pub fn is_empty(&self) -> bool {
        self.rows.is_empty()
    }

    /// Adds one frame as a row (RGB, depth, labels).
    pub fn push(&mut self, f: FrameView<'_>) -> Result<(), SheetError> {
        let n = f.width as usize * f.height as usize;
        if f.rgb.len() != n * 3 || f.depth_m.len() != n || f.labels.len() != n {
            return Err(SheetError::PlaneSize {
                width: f.width,
                height: f.height,
                rgb: f.rgb.len(),
                depth: f.depth_m.len(),
                labels: f.labels.len(),
            });
        }
        if n == 0 || self.thumb_width == 0 {
            return Err(SheetError::Empty);
        }
        let range = self.depth_range_m.unwrap_or_else(|| {
            let (lo, hi) = f
                .depth_m
                .iter()
                .filter(|z| **z > 0.0 && z.is_finite())
                .fold((f32::INFINITY, 0.0f32), |(lo, hi), &z| (lo.min(z), hi.max(z)));
            if lo.is_finite() { (lo, hi.max(lo + 1e-3)) } else { (0.0, 1.0) }
        });
        let tw = self.thumb_width;
        let th = ((f.height as u64 * tw as u64) / f.width as u64).max(1) as u32;
        let thumb = |colour: &dyn Fn(usize) -> [u8; 3]| {
            RgbImage::from_fn(tw, th, |x, y| {
                let sx = (x as u64 * f.width as u64 / tw as u64) as usize;
                let sy = (y as u64 * f.height as u64 / th as u64) as usize;
                Rgb(colour(sy * f.width as usize + sx))
            })
        };
        let rgb = thumb(&|i| [f.rgb[i * 3], f.rgb[i * 3 + 1], f.rgb[i * 3 + 2]]);
        let depth = thumb(&|i| {
            let z = f.depth_m[i];
            if z > 0.0 && z.is_finite() { turbo((z - range.0) / (range.1 - range.0)) } else { [0, 0, 0] }
        });
        let labels = thumb(&|i| label_colour(f.labels[i]));
        self.rows.push(Row { rgb, depth, labels, range });
        Ok(())
    }

    /// The sheet as an image (columns: RGB, depth, depth scale, labels).
    pub fn to_image(&self) -> Result<RgbImage, SheetError> {
        let first = self.rows.first().ok_or(SheetError::NoFrames)?;
        let tw = first.rgb.width();
        let th = self.rows.iter().map(|r| r.rgb.height()).max().unwrap_or(1);
        let width = PAD + 3 * (tw + PAD) + SCALE_W + PAD;
        let height = PAD + self.rows.len() as u32 * (th + PAD);
        let mut img = RgbImage::from_pixel(width, height, Rgb([255, 255, 255]));
        for (r, row) in self.rows.iter().enumerate() {
            let y0 = PAD + r as u32 * (th + PAD);
            let mut x = PAD;
            image::imageops::overlay(&mut img, &row.rgb, x as i64, y0 as i64);
            x += tw + PAD;
            image::imageops::overlay(&mut img, &row.depth, x as i64, y0 as i64);
            x += tw + PAD;
            draw_scale(&mut img, x, y0, th, row.range);
            x += SCALE_W + PAD;
            image::imageops::overlay(&mut img, &row.labels, x as i64, y0 as i64);
        }
        Ok(img)
    }

    /// Writes the sheet as a PNG.
    pub fn save_png(&self, path: impl AsRef<Path>) -> Result<(), SheetError> {
        self.to_image()?.save_with_format(path, image::ImageFormat::Png)?;
        Ok(())
    }
}

/// A vertical turbo bar (far at the top) with the range's ends written beside it.
fn draw_scale(img: &mut RgbImage, x0: u32, y0: u32, h: u32, (lo, hi): (f32, f32)) {
    for y in 0..h {
        let t = 1.0 - y as f32 / (h.max(2) - 1) as f32;
        let c = turbo(t);
        for x in 0..BAR_W {
            img.put_pixel(x0 + x, y0 + y, Rgb(c));
        }
    }
    let tx = x0 + BAR_W + 4;
    draw_text(img, tx, y0, &format!("{hi:.2}m"));
    draw_text(img, tx, y0 + h.saturating_sub(5 * GLYPH_SCALE), &format!("{lo:.2}m"));
}

/// 3x5 glyphs for digits, '.', 'm' and '-' (rows top to bottom, 3 bits each).
fn glyph(c: char) -> [u8; 5] {
    match c {
        '0' => [7, 5, 5, 5, 7],
        '1' => [2, 6, 2, 2, 7],
        '2' => [7, 1, 7, 4, 7],
        '3' => [7, 1, 7, 1, 7],
        '4' => [5, 5, 7, 1, 1],
        '5' => [7, 4, 7, 1, 7],
        '6' => [7, 4, 7, 5, 7],
        '7' => [7, 1, 1, 1, 1],
        '8' => [7, 5, 7, 5, 7],
        '9' => [7, 5, 7, 1, 7],
        '.' => [0, 0, 0, 0, 2],
        'm' => [0, 0, 7, 7, 5],
        '-' => [0, 0, 7, 0, 0],
        _ => [0; 5],
    }
}

fn draw_text(img: &mut RgbImage, x0: u32, y0: u32, s: &str) {
    for (i, c) in s.chars().enumerate() {
        let g = glyph(c);
        for (row, bits) in g.iter().enumerate() {
            for col in 0..3 {
                if bits & (4 >> col) == 0 {
                    continue;
                }
                for dy in 0..GLYPH_SCALE {
                    for dx in 0..GLYPH_SCALE {
                        let x = x0 + (i as u32 * 4 + col) * GLYPH_SCALE + dx;
                        let y = y0 + row as u32 * GLYPH_SCALE + dy;
                        if x < img.width() && y < img.height() {
                            img.put_pixel(x, y, Rgb([0, 0, 0]));
                        }
                    }
                }
            }
        }
    }
}

/// Google's turbo colour map (polynomial fit), t in 0..1 (clamped).
pub fn turbo(t: f32) -> [u8; 3] {
    let x = if t.is_finite() { t.clamp(0.0, 1.0) } else { 0.0 };
    let r = 0.135_721_38 + x * (4.615_392_6 + x * (-42.660_324 + x * (132.131_08 + x * (-152.942_4 + x * 59.286_38))));
    let g =
        0.091_402_61 + x * (2.194_188_4 + x * (4.842_966_6 + x * (-14.185_033 + x * (4.277_298_5 + x * 2.829_566))));
    let b = 0.106_673_3 + x * (12.641_946 + x * (-60.582_05 + x * (110.362_77 + x * (-89.903_11 + x * 27.348_25))));
    [r, g, b].map(|c| (c.clamp(0.0, 1.0) * 255.0).round() as u8)
}

/// A distinct, saturated colour per label (golden-ratio hue steps); 0 is black.
pub fn label_colour(label: u16) -> [u8; 3] {
    if label == 0 {
        return [0, 0, 0];
    }
    let h = (label as f32 * 0.618_034).fract() * 6.0;
    let (s, v) = (0.8f32, if label.is_multiple_of(2) { 0.8 } else { 1.0 });
    let c = v * s;
    let x = c * (1.0 - ((h % 2.0) - 1.0).abs());
    let (r, g, b) = match h as u32 {
        0 => (c, x, 0.0),
        1 => (x, c, 0.0),
        2 => (0.0, c, x),
        3 => (0.0, x, c),
        4 => (x, 0.0, c),
        _ => (c, 0.0, x),
    };
    let m = v - c;
    [r + m, g + m, b + m].map(|c| (c * 255.0).round() as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sheet_has_one_row_per_frame_and_round_trips_through_png() {
        let (w, h) = (8u32, 6u32);
        let n = (w * h) as usize;
        let rgb: Vec<u8> = (0..n * 3).map(|i| (i * 5) as u8).collect();
        let depth: Vec<f32> = (0..n).map(|i| if i % 7 == 0 { 0.0 } else { 0.5 + i as f32 * 0.01 }).collect();
        let labels: Vec<u16> = (0..n).map(|i| (i % 4) as u16).collect();
        let frame = FrameView { width: w, height: h, rgb: &rgb, depth_m: &depth, labels: &labels };
        let mut sheet = ContactSheet::new(16);
        assert!(matches!(sheet.to_image(), Err(SheetError::NoFrames)));
        sheet.push(frame).unwrap();
        sheet.push(frame).unwrap();
        let img = sheet.to_image().unwrap();
        assert_eq!(img.height(), PAD + 2 * (12 + PAD));
        assert_eq!(img.width(), PAD + 3 * (16 + PAD) + SCALE_W + PAD);
        // The first RGB thumbnail pixel is the frame's first pixel.
        assert_eq!(img.get_pixel(PAD, PAD).0, [0, 5, 10]);
        // Missing depth is black; label 0 is black, others coloured.
        assert_eq!(img.get_pixel(PAD + 16 + PAD, PAD).0, [0, 0, 0]);
        let path = std::env::temp_dir().join(format!("fusepose_sheet_test_{}.png", std::process::id()));
        sheet.save_png(&path).unwrap();
        let back = image::open(&path).unwrap().to_rgb8();
        std::fs::remove_file(&path).ok();
        assert_eq!(back, img);

        let bad = FrameView { labels: &labels[1..], ..frame };
        assert!(matches!(sheet.push(bad), Err(SheetError::PlaneSize { .. })));
    }

    #[test]
    fn label_colours_are_distinct_and_turbo_spans_blue_to_red() {
        let cols: Vec<[u8; 3]> = (1..=16).map(label_colour).collect();
        for i in 0..cols.len() {
            for j in i + 1..cols.len() {
                let d: i32 = (0..3).map(|c| (cols[i][c] as i32 - cols[j][c] as i32).abs()).sum();
                assert!(d > 30, "labels {} and {} look alike", i + 1, j + 1);
            }
        }
        let (lo, hi) = (turbo(0.15), turbo(0.9));
        assert!(lo[2] > lo[0] && hi[0] > hi[2]);
    }
}
