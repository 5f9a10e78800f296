//! Validating a received frame: every header field and every plane offset and
//! length is checked against the payload slice before any plane is borrowed.
//! Never reads outside the slice, never panics, never allocates.

use crate::InvalidReason;
use crate::frame_header::{
    ColorFormat, DepthFormat, FOCAL_RANGE_PX, FRAME_MAGIC, FrameHeader, FrameLayout, LabelFormat, MAX_IMAGE_SIDE,
    PlaneRef,
};

/// Depth values borrowed from the payload.
#[derive(Clone, Copy, Debug)]
pub enum DepthData<'a> {
    /// Units times `scale` metres; 0 = no reading.
    U16 { data: &'a [u16], scale: f32 },
    /// Metres; 0, NaN or infinity = no reading.
    F32(&'a [f32]),
}

/// Per-pixel class ids borrowed from the payload (0 = background).
#[derive(Clone, Copy, Debug)]
pub enum LabelData<'a> {
    U8(&'a [u8]),
    U16(&'a [u16]),
}

/// A validated frame: header copy plus plane slices of exactly width*height values each.
#[derive(Clone, Copy, Debug)]
pub struct FramePlanes<'a> {
    pub header: FrameHeader,
    pub color_format: ColorFormat,
    /// width * height * 3 bytes.
    pub color: &'a [u8],
    pub depth: DepthData<'a>,
    pub labels: Option<LabelData<'a>>,
}

/// Why a received frame was refused; [`FrameRejection::reason`] gives its stats code.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum FrameRejection {
    #[error("magic is {0:#010x}, not a fusepose frame")]
    BadMagic(u32),
    #[error("frame wire-format version {got}, this daemon speaks v{}", crate::WIRE_VERSION)]
    VersionMismatch { got: u16 },
    #[error("header size {got}, expected {}", core::mem::size_of::<FrameHeader>())]
    HeaderSize { got: u16 },
    #[error("image size {width}x{height} is outside 1..={MAX_IMAGE_SIDE}")]
    BadSize { width: u32, height: u32 },
    #[error("unknown {plane} format code {code}")]
    UnknownFormat { plane: &'static str, code: u8 },
    #[error("focal length fx={fx}, fy={fy} is not a finite number of pixels in {:?}", FOCAL_RANGE_PX)]
    BadFocalLength { fx: f64, fy: f64 },
    #[error("principal point ({cx}, {cy}) is not finite or lies outside [-0.5, 1.5] x the image size")]
    BadPrincipalPoint { cx: f64, cy: f64 },
    #[error("depth scale {0} is not a positive finite number")]
    BadDepthScale(f32),
    #[error("{plane} plane [{offset}, +{len}) lies outside the {payload_len}-byte payload")]
    PlaneOutOfBounds { plane: &'static str, offset: u64, len: u64, payload_len: usize },
    #[error("{plane} plane has {got} bytes, expected {expected}")]
    PlaneLength { plane: &'static str, got: u64, expected: u64 },
    #[error("{plane} plane at offset {offset} is not aligned to its {align}-byte values")]
    PlaneMisaligned { plane: &'static str, offset: u64, align: usize },
    #[error("{a} and {b} planes overlap")]
    PlaneOverlap { a: &'static str, b: &'static str },
    #[error("frame says camera id {got:#010x}, this service belongs to {expected:#010x}")]
    WrongCamera { got: u32, expected: u32 },
    #[error("payload has {got} bytes, the header's plane layout needs {expected}")]
    PayloadTruncated { got: usize, expected: u64 },
    #[error("has_labels = 1 but the label plane is empty")]
    LabelsMissing,
}

impl FrameRejection {
    pub fn reason(&self) -> InvalidReason {
        match self {
            Self::BadMagic(_) => InvalidReason::BadMagic,
            Self::VersionMismatch { .. } => InvalidReason::VersionMismatch,
            Self::HeaderSize { .. } => InvalidReason::HeaderSize,
            Self::BadSize { .. } => InvalidReason::BadSize,
            Self::UnknownFormat { .. } => InvalidReason::UnknownFormat,
            Self::BadFocalLength { .. } => InvalidReason::BadFocalLength,
            Self::BadPrincipalPoint { .. } => InvalidReason::BadPrincipalPoint,
            Self::BadDepthScale(_) => InvalidReason::BadDepthScale,
            Self::PlaneOutOfBounds { .. } => InvalidReason::PlaneOutOfBounds,
            Self::PlaneLength { .. } => InvalidReason::PlaneLength,
            Self::PlaneMisaligned { .. } => InvalidReason::PlaneMisaligned,
            Self::PlaneOverlap { .. } => InvalidReason::PlaneOverlap,
            Self::WrongCamera { .. } => InvalidReason::WrongCamera,
            Self::PayloadTruncated { .. } => InvalidReason::PayloadTruncated,
            Self::LabelsMissing => InvalidReason::LabelsMissing,
        }
    }
}

/// Bytes of one plane, bounds- and length-checked.
fn plane_bytes<'a>(
    payload: &'a [u8],
    plane: &'static str,
    at: PlaneRef,
    expected_len: u64,
) -> Result<&'a [u8], FrameRejection> {
    let out_of_bounds =
        FrameRejection::PlaneOutOfBounds { plane, offset: at.offset, len: at.len, payload_len: payload.len() };
    let end = at.offset.checked_add(at.len).ok_or(out_of_bounds)?;
    if end > payload.len() as u64 {
        return Err(out_of_bounds);
    }
    if at.len != expected_len {
        return Err(FrameRejection::PlaneLength { plane, got: at.len, expected: expected_len });
    }
    // Both fit in usize: end <= payload.len().
    Ok(&payload[at.offset as usize..end as usize])
}

fn cast_plane<'a, T: bytemuck::Pod>(
    bytes: &'a [u8],
    plane: &'static str,
    offset: u64,
) -> Result<&'a [T], FrameRejection> {
    bytemuck::try_cast_slice(bytes).map_err(|_| FrameRejection::PlaneMisaligned {
        plane,
        offset,
        align: core::mem::align_of::<T>(),
    })
}

fn overlaps(a: PlaneRef, b: PlaneRef) -> bool {
    // Called only after bounds checks, so the sums cannot overflow.
    a.len > 0 && b.len > 0 && a.offset < b.offset + b.len && b.offset < a.offset + a.len
}

/// Validates `header` against `payload` and borrows the planes.
///
/// `expected_camera_id`: the id of the service the frame came in on, when the
/// caller wants it enforced.
pub fn decode_frame<'a>(
    header: &FrameHeader,
    payload: &'a [u8],
    expected_camera_id: Option<u32>,
) -> Result<FramePlanes<'a>, FrameRejection> {
    let h = *header;
    if h.magic != FRAME_MAGIC {
        return Err(FrameRejection::BadMagic(h.magic));
    }
    if h.format_version != crate::WIRE_VERSION {
        return Err(FrameRejection::VersionMismatch { got: h.format_version });
    }
    if h.header_size as usize != core::mem::size_of::<FrameHeader>() {
        return Err(FrameRejection::HeaderSize { got: h.header_size });
    }
    if let Some(expected) = expected_camera_id
        && h.camera_id != expected
    {
        return Err(FrameRejection::WrongCamera { got: h.camera_id, expected });
    }
    if h.width == 0 || h.height == 0 || h.width > MAX_IMAGE_SIDE || h.height > MAX_IMAGE_SIDE {
        return Err(FrameRejection::BadSize { width: h.width, height: h.height });
    }
    let color_format = ColorFormat::from_code(h.color_format)
        .ok_or(FrameRejection::UnknownFormat { plane: "colour", code: h.color_format })?;
    let depth_format = DepthFormat::from_code(h.depth_format)
        .ok_or(FrameRejection::UnknownFormat { plane: "depth", code: h.depth_format })?;
    let label_format = match h.has_labels {
        0 => None,
        1 => Some(
            LabelFormat::from_code(h.label_format)
                .ok_or(FrameRejection::UnknownFormat { plane: "label", code: h.label_format })?,
        ),
        flag => return Err(FrameRejection::UnknownFormat { plane: "label flag", code: flag }),
    };
    // RangeInclusive::contains is false for NaN.
    if !(FOCAL_RANGE_PX.contains(&h.fx) && FOCAL_RANGE_PX.contains(&h.fy)) {
        return Err(FrameRejection::BadFocalLength { fx: h.fx, fy: h.fy });
    }
    let (w, hgt) = (h.width as f64, h.height as f64);
    if !(h.cx.is_finite()
        && h.cx >= -0.5 * w
        && h.cx <= 1.5 * w
        && h.cy.is_finite()
        && h.cy >= -0.5 * hgt
        && h.cy <= 1.5 * hgt)
    {
        return Err(FrameRejection::BadPrincipalPoint { cx: h.cx, cy: h.cy });
    }
    if !(h.depth_scale.is_finite() && h.depth_scale > 0.0) {
        return Err(FrameRejection::BadDepthScale(h.depth_scale));
    }
    if label_format.is_some() && h.labels.len == 0 {
        return Err(FrameRejection::LabelsMissing);
    }
    // A header with the standard layout (what `Producer` writes) over a short
    // payload is a truncated frame; other layouts fall to the per-plane checks.
    let standard = FrameLayout {
        width: h.width,
        height: h.height,
        color_format,
        depth_format,
        depth_scale: h.depth_scale,
        labels: label_format,
    };
    let [color, depth, labels] = standard.planes();
    if h.color == color && h.depth == depth && (label_format.is_none() || h.labels == labels) {
        let expected = standard.payload_len() as u64;
        if (payload.len() as u64) < expected {
            return Err(FrameRejection::PayloadTruncated { got: payload.len(), expected });
        }
    }

    let pixels = h.width as u64 * h.height as u64; // <= 4096², no overflow
    let color = plane_bytes(payload, "colour", h.color, pixels * 3)?;
    let depth_bytes = plane_bytes(payload, "depth", h.depth, pixels * depth_format.bytes_per_pixel() as u64)?;
    let depth = match depth_format {
        DepthFormat::U16 => {
            DepthData::U16 { data: cast_plane(depth_bytes, "depth", h.depth.offset)?, scale: h.depth_scale }
        }
        DepthFormat::F32 => DepthData::F32(cast_plane(depth_bytes, "depth", h.depth.offset)?),
    };
    if overlaps(h.color, h.depth) {
        return Err(FrameRejection::PlaneOverlap { a: "colour", b: "depth" });
    }
    let labels = match label_format {
        None => None,
        Some(format) => {
            let bytes = plane_bytes(payload, "label", h.labels, pixels * format.bytes_per_pixel() as u64)?;
            if overlaps(h.labels, h.color) {
                return Err(FrameRejection::PlaneOverlap { a: "label", b: "colour" });
            }
            if overlaps(h.labels, h.depth) {
                return Err(FrameRejection::PlaneOverlap { a: "label", b: "depth" });
            }
            Some(match format {
                LabelFormat::U8 => LabelData::U8(bytes),
                LabelFormat::U16 => LabelData::U16(cast_plane(bytes, "label", h.labels.offset)?),
            })
        }
    };
    Ok(FramePlanes { header: h, color_format, color, depth, labels })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame_header::FrameLayout;

    /// A payload buffer aligned to 8 bytes like iceoryx2's.
    fn aligned_payload(len: usize) -> Vec<u64> {
        vec![0u64; len.div_ceil(8) + 1]
    }

    fn good_header(layout: &FrameLayout) -> FrameHeader {
        FrameHeader { fx: 500.0, fy: 500.0, cx: 2.0, cy: 1.5, ..layout.header(7) }
    }

    fn small_layout() -> FrameLayout {
        FrameLayout { width: 5, height: 3, labels: Some(LabelFormat::U16), ..FrameLayout::vga_rgbd() }
    }

    #[test]
    fn a_well_formed_frame_decodes_with_exact_plane_sizes() {
        let layout = small_layout();
        let buf = aligned_payload(layout.payload_len());
        let bytes = &bytemuck::cast_slice::<u64, u8>(&buf)[..layout.payload_len()];
        let planes = decode_frame(&good_header(&layout), bytes, Some(7)).unwrap();
        assert_eq!(planes.color.len(), 45);
        match planes.depth {
            DepthData::U16 { data, scale } => assert_eq!((data.len(), scale), (15, 0.001)),
            DepthData::F32(_) => panic!("wrong depth format"),
        }
        assert!(matches!(planes.labels, Some(LabelData::U16(l)) if l.len() == 15));
    }

    #[test]
    fn every_corruption_is_refused_with_its_reason() {
        let layout = small_layout();
        let buf = aligned_payload(layout.payload_len());
        let bytes = &bytemuck::cast_slice::<u64, u8>(&buf)[..layout.payload_len()];
        let good = good_header(&layout);
        let cases: Vec<(FrameHeader, InvalidReason)> = vec![
            (FrameHeader { magic: 0, ..good }, InvalidReason::BadMagic),
            (FrameHeader { format_version: 99, ..good }, InvalidReason::VersionMismatch),
            (FrameHeader { header_size: 64, ..good }, InvalidReason::HeaderSize),
            (FrameHeader { camera_id: 8, ..good }, InvalidReason::WrongCamera),
            (FrameHeader { width: 0, ..good }, InvalidReason::BadSize),
            (FrameHeader { height: 5000, ..good }, InvalidReason::BadSize),
            (FrameHeader { color_format: 9, ..good }, InvalidReason::UnknownFormat),
            (FrameHeader { depth_format: 0, ..good }, InvalidReason::UnknownFormat),
            (FrameHeader { has_labels: 2, ..good }, InvalidReason::UnknownFormat),
            (FrameHeader { fx: f64::NAN, ..good }, InvalidReason::BadFocalLength),
            (FrameHeader { fy: -1.0, ..good }, InvalidReason::BadFocalLength),
            (FrameHeader { fx: 0.0, ..good }, InvalidReason::BadFocalLength),
            (FrameHeader { fy: f64::INFINITY, ..good }, InvalidReason::BadFocalLength),
            // Positive and finite but absurd: points would land at infinity.
            (FrameHeader { fx: 1e-300, ..good }, InvalidReason::BadFocalLength),
            (FrameHeader { fy: 0.5, ..good }, InvalidReason::BadFocalLength),
            (FrameHeader { fx: 2.0e6, ..good }, InvalidReason::BadFocalLength),
            (FrameHeader { cx: f64::INFINITY, ..good }, InvalidReason::BadPrincipalPoint),
            (FrameHeader { cy: -100.0, ..good }, InvalidReason::BadPrincipalPoint),
            (FrameHeader { labels: PlaneRef::default(), ..good }, InvalidReason::LabelsMissing),
            (FrameHeader { depth_scale: 0.0, ..good }, InvalidReason::BadDepthScale),
            (FrameHeader { color: PlaneRef { offset: u64::MAX, len: 45 }, ..good }, InvalidReason::PlaneOutOfBounds),
            (FrameHeader { color: PlaneRef { offset: 0, len: u64::MAX }, ..good }, InvalidReason::PlaneOutOfBounds),
            (FrameHeader { labels: PlaneRef { offset: 90, len: 30 }, ..good }, InvalidReason::PlaneOutOfBounds),
            (FrameHeader { color: PlaneRef { offset: 0, len: 44 }, ..good }, InvalidReason::PlaneLength),
            (FrameHeader { depth: PlaneRef { offset: 49, len: 30 }, ..good }, InvalidReason::PlaneMisaligned),
            (FrameHeader { depth: PlaneRef { offset: 40, len: 30 }, ..good }, InvalidReason::PlaneOverlap),
            (FrameHeader { labels: PlaneRef { offset: 48, len: 30 }, ..good }, InvalidReason::PlaneOverlap),
        ];
        for (header, reason) in cases {
            let got = decode_frame(&header, bytes, Some(7)).map(|_| ()).unwrap_err();
            assert_eq!(got.reason(), reason, "{header:?} gave {got}");
        }
        // A truncated payload under the standard layout: the label plane no longer fits.
        let got = decode_frame(&good, &bytes[..bytes.len() - 1], Some(7)).map(|_| ()).unwrap_err();
        assert_eq!(got, FrameRejection::PayloadTruncated { got: bytes.len() - 1, expected: bytes.len() as u64 });
        // The focal range ends are accepted.
        for f in [1.0, 1.0e6] {
            assert!(decode_frame(&FrameHeader { fx: f, fy: f, ..good }, bytes, Some(7)).is_ok(), "{f}");
        }
    }

    #[test]
    fn random_headers_never_panic_or_escape_the_slice() {
        let layout = small_layout();
        let buf = aligned_payload(layout.payload_len());
        let bytes = &bytemuck::cast_slice::<u64, u8>(&buf)[..layout.payload_len()];
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        let good = good_header(&layout);
        for _ in 0..20_000 {
            let mut h = good;
            let r = next();
            match r % 6 {
                0 => h.color = PlaneRef { offset: next() % 128, len: next() % 128 },
                1 => h.depth = PlaneRef { offset: next() % 128, len: next() % 64 },
                2 => h.labels = PlaneRef { offset: next(), len: next() },
                3 => (h.width, h.height) = ((next() % 8) as u32, (next() % 8) as u32),
                4 => (h.depth_format, h.label_format) = ((next() % 4) as u8, (next() % 4) as u8),
                _ => h.depth.offset = next() % 100,
            }
            if let Ok(planes) = decode_frame(&h, bytes, None) {
                let base = bytes.as_ptr() as usize;
                let end = base + bytes.len();
                let inside = |p: *const u8, n: usize| p as usize >= base && p as usize + n <= end;
                assert!(inside(planes.color.as_ptr(), planes.color.len()));
                match planes.depth {
                    DepthData::U16 { data, .. } => assert!(inside(data.as_ptr().cast(), data.len() * 2)),
                    DepthData::F32(data) => assert!(inside(data.as_ptr().cast(), data.len() * 4)),
                }
            }
        }
    }
}
