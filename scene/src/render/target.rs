//! The reusable render target: output planes (RGB8, depth, labels), per-item
//! coverage, and the scratch buffers the rasteriser and noise model reuse.

use super::shading::TriShade;

/// Marks a pixel no triangle covers in the triangle-id buffer.
pub(super) const NO_TRIANGLE: u32 = u32::MAX;

/// An inclusive pixel rectangle: columns `u_min..=u_max`, rows `v_min..=v_max`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PixelBox {
    pub u_min: u32,
    pub v_min: u32,
    pub u_max: u32,
    pub v_max: u32,
}

impl PixelBox {
    pub fn width(&self) -> u32 {
        self.u_max - self.u_min + 1
    }

    pub fn height(&self) -> u32 {
        self.v_max - self.v_min + 1
    }

    pub(super) fn include(b: &mut Option<PixelBox>, u: u32, v: u32) {
        match b {
            None => *b = Some(PixelBox { u_min: u, v_min: v, u_max: u, v_max: v }),
            Some(b) => {
                b.u_min = b.u_min.min(u);
                b.u_max = b.u_max.max(u);
                b.v_min = b.v_min.min(v);
                b.v_max = b.v_max.max(v);
            }
        }
    }
}

/// How much of one rendered item is seen (noise never changes these).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ItemCoverage {
    pub instance_label: u16,
    /// Pixels where this item is the nearest surface.
    pub visible_pixels: u32,
    /// Pixels it covers inside the image when rendered alone (no occluders).
    pub alone_pixels: u32,
    /// Bounding box of its visible pixels; `None` when fully hidden or off-image.
    pub bbox: Option<PixelBox>,
}

impl ItemCoverage {
    /// `visible_pixels / alone_pixels` in 0..=1; 0 when the item covers no
    /// pixel even alone. Truncation by the image border does not count as
    /// occlusion (both counts are inside the image).
    pub fn visible_fraction(&self) -> f64 {
        if self.alone_pixels == 0 { 0.0 } else { self.visible_pixels as f64 / self.alone_pixels as f64 }
    }
}

/// Output planes of one frame, allocated once per size and reused.
///
/// All planes are row-major, top row first, `width * height` pixels.
#[derive(Clone, Debug, Default)]
pub struct RenderTarget {
    width: u32,
    height: u32,
    pub(super) rgb: Vec<u8>,
    pub(super) depth_m: Vec<f32>,
    pub(super) depth_u16: Vec<u16>,
    pub(super) labels: Vec<u16>,
    pub(super) coverage: Vec<ItemCoverage>,
    // Scratch, reused across frames.
    pub(super) inv_depth: Vec<f32>,
    pub(super) tri_id: Vec<u32>,
    pub(super) stamp: Vec<u16>,
    /// Intrinsics of the last render (the noise model needs the pixel rays).
    pub(super) intrinsics: Option<crate::Intrinsics>,
    pub(super) tris: Vec<TriShade>,
    pub(super) scratch_f32: Vec<f32>,
    pub(super) scratch_rgb: Vec<u8>,
    /// Albedo luminance per pixel (0..255 linear), for the active-sensor models.
    pub(super) reflectance: Vec<u8>,
    /// Specular highlight strength per pixel (0..255), per-pixel mode only.
    pub(super) specular: Vec<u8>,
    /// Shadow-map buffers kept between frames.
    pub(super) shadow_pool: Vec<Vec<f32>>,
    /// More scratch for the sensor models.
    pub(super) scratch_f32b: Vec<f32>,
    pub(super) scratch_u8: Vec<u8>,
}

impl RenderTarget {
    /// A target for `width x height` pixels (all planes zeroed).
    pub fn new(width: u32, height: u32) -> RenderTarget {
        let mut t = RenderTarget::default();
        t.resize(width, height);
        t
    }

    /// A target matching the intrinsics' image size.
    pub fn for_intrinsics(k: &crate::Intrinsics) -> RenderTarget {
        RenderTarget::new(k.width, k.height)
    }

    /// Changes the size; reallocates only when the pixel count grows.
    pub fn resize(&mut self, width: u32, height: u32) {
        self.intrinsics = None;
        self.tris.clear();
        self.coverage.clear();
        let n = width as usize * height as usize;
        self.width = width;
        self.height = height;
        self.rgb.resize(n * 3, 0);
        self.depth_m.resize(n, 0.0);
        self.depth_u16.resize(n, 0);
        self.labels.resize(n, 0);
        self.inv_depth.resize(n, 0.0);
        self.tri_id.resize(n, NO_TRIANGLE);
        self.stamp.resize(n, 0);
        self.scratch_f32.resize(n, 0.0);
        self.scratch_rgb.resize(n * 3, 0);
        self.reflectance.resize(n, 0);
        self.specular.resize(n, 0);
        self.scratch_f32b.resize(n, 0.0);
        self.scratch_u8.resize(n, 0);
    }

    pub fn width(&self) -> u32 {
        self.width
    }

    pub fn height(&self) -> u32 {
        self.height
    }

    pub fn pixel_count(&self) -> usize {
        self.width as usize * self.height as usize
    }

    /// RGB8, 3 bytes per pixel (sRGB-encoded).
    pub fn rgb(&self) -> &[u8] {
        &self.rgb
    }

    /// Depth: camera-frame z in metres; 0 = no measurement.
    pub fn depth_m(&self) -> &[f32] {
        &self.depth_m
    }

    /// Depth in units of 0.1 mm (`round(z * 10000)`, saturating); 0 = missing.
    pub fn depth_u16(&self) -> &[u16] {
        &self.depth_u16
    }

    /// Label map: the visible item's `instance_label`; 0 = background.
    pub fn labels(&self) -> &[u16] {
        &self.labels
    }

    /// Albedo luminance of the visible surface (linear, 0..255; 0 where
    /// nothing is drawn): the active-sensor models' reflectance.
    pub fn reflectance(&self) -> &[u8] {
        &self.reflectance
    }

    /// Specular highlight strength per pixel (0..255; per-pixel mode only,
    /// else 0): where structured-light sensors lose depth on glare.
    pub fn specular(&self) -> &[u8] {
        &self.specular
    }

    /// Mutable RGB plane (for post-processing such as the camera pipeline).
    pub fn rgb_mut(&mut self) -> &mut [u8] {
        &mut self.rgb
    }

    /// Coverage of each item of the last `render_scene` call, in item order.
    pub fn coverage(&self) -> &[ItemCoverage] {
        &self.coverage
    }

    /// Writes the label map through a lookup table (`out[p] = lut[labels[p]]`,
    /// 0 where a label is past the table), e.g. instance → class id. `out` is
    /// resized to the pixel count; no allocation when it already fits.
    pub fn map_labels(&self, lut: &[u16], out: &mut Vec<u16>) {
        out.clear();
        out.extend(self.labels.iter().map(|&l| lut.get(l as usize).copied().unwrap_or(0)));
    }

    /// Rewrites the label map in place through a lookup table (see [`Self::map_labels`]).
    pub fn map_labels_in_place(&mut self, lut: &[u16]) {
        for l in self.labels.iter_mut() {
            *l = lut.get(*l as usize).copied().unwrap_or(0);
        }
    }
}
