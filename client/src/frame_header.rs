//! Frame wire format: the `#[repr(C)]` header in front of the RGB, depth and
//! optional label planes of one `[u8]` payload (class ids, or instance ids
//! plus an instance → class table), and the producer-side layout.
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

/// Label plane encoding.
///
/// `U8` and `U16` carry a class id per pixel (0 = background). `InstanceU16`
/// carries an instance id per pixel (u16, 0 = background) plus the instance
/// class table, a plane of `max_instances + 1` u16 entries where entry `id` is
/// the class id of instance `id` (entry 0 unused, write 0).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LabelFormat {
    U8,
    U16,
    /// Instance ids 1..=`max_instances` per pixel, and their classes in the table.
    InstanceU16 {
        max_instances: u16,
    },
}

/// `label_format` code of [`LabelFormat::U8`].
pub const LABELS_U8: u8 = 1;
/// `label_format` code of [`LabelFormat::U16`].
pub const LABELS_U16: u8 = 2;
/// `label_format` code of [`LabelFormat::InstanceU16`].
pub const LABELS_INSTANCE_U16: u8 = 3;

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
    /// The format of header code `code`; `instance_count` (the header field)
    /// sizes the instance class table of code 3.
    pub fn from_code(code: u8, instance_count: u16) -> Option<Self> {
        match code {
            LABELS_U8 => Some(Self::U8),
            LABELS_U16 => Some(Self::U16),
            LABELS_INSTANCE_U16 => Some(Self::InstanceU16 { max_instances: instance_count }),
            _ => None,
        }
    }

    /// The header's `label_format` code.
    pub fn code(self) -> u8 {
        match self {
            Self::U8 => LABELS_U8,
            Self::U16 => LABELS_U16,
            Self::InstanceU16 { .. } => LABELS_INSTANCE_U16,
        }
    }

    /// Bytes per label value.
    pub fn bytes_per_pixel(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 | Self::InstanceU16 { .. } => 2,
        }
    }

    /// Entries of the instance class table (`max_instances + 1`; 0 for class-id formats).
    pub fn instance_table_entries(self) -> usize {
        match self {
            Self::InstanceU16 { max_instances } => max_instances as usize + 1,
            Self::U8 | Self::U16 => 0,
        }
    }
}

/// Where one plane lies in the payload, in bytes from the payload start.
///
/// u32 is enough: the largest frame (4096² pixels, RGB8 + f32 depth + u16
/// labels + a full instance class table) is about 151 MB.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ZeroCopySend)]
#[type_name("fusepose::PlaneRef")]
pub struct PlaneRef {
    pub offset: u32,
    pub len: u32,
}

impl PlaneRef {
    /// One past the last byte (no overflow: computed in u64).
    pub fn end(&self) -> u64 {
        self.offset as u64 + self.len as u64
    }
}

/// The user header of every frame sample (128 bytes, no padding; offsets in
/// `docs/PROTOCOL.md`, "Frames").
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
    /// [`LabelFormat`] code (ignored without labels, except that 3 needs `has_labels = 1`).
    pub label_format: u8,
    /// Label format 3: instance ids run 1..=`instance_count` and the instance
    /// class table has `instance_count + 1` entries. 0 for every other format.
    pub instance_count: u16,
    /// Write 0 (not checked).
    pub _reserved: u16,
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
    /// Class ids (formats 1, 2) or instance ids (format 3); empty without labels.
    pub labels: PlaneRef,
    /// Label format 3: u16 class id per instance id (`instance_count + 1`
    /// entries, entry 0 unused); empty for every other format.
    pub instance_classes: PlaneRef,
    /// Write 0 (not checked).
    pub _reserved_end: [u8; 16],
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

/// A plane of `len` bytes (at most ~151 MB for a valid layout, see [`PlaneRef`]).
fn plane(offset: u64, len: u64) -> PlaneRef {
    PlaneRef { offset: offset as u32, len: len as u32 }
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
        let color = plane(0, self.pixels() * 3);
        let depth = plane(align8(color.end()), self.pixels() * self.depth_format.bytes_per_pixel() as u64);
        let labels = match self.labels {
            Some(f) => plane(align8(depth.end()), self.pixels() * f.bytes_per_pixel() as u64),
            None => PlaneRef::default(),
        };
        [color, depth, labels]
    }

    /// The instance class table, after the label plane at the next multiple of
    /// 8 (empty unless the labels are [`LabelFormat::InstanceU16`]).
    pub fn instance_classes(&self) -> PlaneRef {
        match self.labels {
            Some(f @ LabelFormat::InstanceU16 { .. }) => {
                plane(align8(self.planes()[2].end()), f.instance_table_entries() as u64 * 2)
            }
            _ => PlaneRef::default(),
        }
    }

    /// Bytes of payload one frame needs.
    pub fn payload_len(&self) -> usize {
        let [_, depth, labels] = self.planes();
        depth.end().max(labels.end()).max(self.instance_classes().end()) as usize
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
            label_format: self.labels.map_or(0, LabelFormat::code),
            instance_count: match self.labels {
                Some(LabelFormat::InstanceU16 { max_instances }) => max_instances,
                _ => 0,
            },
            color,
            depth,
            labels,
            instance_classes: self.instance_classes(),
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
        assert!(l.offset as u64 >= d.end() && l.offset % 8 == 0);
        assert_eq!(layout.payload_len() as u64, l.end());
    }

    #[test]
    fn odd_width_still_aligns_depth() {
        let layout = FrameLayout { width: 3, height: 1, ..FrameLayout::vga_rgbd() };
        let [c, d, _] = layout.planes();
        assert_eq!(c.len, 9);
        assert_eq!(d.offset, 16);
        assert_eq!(layout.payload_len(), 22);
    }

    #[test]
    fn instance_layout_puts_the_class_table_after_the_ids() {
        let layout = FrameLayout {
            width: 5,
            height: 3,
            labels: Some(LabelFormat::InstanceU16 { max_instances: 4 }),
            ..FrameLayout::vga_rgbd()
        };
        let [c, d, l] = layout.planes();
        let t = layout.instance_classes();
        assert_eq!((c.offset, c.len, d.offset, d.len), (0, 45, 48, 30));
        assert_eq!((l.offset, l.len), (80, 30));
        // 5 entries (ids 0..=4) at the next multiple of 8 after the id plane.
        assert_eq!((t.offset, t.len), (112, 10));
        assert_eq!(layout.payload_len(), 122);
        let h = layout.header(1);
        assert_eq!((h.has_labels, h.label_format, h.instance_count), (1, 3, 4));
        assert_eq!((h.labels, h.instance_classes), (l, t));
        // Class-id layouts have no table.
        let classes = FrameLayout { labels: Some(LabelFormat::U16), ..layout };
        assert_eq!(classes.instance_classes(), PlaneRef::default());
        assert_eq!(classes.header(1).instance_count, 0);
        assert_eq!(LabelFormat::from_code(3, 4), layout.labels);
        assert_eq!(LabelFormat::from_code(4, 0), None);
    }

    #[test]
    fn header_offsets_are_the_documented_ones() {
        use core::mem::offset_of;
        assert_eq!(offset_of!(FrameHeader, label_format), 27);
        assert_eq!(offset_of!(FrameHeader, instance_count), 28);
        assert_eq!(offset_of!(FrameHeader, _reserved), 30);
        assert_eq!(offset_of!(FrameHeader, sequence), 32);
        assert_eq!(offset_of!(FrameHeader, fx), 48);
        assert_eq!(offset_of!(FrameHeader, color), 80);
        assert_eq!(offset_of!(FrameHeader, depth), 88);
        assert_eq!(offset_of!(FrameHeader, labels), 96);
        assert_eq!(offset_of!(FrameHeader, instance_classes), 104);
        assert_eq!(offset_of!(FrameHeader, _reserved_end), 112);
    }
}
