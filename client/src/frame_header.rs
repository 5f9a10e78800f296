//! Frame wire format: the `#[repr(C)]` header in front of the RGB, depth and
//! optional label planes of one `[u8]` payload, and the producer-side layout.
//!
//! Format codes are stored as raw integers (never Rust enums) so that any byte
//! pattern another process writes is a valid header that validation can reject.

use iceoryx2::prelude::ZeroCopySend;

/// `b"FPFR"` read as a little-endian u32: the first field of every frame header.
pub const FRAME_MAGIC: u32 = u32::from_le_bytes(*b"FPFR");

/// Largest accepted image side, pixels.
pub const MAX_IMAGE_SIDE: u32 = 4096;

/// Accepted focal lengths fx, fy, pixels. Real lenses on images up to
/// [`MAX_IMAGE_SIDE`] lie far inside; values outside (e.g. 1e-300) put
/// back-projected points at infinity and make every pose non-finite.
pub const FOCAL_RANGE_PX: core::ops::RangeInclusive<f64> = 1.0..=1.0e6;

/// Byte order of the colour plane: 3 bytes per pixel, row-major.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorFormat {
    Rgb8 = 1,
    Bgr8 = 2,
}

/// Depth plane encoding: u16 units times `depth_scale` metres (0 = no reading),
/// or f32 metres (0, NaN, infinity = no reading).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DepthFormat {
    U16 = 1,
    F32 = 2,
}

/// Label plane encoding: per-pixel class id, 0 = background.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LabelFormat {
    U8 = 1,
    U16 = 2,
}

impl ColorFormat {
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            1 => Some(Self::Rgb8),
            2 => Some(Self::Bgr8),
            _ => None,
        }
    }
}

impl DepthFormat {
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            1 => Some(Self::U16),
            2 => Some(Self::F32),
            _ => None,
        }
    }
    /// Bytes per depth value.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::U16 => 2,
            Self::F32 => 4,
        }
    }
}

impl LabelFormat {
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            1 => Some(Self::U8),
            2 => Some(Self::U16),
            _ => None,
        }
    }
    /// Bytes per label value.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 => 2,
        }
    }
}

/// Where one plane lies in the payload, in bytes from the payload start.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("fusepose::PlaneRef")]
pub struct PlaneRef {
    pub offset: u64,
    pub len: u64,
}

/// The user header of every frame sample (128 bytes, no padding).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("fusepose::FrameHeader")]
pub struct FrameHeader {
    /// [`FRAME_MAGIC`].
    pub magic: u32,
    /// [`crate::WIRE_VERSION`].
    pub format_version: u16,
    /// `size_of::<FrameHeader>()` as the producer saw it.
    pub header_size: u16,
    /// [`crate::camera_id`] of the camera name.
    pub camera_id: u32,
    pub width: u32,
    pub height: u32,
    /// Metres per depth unit for [`DepthFormat::U16`] (e.g. 0.001); 1.0 for f32 depth.
    pub depth_scale: f32,
    /// [`ColorFormat`] code.
    pub color_format: u8,
    /// [`DepthFormat`] code.
    pub depth_format: u8,
    /// 1 when a label plane is present, else 0.
    pub has_labels: u8,
    /// [`LabelFormat`] code (ignored without labels).
    pub label_format: u8,
    pub _reserved: u32,
    /// Producer's frame counter, +1 per frame; gaps mean frames the producer dropped.
    pub sequence: u64,
    /// When the image was captured, `CLOCK_MONOTONIC` ns.
    pub capture_time_ns: u64,
    /// Pinhole intrinsics, pixels (pixel centres at integer coordinates).
    pub fx: f64,
    pub fy: f64,
    pub cx: f64,
    pub cy: f64,
    pub color: PlaneRef,
    pub depth: PlaneRef,
    pub labels: PlaneRef,
}

const _: () = assert!(core::mem::size_of::<FrameHeader>() == 128);

/// Image size and plane formats a producer publishes; decides the plane offsets.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameLayout {
    pub width: u32,
    pub height: u32,
    pub color_format: ColorFormat,
    pub depth_format: DepthFormat,
    /// Metres per depth unit for u16 depth; ignored (1.0 on the wire) for f32.
    pub depth_scale: f32,
    pub labels: Option<LabelFormat>,
}

fn align8(n: u64) -> u64 {
    n.div_ceil(8) * 8
}

impl FrameLayout {
    /// A 640x480 RGB8 + u16 millimetre depth layout, without labels.
    pub fn vga_rgbd() -> Self {
        Self {
            width: 640,
            height: 480,
            color_format: ColorFormat::Rgb8,
            depth_format: DepthFormat::U16,
            depth_scale: 0.001,
            labels: None,
        }
    }

    fn pixels(&self) -> u64 {
        self.width as u64 * self.height as u64
    }

    /// Colour, depth and label planes (label plane empty without labels), each 8-byte aligned.
    pub fn planes(&self) -> [PlaneRef; 3] {
        let color = PlaneRef { offset: 0, len: self.pixels() * 3 };
        let depth =
            PlaneRef { offset: align8(color.len), len: self.pixels() * self.depth_format.bytes_per_pixel() as u64 };
        let labels = match self.labels {
            Some(f) => {
                PlaneRef { offset: align8(depth.offset + depth.len), len: self.pixels() * f.bytes_per_pixel() as u64 }
            }
            None => PlaneRef::default(),
        };
        [color, depth, labels]
    }

    /// Bytes of payload one frame needs.
    pub fn payload_len(&self) -> usize {
        let [_, depth, labels] = self.planes();
        (depth.offset + depth.len).max(labels.offset + labels.len) as usize
    }

    /// Checks the size and scale a producer asks for.
    pub fn validate(&self) -> Result<(), String> {
        if self.width == 0 || self.height == 0 || self.width > MAX_IMAGE_SIDE || self.height > MAX_IMAGE_SIDE {
            return Err(format!("image size {}x{} is outside 1..={MAX_IMAGE_SIDE}", self.width, self.height));
        }
        if self.depth_format == DepthFormat::U16 && !(self.depth_scale.is_finite() && self.depth_scale > 0.0) {
            return Err(format!("depth scale {} is not a positive finite number", self.depth_scale));
        }
        Ok(())
    }

    /// A header for this layout with everything but sequence, time and intrinsics filled in.
    pub fn header(&self, camera_id: u32) -> FrameHeader {
        let [color, depth, labels] = self.planes();
        FrameHeader {
            magic: FRAME_MAGIC,
            format_version: crate::WIRE_VERSION,
            header_size: core::mem::size_of::<FrameHeader>() as u16,
            camera_id,
            width: self.width,
            height: self.height,
            depth_scale: match self.depth_format {
                DepthFormat::U16 => self.depth_scale,
                DepthFormat::F32 => 1.0,
            },
            color_format: self.color_format as u8,
            depth_format: self.depth_format as u8,
            has_labels: self.labels.is_some() as u8,
            label_format: self.labels.map_or(0, |f| f as u8),
            color,
            depth,
            labels,
            ..FrameHeader::default()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vga_layout_planes_are_aligned_and_disjoint() {
        let mut layout = FrameLayout::vga_rgbd();
        layout.labels = Some(LabelFormat::U8);
        let [c, d, l] = layout.planes();
        assert_eq!(c.len, 640 * 480 * 3);
        assert_eq!(d.offset % 8, 0);
        assert_eq!(d.len, 640 * 480 * 2);
        assert!(l.offset >= d.offset + d.len && l.offset % 8 == 0);
        assert_eq!(layout.payload_len() as u64, l.offset + l.len);
    }

    #[test]
    fn odd_width_still_aligns_depth() {
        let layout = FrameLayout { width: 3, height: 1, ..FrameLayout::vga_rgbd() };
        let [c, d, _] = layout.planes();
        assert_eq!(c.len, 9);
        assert_eq!(d.offset, 16);
        assert_eq!(layout.payload_len(), 22);
    }
}
