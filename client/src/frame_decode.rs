//! Validating a received frame: every header field and every plane offset and
//! length is checked against the payload slice before any plane is borrowed.
//! Never reads outside the slice, never panics, never allocates.

use crate::InvalidReason;
use crate::frame_header::{
    ColorFormat, DepthFormat, FOCAL_RANGE_PX, FRAME_MAGIC, FrameHeader, FrameLayout, LABELS_INSTANCE_U16, LabelFormat,
    MAX_IMAGE_SIDE, PlaneRef,
};

/// Depth values borrowed from the payload.
#[derive(Clone, Copy, Debug)]
pub enum DepthData<'a> {
    /// Units times `scale` metres; 0 = no reading.
    U16 { data: &'a [u16], scale: f32 },
    /// Metres; 0, NaN or infinity = no reading.
    F32(&'a [f32]),
}

/// Per-pixel labels borrowed from the payload (0 = background).
#[derive(Clone, Copy, Debug)]
pub enum LabelData<'a> {
    /// Class ids.
    U8(&'a [u8]),
    /// Class ids.
    U16(&'a [u16]),
    /// Instance ids, and the instance class table: `classes[id]` is the class
    /// of instance `id` (`instance_count + 1` entries, entry 0 unused).
    Instances { ids: &'a [u16], classes: &'a [u16] },
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
    #[error(
        "frame wire-format version {got}, this daemon speaks v{}: upgrade/downgrade all fusepose processes together",
        crate::WIRE_VERSION
    )]
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
    #[error(
        "label format 3 (instance ids) but the instance class table is empty: \
         send instance_count + 1 u16 class ids in the instance_classes plane"
    )]
    InstanceTableMissing,
    #[error(
        "instance class table has {got} bytes, instance_count {instance_count} needs {expected} \
         (instance_count + 1 u16 entries, entry 0 unused)"
    )]
    InstanceTableLength { got: u64, expected: u64, instance_count: u16 },
    #[error("instance class table at offset {offset} is not aligned to its u16 entries: place it at an even offset")]
    InstanceTableMisaligned { offset: u64 },
    #[error(
        "instance label fields disagree (has_labels {has_labels}, label_format {label_format}, instance_count \
         {instance_count}, instance class table {table_len} bytes): instance ids need has_labels = 1 and \
         label_format = 3; without them send instance_count = 0 and an empty table"
    )]
    InstanceLabelsInconsistent { has_labels: u8, label_format: u8, instance_count: u16, table_len: u64 },
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
            Self::InstanceTableMissing => InvalidReason::InstanceTableMissing,
            Self::InstanceTableLength { .. } => InvalidReason::InstanceTableLength,
            Self::InstanceTableMisaligned { .. } => InvalidReason::InstanceTableMisaligned,
            Self::InstanceLabelsInconsistent { .. } => InvalidReason::InstanceLabelsInconsistent,
        }
    }
}

/// Name of the instance class table in errors.
const TABLE: &str = "instance class table";

/// Bytes of one plane, bounds-checked.
fn plane_span<'a>(payload: &'a [u8], plane: &'static str, at: PlaneRef) -> Result<&'a [u8], FrameRejection> {
    if at.end() > payload.len() as u64 {
        return Err(FrameRejection::PlaneOutOfBounds {
            plane,
            offset: at.offset as u64,
            len: at.len as u64,
            payload_len: payload.len(),
        });
    }
    // Both fit in usize: end <= payload.len().
    Ok(&payload[at.offset as usize..at.end() as usize])
}

/// Bytes of one plane, bounds- and length-checked.
fn plane_bytes<'a>(
    payload: &'a [u8],
    plane: &'static str,
    at: PlaneRef,
    expected_len: u64,
) -> Result<&'a [u8], FrameRejection> {
    let bytes = plane_span(payload, plane, at)?;
    if at.len as u64 != expected_len {
        return Err(FrameRejection::PlaneLength { plane, got: at.len as u64, expected: expected_len });
    }
    Ok(bytes)
}

fn cast_plane<'a, T: bytemuck::Pod>(
    bytes: &'a [u8],
    plane: &'static str,
    offset: u32,
) -> Result<&'a [T], FrameRejection> {
    bytemuck::try_cast_slice(bytes).map_err(|_| FrameRejection::PlaneMisaligned {
        plane,
        offset: offset as u64,
        align: core::mem::align_of::<T>(),
    })
}

fn overlaps(a: PlaneRef, b: PlaneRef) -> bool {
    a.len > 0 && b.len > 0 && (a.offset as u64) < b.end() && (b.offset as u64) < a.end()
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
            LabelFormat::from_code(h.label_format, h.instance_count)
                .ok_or(FrameRejection::UnknownFormat { plane: "label", code: h.label_format })?,
        ),
        flag => return Err(FrameRejection::UnknownFormat { plane: "label flag", code: flag }),
    };
    // Instance fields only go with instance labels, and instance labels only with has_labels = 1.
    let instances = matches!(label_format, Some(LabelFormat::InstanceU16 { .. }));
    if (h.label_format == LABELS_INSTANCE_U16 && h.has_labels == 0)
        || (!instances && (h.instance_count != 0 || h.instance_classes.len != 0))
    {
        return Err(FrameRejection::InstanceLabelsInconsistent {
            has_labels: h.has_labels,
            label_format: h.label_format,
            instance_count: h.instance_count,
            table_len: h.instance_classes.len as u64,
        });
    }
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
    if instances && h.instance_classes.len == 0 {
        return Err(FrameRejection::InstanceTableMissing);
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
    if h.color == color
        && h.depth == depth
        && (label_format.is_none() || h.labels == labels)
        && h.instance_classes == standard.instance_classes()
    {
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
                LabelFormat::InstanceU16 { .. } => LabelData::Instances {
                    ids: cast_plane(bytes, "label", h.labels.offset)?,
                    classes: instance_table(payload, &h, format)?,
                },
            })
        }
    };
    Ok(FramePlanes { header: h, color_format, color, depth, labels })
}

/// The instance class table of an instance-label frame: in bounds, exactly
/// `instance_count + 1` u16 entries, aligned, disjoint from the other planes.
fn instance_table<'a>(payload: &'a [u8], h: &FrameHeader, format: LabelFormat) -> Result<&'a [u16], FrameRejection> {
    let at = h.instance_classes;
    let bytes = plane_span(payload, TABLE, at)?;
    let expected = format.instance_table_entries() as u64 * 2;
    if at.len as u64 != expected {
        return Err(FrameRejection::InstanceTableLength {
            got: at.len as u64,
            expected,
            instance_count: h.instance_count,
        });
    }
    let classes = bytemuck::try_cast_slice(bytes)
        .map_err(|_| FrameRejection::InstanceTableMisaligned { offset: at.offset as u64 })?;
    for (other, name) in [(h.color, "colour"), (h.depth, "depth"), (h.labels, "label")] {
        if overlaps(at, other) {
            return Err(FrameRejection::PlaneOverlap { a: TABLE, b: name });
        }
    }
    Ok(classes)
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
            // A version-2 producer (before instance labels) gets the version error, not a layout one.
            (FrameHeader { format_version: 2, ..good }, InvalidReason::VersionMismatch),
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
            (FrameHeader { color: PlaneRef { offset: u32::MAX, len: 45 }, ..good }, InvalidReason::PlaneOutOfBounds),
            (FrameHeader { color: PlaneRef { offset: 0, len: u32::MAX }, ..good }, InvalidReason::PlaneOutOfBounds),
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

    fn instance_layout() -> FrameLayout {
        FrameLayout {
            width: 5,
            height: 3,
            labels: Some(LabelFormat::InstanceU16 { max_instances: 3 }),
            ..small_layout()
        }
    }

    #[test]
    fn an_instance_frame_decodes_ids_and_class_table() {
        let layout = instance_layout();
        let mut buf = aligned_payload(layout.payload_len());
        let table = layout.instance_classes();
        {
            let bytes = bytemuck::cast_slice_mut::<u64, u8>(&mut buf);
            let t = table.offset as usize;
            bytes[t + 2..t + 8].copy_from_slice(&[4, 0, 4, 0, 9, 0]);
            let ids = layout.planes()[2].offset as usize;
            bytes[ids] = 2;
        }
        let bytes = &bytemuck::cast_slice::<u64, u8>(&buf)[..layout.payload_len()];
        let planes = decode_frame(&good_header(&layout), bytes, Some(7)).unwrap();
        match planes.labels {
            Some(LabelData::Instances { ids, classes }) => {
                assert_eq!(ids.len(), 15);
                assert_eq!(ids[0], 2);
                assert_eq!(classes, &[0, 4, 4, 9]);
            }
            other => panic!("expected instance labels, got {other:?}"),
        }
    }

    #[test]
    fn instance_label_faults_have_their_own_reasons() {
        let layout = instance_layout();
        let len = layout.payload_len();
        // 8 spare bytes so that a moved table can stay inside the payload.
        let buf = aligned_payload(len + 8);
        let bytes = &bytemuck::cast_slice::<u64, u8>(&buf)[..len + 8];
        let good = good_header(&layout);
        assert!(decode_frame(&good, bytes, Some(7)).is_ok());
        let table = good.instance_classes;
        let ids = good.labels;
        let class_frame = good_header(&small_layout());
        let cases: Vec<(FrameHeader, InvalidReason)> = vec![
            (FrameHeader { instance_classes: PlaneRef::default(), ..good }, InvalidReason::InstanceTableMissing),
            // Sized for the instances present (3 entries) instead of instance_count + 1 (4).
            (
                FrameHeader { instance_classes: PlaneRef { len: 6, ..table }, ..good },
                InvalidReason::InstanceTableLength,
            ),
            (FrameHeader { instance_count: 9, ..good }, InvalidReason::InstanceTableLength),
            (
                FrameHeader { instance_classes: PlaneRef { offset: table.offset + 1, ..table }, ..good },
                InvalidReason::InstanceTableMisaligned,
            ),
            (FrameHeader { has_labels: 0, ..good }, InvalidReason::InstanceLabelsInconsistent),
            (FrameHeader { instance_count: 2, ..class_frame }, InvalidReason::InstanceLabelsInconsistent),
            (FrameHeader { instance_classes: table, ..class_frame }, InvalidReason::InstanceLabelsInconsistent),
            (
                FrameHeader { instance_classes: PlaneRef { offset: len as u32 + 2, ..table }, ..good },
                InvalidReason::PlaneOutOfBounds,
            ),
            (
                FrameHeader { instance_classes: PlaneRef { offset: u32::MAX, ..table }, ..good },
                InvalidReason::PlaneOutOfBounds,
            ),
            (
                FrameHeader { instance_classes: PlaneRef { offset: ids.offset, ..table }, ..good },
                InvalidReason::PlaneOverlap,
            ),
            // The id plane is u16: an odd offset is misaligned like any plane.
            (
                FrameHeader { labels: PlaneRef { offset: ids.offset + 1, ..ids }, ..good },
                InvalidReason::PlaneMisaligned,
            ),
        ];
        for (header, reason) in cases {
            let got = decode_frame(&header, bytes, Some(7)).map(|_| ()).unwrap_err();
            assert_eq!(got.reason(), reason, "{header:?} gave {got}");
        }
        // Truncated under the standard instance layout: the table no longer fits.
        let got = decode_frame(&good, &bytes[..len - 1], Some(7)).map(|_| ()).unwrap_err();
        assert_eq!(got, FrameRejection::PayloadTruncated { got: len - 1, expected: len as u64 });
        // Without labels, label_format 1/2 stays ignored as in version 2.
        let none = good_header(&FrameLayout { labels: None, ..small_layout() });
        assert!(decode_frame(&FrameHeader { label_format: 2, ..none }, bytes, Some(7)).is_ok());
    }

    #[test]
    fn random_headers_never_panic_or_escape_the_slice() {
        for layout in [small_layout(), instance_layout()] {
            let buf = aligned_payload(layout.payload_len());
            let bytes = &bytemuck::cast_slice::<u64, u8>(&buf)[..layout.payload_len()];
            let mut state = 0x9E37_79B9_7F4A_7C15u64;
            let mut next = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                state as u32
            };
            let good = good_header(&layout);
            let mut decoded = 0;
            for _ in 0..20_000 {
                let mut h = good;
                match next() % 8 {
                    0 => h.color = PlaneRef { offset: next() % 128, len: next() % 128 },
                    1 => h.depth = PlaneRef { offset: next() % 128, len: next() % 64 },
                    2 => h.labels = PlaneRef { offset: next(), len: next() },
                    3 => (h.width, h.height) = (next() % 8, next() % 8),
                    4 => (h.depth_format, h.label_format) = ((next() % 4) as u8, (next() % 4) as u8),
                    5 => h.instance_classes = PlaneRef { offset: next() % 160, len: next() % 16 },
                    6 => (h.has_labels, h.instance_count) = ((next() % 3) as u8, (next() % 6) as u16),
                    _ => h.depth.offset = next() % 100,
                }
                let Ok(planes) = decode_frame(&h, bytes, None) else { continue };
                decoded += 1;
                let base = bytes.as_ptr() as usize;
                let end = base + bytes.len();
                let inside = |p: *const u8, n: usize| p as usize >= base && p as usize + n <= end;
                assert!(inside(planes.color.as_ptr(), planes.color.len()));
                match planes.depth {
                    DepthData::U16 { data, .. } => assert!(inside(data.as_ptr().cast(), data.len() * 2)),
                    DepthData::F32(data) => assert!(inside(data.as_ptr().cast(), data.len() * 4)),
                }
                if let Some(LabelData::Instances { ids, classes }) = planes.labels {
                    assert!(inside(ids.as_ptr().cast(), ids.len() * 2));
                    assert!(inside(classes.as_ptr().cast(), classes.len() * 2));
                    assert_eq!(classes.len(), h.instance_count as usize + 1);
                }
            }
            assert!(decoded > 200, "{decoded} of 20000 mutated headers decoded");
        }
    }
}
