//! Lambert + ambient lighting, sRGB conversion, texture sampling, and the
//! resolve pass that shades each visible pixel once and writes the outputs
//! (RGB, depth, labels, per-item coverage, per-pixel incidence cosine).

use super::raster::{N_ATTR, NO_TEXTURE, ScreenVert};
use super::target::{NO_TRIANGLE, PixelBox, RenderTarget};
use super::{Lighting, RenderItem, RenderSettings, TextureFilter, depth_to_u16};
use crate::Texture;
use std::sync::OnceLock;

/// Rec. 709 luminance of a linear RGB colour.
#[inline]
pub(super) fn luminance(c: [f32; 3]) -> f32 {
    0.2126 * c[0] + 0.7152 * c[1] + 0.0722 * c[2]
}

/// Linear 0..1 → 0..255 byte (clamped).
#[inline]
pub(super) fn unit_to_u8(x: f32) -> u8 {
    (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8
}

/// Lambert + ambient for unit normal `n` (camera frame), seen from side `sign` (±1).
pub(super) fn lambert(l: &Lighting, n: &[f64; 3], sign: f64) -> [f32; 3] {
    let mut s = l.ambient;
    for light in &l.lights {
        let d = light.direction;
        let c = (sign * (n[0] * d.x + n[1] * d.y + n[2] * d.z)).max(0.0) as f32;
        for (sc, lc) in s.iter_mut().zip(light.color) {
            *sc += lc * c;
        }
    }
    s
}

pub(super) fn srgb_decode_table() -> &'static [f32; 256] {
    static T: OnceLock<[f32; 256]> = OnceLock::new();
    T.get_or_init(|| {
        std::array::from_fn(|i| {
            let c = i as f32 / 255.0;
            if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
        })
    })
}

/// Entries of the linear → sRGB table (12-bit input).
pub(super) const ENCODE_STEPS: usize = 4096;

pub(super) fn srgb_encode_table() -> &'static [u8; ENCODE_STEPS] {
    static T: OnceLock<[u8; ENCODE_STEPS]> = OnceLock::new();
    T.get_or_init(|| {
        std::array::from_fn(|i| {
            let l = i as f32 / (ENCODE_STEPS - 1) as f32;
            let c = if l <= 0.003_130_8 { l * 12.92 } else { 1.055 * l.powf(1.0 / 2.4) - 0.055 };
            (c * 255.0).round().clamp(0.0, 255.0) as u8
        })
    })
}

/// sRGB byte → linear 0..1.
#[inline]
pub(super) fn srgb_to_linear(c: u8) -> f32 {
    srgb_decode_table()[c as usize]
}

/// Linear → sRGB byte (clamped to 0..1 first; NaN → 0).
#[inline]
fn linear_to_srgb(table: &[u8; ENCODE_STEPS], l: f32) -> u8 {
    let i = (l.clamp(0.0, 1.0) * (ENCODE_STEPS - 1) as f32 + 0.5) as usize;
    table[i.min(ENCODE_STEPS - 1)]
}

/// Everything the resolve pass needs to shade one triangle's pixels: affine
/// planes (in pixel coordinates, relative to (x0, y0)) of inverse depth and of
/// each attribute divided by depth, so `attr = plane_i / plane_w` is exact.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TriShade {
    pub item: u32,
    pub texture: u32,
    x0: f32,
    y0: f32,
    /// `[d/dx, d/dy, value at (x0, y0)]` of 1/z.
    w_plane: [f32; 3],
    attr_planes: [[f32; 3]; N_ATTR],
    /// Unit geometric normal (camera frame).
    normal: [f32; 3],
}

impl TriShade {
    pub(super) fn new(v: &[ScreenVert; 3], item: u32, texture: u32, normal: [f32; 3]) -> TriShade {
        let (x0, y0) = (v[0].x, v[0].y);
        let (dx1, dy1) = (v[1].x - x0, v[1].y - y0);
        let (dx2, dy2) = (v[2].x - x0, v[2].y - y0);
        let det = dx1 * dy2 - dx2 * dy1;
        let plane = |f: [f64; 3]| -> [f32; 3] {
            if det.abs() < 1e-9 {
                return [0.0, 0.0, f[0] as f32];
            }
            let (d1, d2) = (f[1] - f[0], f[2] - f[0]);
            let a = (d1 * dy2 - d2 * dy1) / det;
            let b = (d2 * dx1 - d1 * dx2) / det;
            [a as f32, b as f32, f[0] as f32]
        };
        let w_plane = plane([v[0].w, v[1].w, v[2].w]);
        let attr_planes = std::array::from_fn(|i| {
            plane([v[0].a[i] as f64 * v[0].w, v[1].a[i] as f64 * v[1].w, v[2].a[i] as f64 * v[2].w])
        });
        TriShade { item, texture, x0: x0 as f32, y0: y0 as f32, w_plane, attr_planes, normal }
    }

    /// The geometric normal (unit, camera frame) flipped towards the camera
    /// side it is seen from, approximately (for degenerate interpolated normals).
    #[inline]
    pub(super) fn normal_facing(&self) -> [f32; 3] {
        let n = self.normal;
        if n[2] > 0.0 { [-n[0], -n[1], -n[2]] } else { n }
    }

    /// |cos| of the angle between the surface and the ray through pixel (x, y).
    #[inline]
    pub(super) fn cos_incidence(&self, rx: f32, ry: f32) -> f32 {
        let n = self.normal;
        (n[0] * rx + n[1] * ry + n[2]).abs() / (rx * rx + ry * ry + 1.0).sqrt()
    }

    /// Interpolated attributes at pixel (x, y).
    #[inline]
    pub(super) fn attributes(&self, x: f32, y: f32) -> [f32; N_ATTR] {
        let (dx, dy) = (x - self.x0, y - self.y0);
        let w = self.w_plane[2] + self.w_plane[0] * dx + self.w_plane[1] * dy;
        let inv_w = if w > 0.0 { 1.0 / w } else { 0.0 };
        std::array::from_fn(|i| {
            let p = &self.attr_planes[i];
            (p[2] + p[0] * dx + p[1] * dy) * inv_w
        })
    }
}

/// `floor` without a libm call (baseline x86-64 has no SSE4.1 `roundss`);
/// exact for |x| < 2^31, NaN → 0.
#[inline]
pub(super) fn fast_floor(x: f32) -> f32 {
    let i = x as i32 as f32;
    if i > x { i - 1.0 } else { i }
}

/// Samples a texture (wrapping) at (u, v); v = 1 is the top row. Linear RGB.
#[inline]
pub(super) fn sample(dec: &[f32; 256], tex: &Texture, u: f32, v: f32, filter: TextureFilter) -> [f32; 3] {
    let (w, h) = (tex.width as usize, tex.height as usize);
    let fu = u - fast_floor(u);
    let fv = 1.0 - (v - fast_floor(v));
    let fu = if (0.0..=1.0).contains(&fu) { fu } else { 0.0 };
    let fv = if (0.0..=1.0).contains(&fv) { fv } else { 0.0 };
    match filter {
        TextureFilter::Nearest => {
            let x = ((fu * w as f32) as usize).min(w - 1);
            let y = ((fv * h as f32) as usize).min(h - 1);
            let i = (y * w + x) * 3;
            [dec[tex.rgb[i] as usize], dec[tex.rgb[i + 1] as usize], dec[tex.rgb[i + 2] as usize]]
        }
        TextureFilter::Bilinear => {
            let x = fu * w as f32 - 0.5;
            let y = fv * h as f32 - 0.5;
            let (xf, yf) = (fast_floor(x), fast_floor(y));
            let (tx, ty) = (x - xf, y - yf);
            // fu, fv ∈ [0, 1] so xf ∈ [-1, w - 1]: wrap without a division.
            let xa = if xf < 0.0 { w - 1 } else { (xf as usize).min(w - 1) };
            let ya = if yf < 0.0 { h - 1 } else { (yf as usize).min(h - 1) };
            let xb = if xa + 1 == w { 0 } else { xa + 1 };
            let yb = if ya + 1 == h { 0 } else { ya + 1 };
            let (i00, i10) = ((ya * w + xa) * 3, (ya * w + xb) * 3);
            let (i01, i11) = ((yb * w + xa) * 3, (yb * w + xb) * 3);
            let px = &tex.rgb;
            let (t00, t10) = (&px[i00..i00 + 3], &px[i10..i10 + 3]);
            let (t01, t11) = (&px[i01..i01 + 3], &px[i11..i11 + 3]);
            let (w00, w10) = ((1.0 - tx) * (1.0 - ty), tx * (1.0 - ty));
            let (w01, w11) = ((1.0 - tx) * ty, tx * ty);
            let mix = |c: usize| {
                dec[t00[c] as usize] * w00
                    + dec[t10[c] as usize] * w10
                    + dec[t01[c] as usize] * w01
                    + dec[t11[c] as usize] * w11
            };
            [mix(0), mix(1), mix(2)]
        }
    }
}

/// Writes pixel `(x, y)`'s depth, label and coverage from the visibility
/// buffers (background values where nothing covers it) and returns the index
/// of the triangle seen there, if any. Shared by both shading paths.
#[inline]
pub(super) fn write_geometry(
    t: &mut RenderTarget,
    items: &[RenderItem<'_>],
    bg: [u8; 3],
    x: usize,
    y: usize,
) -> Option<usize> {
    let p = y * t.width() as usize + x;
    let id = t.tri_id[p];
    if id == NO_TRIANGLE {
        t.rgb[p * 3..p * 3 + 3].copy_from_slice(&bg);
        t.depth_m[p] = 0.0;
        t.depth_u16[p] = 0;
        t.labels[p] = 0;
        t.reflectance[p] = 0;
        t.specular[p] = 0;
        return None;
    }
    let item = t.tris[id as usize].item as usize;
    let z = 1.0 / t.inv_depth[p] as f64;
    t.depth_m[p] = z as f32;
    t.depth_u16[p] = depth_to_u16(z);
    t.labels[p] = items[item].instance_label;
    let cov = &mut t.coverage[item];
    cov.visible_pixels += 1;
    PixelBox::include(&mut cov.bbox, x as u32, y as u32);
    Some(id as usize)
}

/// Shades every pixel once and fills the output planes and per-item coverage.
pub(super) fn resolve(
    items: &[RenderItem<'_>],
    settings: &RenderSettings,
    textures: &[&Texture],
    target: &mut RenderTarget,
) {
    let enc = srgb_encode_table();
    let dec = srgb_decode_table();
    let (width, height) = (target.width() as usize, target.height() as usize);
    let bg = settings.background_rgb;
    let filter = settings.texture_filter;
    let t = target;
    for y in 0..height {
        for x in 0..width {
            let p = y * width + x;
            let Some(id) = write_geometry(t, items, bg, x, y) else { continue };
            let s = &t.tris[id];

            let a = s.attributes(x as f32, y as f32);
            let lin = if s.texture != NO_TEXTURE {
                let albedo = sample(dec, textures[s.texture as usize], a[0], a[1], filter);
                t.reflectance[p] = unit_to_u8(luminance(albedo));
                [albedo[0] * a[2], albedo[1] * a[3], albedo[2] * a[4]]
            } else {
                t.reflectance[p] = unit_to_u8(a[5]);
                [a[2], a[3], a[4]]
            };
            t.specular[p] = 0;
            let o = &mut t.rgb[p * 3..p * 3 + 3];
            o[0] = linear_to_srgb(enc, lin[0]);
            o[1] = linear_to_srgb(enc, lin[1]);
            o[2] = linear_to_srgb(enc, lin[2]);
        }
    }
}
