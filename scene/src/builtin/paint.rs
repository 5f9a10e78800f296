//! A tiny procedural painter for the built-in objects' textures. Everything is
//! addressed in texture (UV) coordinates: u right, v up (v = 1 is the top row,
//! as in [`crate::model::Texture`]).

use rand::Rng;
use rand_pcg::Pcg64;

use crate::model::Texture;

pub(crate) type Rgb = [u8; 3];

/// A rectangle of the texture in UV coordinates: `[u0, v0, u1, v1]`, u0 < u1, v0 < v1.
pub(crate) type UvRect = [f64; 4];

pub(crate) struct Canvas {
    width: u32,
    height: u32,
    rgb: Vec<u8>,
}

impl Canvas {
    pub(crate) fn new(width: u32, height: u32, fill: Rgb) -> Self {
        let rgb = fill.iter().copied().cycle().take(width as usize * height as usize * 3).collect();
        Canvas { width, height, rgb }
    }

    /// Calls `paint(s, t)` for every pixel centre inside `rect`, where `(s, t)`
    /// are the pixel's coordinates local to the rect (0..1, t up); a returned
    /// colour replaces the pixel.
    pub(crate) fn paint(&mut self, rect: UvRect, mut paint: impl FnMut(f64, f64) -> Option<Rgb>) {
        let (w, h) = (self.width as f64, self.height as f64);
        let x0 = (rect[0] * w).floor().max(0.0) as u32;
        let x1 = ((rect[2] * w).ceil() as u32).min(self.width);
        // Row 0 is v = 1.
        let y0 = ((1.0 - rect[3]) * h).floor().max(0.0) as u32;
        let y1 = (((1.0 - rect[1]) * h).ceil() as u32).min(self.height);
        for y in y0..y1 {
            let v = 1.0 - (y as f64 + 0.5) / h;
            let t = (v - rect[1]) / (rect[3] - rect[1]);
            for x in x0..x1 {
                let u = (x as f64 + 0.5) / w;
                let s = (u - rect[0]) / (rect[2] - rect[0]);
                if !(0.0..=1.0).contains(&s) || !(0.0..=1.0).contains(&t) {
                    continue;
                }
                if let Some(c) = paint(s, t) {
                    let i = (y as usize * self.width as usize + x as usize) * 3;
                    self.rgb[i..i + 3].copy_from_slice(&c);
                }
            }
        }
    }

    pub(crate) fn fill(&mut self, rect: UvRect, color: Rgb) {
        self.paint(rect, |_, _| Some(color));
    }

    /// A filled ellipse inside `rect`, centred at local `(cs, ct)` with local radii `(rs, rt)`.
    pub(crate) fn ellipse(&mut self, rect: UvRect, centre: (f64, f64), radii: (f64, f64), color: Rgb) {
        self.paint(rect, |s, t| {
            let (ds, dt) = ((s - centre.0) / radii.0, (t - centre.1) / radii.1);
            (ds * ds + dt * dt <= 1.0).then_some(color)
        });
    }

    /// Rows of text-like marks (short bars with word gaps) filling the local
    /// area `[s0, t0, s1, t1]` of `rect`, `rows` lines high.
    pub(crate) fn text_marks(&mut self, rect: UvRect, area: [f64; 4], rows: usize, color: Rgb, rng: &mut Pcg64) {
        let [s0, t0, s1, t1] = area;
        let line = (t1 - t0) / rows as f64;
        let mut bars: Vec<[f64; 4]> = Vec::new();
        for r in 0..rows {
            let top = t1 - r as f64 * line;
            let bottom = top - 0.6 * line;
            let mut s = s0;
            while s < s1 {
                let word = (s1 - s0) * rng.random_range(0.05..0.2);
                let end = (s + word).min(s1);
                bars.push([s, bottom, end, top]);
                s = end + (s1 - s0) * 0.03;
            }
        }
        self.paint(rect, |s, t| bars.iter().any(|b| s >= b[0] && s <= b[2] && t >= b[1] && t <= b[3]).then_some(color));
    }

    pub(crate) fn into_texture(self) -> Texture {
        Texture { width: self.width, height: self.height, rgb: self.rgb }
    }
}

/// Scales a colour's brightness by `k` (clamped).
pub(crate) fn shade(c: Rgb, k: f64) -> Rgb {
    c.map(|x| (x as f64 * k).clamp(0.0, 255.0) as u8)
}

/// Deterministic value noise in 0..1 from an integer cell index.
pub(crate) fn hash_noise(i: i64) -> f64 {
    let mut x = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 29;
    (x % 10_000) as f64 / 10_000.0
}
