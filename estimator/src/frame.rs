//! A borrowed view of one RGB-D frame and its validation.
//!
//! Every frame that reaches the estimator comes from another process (shared
//! memory), a dataset or the renderer, so [`FrameView::validate`] checks
//! everything the rest of the crate relies on before any pixel is read: image
//! size, intrinsics, plane lengths and the depth scale. Each failure is a
//! distinct [`FrameError`] variant with a stable [`FrameError::reason_code`].

use fusepose_scene::Intrinsics;

/// Largest accepted image side, pixels.
pub const MAX_IMAGE_SIDE: u32 = 4096;

/// Accepted focal lengths fx, fy, pixels (the same range as the wire decoder's
/// `fusepose_client::FOCAL_RANGE_PX`). Outside it, e.g. fx = 1e-300,
/// back-projected points land at infinity and every pose is non-finite.
pub const FOCAL_RANGE_PX: core::ops::RangeInclusive<f64> = 1.0..=1.0e6;

/// What a depth plane holds, counted in one pass (see [`DepthPlane::census`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct DepthCensus {
    /// Finite, positive readings.
    pub valid: usize,
    /// NaN or infinite values (f32 depth only).
    pub non_finite: usize,
}

/// Byte order of the colour plane (3 bytes per pixel, row-major).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ColorFormat {
    Rgb8,
    Bgr8,
}

/// The depth plane: u16 units times `scale` metres (0 = no measurement), or f32 metres
/// (0, NaN or infinity = no measurement).
#[derive(Clone, Copy, Debug)]
pub enum DepthPlane<'a> {
    U16 { data: &'a [u16], scale: f32 },
    F32(&'a [f32]),
}

impl DepthPlane<'_> {
    /// Number of values in the plane.
    pub fn len(&self) -> usize {
        match self {
            DepthPlane::U16 { data, .. } => data.len(),
            DepthPlane::F32(data) => data.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Depth of value `index` in metres, `None` when there is no valid
    /// measurement (0, negative, NaN, infinity) or the index is out of range.
    #[inline]
    pub fn metres(&self, index: usize) -> Option<f32> {
        let z = match self {
            DepthPlane::U16 { data, scale } => *data.get(index)? as f32 * *scale,
            DepthPlane::F32(data) => *data.get(index)?,
        };
        (z.is_finite() && z > 0.0).then_some(z)
    }

    /// Counts valid readings and NaN/infinite values.
    pub fn census(&self) -> DepthCensus {
        match self {
            DepthPlane::U16 { data, .. } => {
                DepthCensus { valid: data.iter().filter(|&&d| d != 0).count(), non_finite: 0 }
            }
            DepthPlane::F32(data) => data.iter().fold(DepthCensus::default(), |mut c, &z| {
                c.valid += (z.is_finite() && z > 0.0) as usize;
                c.non_finite += (!z.is_finite()) as usize;
                c
            }),
        }
    }
}

/// Per-pixel labels (0 = background): class ids, or instance ids with their classes.
#[derive(Clone, Copy, Debug)]
pub enum LabelPlane<'a> {
    /// Class ids.
    U8(&'a [u8]),
    /// Class ids.
    U16(&'a [u16]),
    /// Instance ids per pixel (0 = background) and the instance class table:
    /// `classes[id]` is the class id of instance `id` (index 0 unused). Each
    /// instance id is one object instance (see [`crate::instances`]).
    Instances { ids: &'a [u16], classes: &'a [u16] },
}

impl LabelPlane<'_> {
    /// Number of values in the plane.
    pub fn len(&self) -> usize {
        match self {
            LabelPlane::U8(data) => data.len(),
            LabelPlane::U16(data) => data.len(),
            LabelPlane::Instances { ids, .. } => ids.len(),
        }
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether the plane holds instance ids.
    pub fn is_instances(&self) -> bool {
        matches!(self, LabelPlane::Instances { .. })
    }

    /// Largest class id in the plane (0 for an empty or all-background plane).
    pub fn max_class(&self) -> u16 {
        match self {
            LabelPlane::U8(data) => data.iter().copied().max().unwrap_or(0) as u16,
            LabelPlane::U16(data) => data.iter().copied().max().unwrap_or(0),
            LabelPlane::Instances { .. } => (0..self.len()).map(|i| self.class_at(i)).max().unwrap_or(0),
        }
    }

    /// Class id of value `index` (0 = background, also for an out-of-range
    /// index and for an instance id without a table entry).
    #[inline]
    pub fn class_at(&self, index: usize) -> u16 {
        match self {
            LabelPlane::U8(data) => data.get(index).map_or(0, |&c| c as u16),
            LabelPlane::U16(data) => data.get(index).copied().unwrap_or(0),
            LabelPlane::Instances { ids, classes } => {
                ids.get(index).and_then(|&id| classes.get(id as usize)).copied().unwrap_or(0)
            }
        }
    }
}

/// One RGB-D frame, borrowed (from shared memory, a dataset, or the renderer).
///
/// The image size is `intrinsics.width` x `intrinsics.height`; all planes are
/// row-major, top row first.
#[derive(Clone, Copy, Debug)]
pub struct FrameView<'a> {
    pub intrinsics: Intrinsics,
    pub color_format: ColorFormat,
    /// width * height * 3 bytes.
    pub color: &'a [u8],
    /// width * height values.
    pub depth: DepthPlane<'a>,
    /// width * height values, when the producer supplies labels.
    pub labels: Option<LabelPlane<'a>>,
}

impl FrameView<'_> {
    /// Image width in pixels.
    pub fn width(&self) -> usize {
        self.intrinsics.width as usize
    }

    /// Image height in pixels.
    pub fn height(&self) -> usize {
        self.intrinsics.height as usize
    }

    /// Checks everything later stages rely on; never panics.
    ///
    /// Accepted: width and height in 1..=[`MAX_IMAGE_SIDE`]; fx, fy in
    /// [`FOCAL_RANGE_PX`]; cx in [-0.5 w, 1.5 w] and cy in [-0.5 h, 1.5 h] (and
    /// finite); colour plane w*h*3 bytes; depth and (when present) label
    /// planes w*h values; a u16 depth scale finite and positive (metres per unit).
    pub fn validate(&self) -> Result<(), FrameError> {
        let k = &self.intrinsics;
        if k.width == 0 || k.height == 0 || k.width > MAX_IMAGE_SIDE || k.height > MAX_IMAGE_SIDE {
            return Err(FrameError::BadSize { width: k.width, height: k.height });
        }
        // RangeInclusive::contains is false for NaN.
        if !(FOCAL_RANGE_PX.contains(&k.fx) && FOCAL_RANGE_PX.contains(&k.fy)) {
            return Err(FrameError::BadFocalLength { fx: k.fx, fy: k.fy });
        }
        let (w, h) = (k.width as f64, k.height as f64);
        let cx_ok = k.cx.is_finite() && k.cx >= -0.5 * w && k.cx <= 1.5 * w;
        let cy_ok = k.cy.is_finite() && k.cy >= -0.5 * h && k.cy <= 1.5 * h;
        if !(cx_ok && cy_ok) {
            return Err(FrameError::BadPrincipalPoint { cx: k.cx, cy: k.cy });
        }
        let pixels = k.width as usize * k.height as usize;
        if self.color.len() != pixels * 3 {
            return Err(FrameError::PlaneSize { plane: "color", got: self.color.len(), expected: pixels * 3 });
        }
        if self.depth.len() != pixels {
            return Err(FrameError::PlaneSize { plane: "depth", got: self.depth.len(), expected: pixels });
        }
        if let DepthPlane::U16 { scale, .. } = self.depth
            && !(scale.is_finite() && scale > 0.0)
        {
            return Err(FrameError::BadDepthScale(scale));
        }
        if let Some(labels) = &self.labels
            && labels.len() != pixels
        {
            return Err(FrameError::PlaneSize { plane: "labels", got: labels.len(), expected: pixels });
        }
        Ok(())
    }

    /// Checks the plane contents (one pass over depth and labels; call after
    /// [`FrameView::validate`]): at least one depth reading, and no label id
    /// above `num_classes` (0 = any id). For instance planes: every instance
    /// id has a table entry, and every instance present has a class in
    /// 1..=`num_classes` (class 0 is refused even when `num_classes` is 0).
    /// Frames failing these are not malformed but carry nothing a pose could
    /// come from, or a label map that does not match the object set.
    /// Never allocates.
    pub fn check_content(&self, num_classes: u16) -> Result<DepthCensus, FrameError> {
        let census = self.depth.census();
        if census.valid == 0 {
            return Err(if census.non_finite > 0 {
                FrameError::DepthNonFinite { values: census.non_finite }
            } else {
                FrameError::DepthEmpty
            });
        }
        match &self.labels {
            Some(LabelPlane::Instances { ids, classes }) => {
                check_instances(ids, classes, self.width(), num_classes)?;
            }
            Some(labels) if num_classes != 0 => {
                let max = labels.max_class();
                if max > num_classes {
                    return Err(FrameError::LabelOutOfRange { max, num_classes });
                }
            }
            _ => {}
        }
        Ok(census)
    }
}

/// The instance checks of [`FrameView::check_content`]; the first bad pixel in raster order is reported.
fn check_instances(ids: &[u16], classes: &[u16], width: usize, num_classes: u16) -> Result<(), FrameError> {
    let at = |p: usize| (p % width.max(1), p / width.max(1));
    for (p, &id) in ids.iter().enumerate() {
        if id == 0 {
            continue;
        }
        let Some(&class) = classes.get(id as usize) else {
            let (u, v) = at(p);
            return Err(FrameError::InstanceBeyondTable { id, entries: classes.len(), u, v });
        };
        if class == 0 || (num_classes != 0 && class > num_classes) {
            let (u, v) = at(p);
            return Err(FrameError::InstanceClassUnknown { id, class, num_classes, u, v });
        }
    }
    Ok(())
}

/// Why a frame was refused. Each variant is a distinct reason for stats; see
/// [`FrameError::reason_code`] and [`FrameError::reason`].
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FrameError {
    #[error("image size {width}x{height} is outside 1..=4096")]
    BadSize { width: u32, height: u32 },
    /// Intrinsics inconsistent in a way not covered by a more specific variant.
    #[error("intrinsics invalid: {0}")]
    BadIntrinsics(&'static str),
    #[error("focal length fx={fx}, fy={fy} is not a finite number of pixels in {:?}", FOCAL_RANGE_PX)]
    BadFocalLength { fx: f64, fy: f64 },
    #[error("principal point ({cx}, {cy}) lies outside [-0.5, 1.5] x the image size")]
    BadPrincipalPoint { cx: f64, cy: f64 },
    #[error("{plane} plane has {got} values, expected {expected}")]
    PlaneSize { plane: &'static str, got: usize, expected: usize },
    #[error("depth scale {0} is not a positive finite number")]
    BadDepthScale(f32),
    /// The frame carries no label plane but the call needs one.
    #[error("frame has no label plane")]
    MissingLabels,
    /// No depth reading at all (every value 0, or negative for f32 depth).
    #[error("the depth plane holds no reading (all zero)")]
    DepthEmpty,
    /// No depth reading at all, and NaN/infinite values among them.
    #[error("the depth plane holds no reading ({values} NaN/infinite values)")]
    DepthNonFinite { values: usize },
    /// A label id above the object set's number of classes.
    #[error("label id {max} exceeds the {num_classes} object classes")]
    LabelOutOfRange { max: u16, num_classes: u16 },
    /// An instance id with no entry in the instance class table.
    #[error(
        "instance id {id} at pixel ({u}, {v}) has no entry in the {entries}-entry instance class table: \
         send instance_count >= {id} and the instance's class"
    )]
    InstanceBeyondTable { id: u16, entries: usize, u: usize, v: usize },
    /// An instance whose class is 0 or above the object set's number of classes.
    #[error(
        "instance {id} at pixel ({u}, {v}) has class {class}, not one of the object classes 1..={num_classes} \
         (0 = any): set its class table entry to the object's class id"
    )]
    InstanceClassUnknown { id: u16, class: u16, num_classes: u16, u: usize, v: usize },
}

impl FrameError {
    /// Stable numeric code per variant (never reused or renumbered), for the
    /// daemon's counters and the wire. 0 is reserved for "no error".
    pub fn reason_code(&self) -> u16 {
        match self {
            FrameError::BadSize { .. } => 1,
            FrameError::BadIntrinsics(_) => 2,
            FrameError::BadFocalLength { .. } => 3,
            FrameError::BadPrincipalPoint { .. } => 4,
            FrameError::PlaneSize { .. } => 5,
            FrameError::BadDepthScale(_) => 6,
            FrameError::MissingLabels => 7,
            FrameError::DepthEmpty => 8,
            FrameError::DepthNonFinite { .. } => 9,
            FrameError::LabelOutOfRange { .. } => 10,
            FrameError::InstanceBeyondTable { .. } => 11,
            FrameError::InstanceClassUnknown { .. } => 12,
        }
    }

    /// Stable short snake_case name per variant, for logs and stats tables.
    pub fn reason(&self) -> &'static str {
        match self {
            FrameError::BadSize { .. } => "bad_size",
            FrameError::BadIntrinsics(_) => "bad_intrinsics",
            FrameError::BadFocalLength { .. } => "bad_focal_length",
            FrameError::BadPrincipalPoint { .. } => "bad_principal_point",
            FrameError::PlaneSize { .. } => "plane_size",
            FrameError::BadDepthScale(_) => "bad_depth_scale",
            FrameError::MissingLabels => "missing_labels",
            FrameError::DepthEmpty => "depth_empty",
            FrameError::DepthNonFinite { .. } => "depth_non_finite",
            FrameError::LabelOutOfRange { .. } => "label_out_of_range",
            FrameError::InstanceBeyondTable { .. } => "instance_beyond_table",
            FrameError::InstanceClassUnknown { .. } => "instance_class_unknown",
        }
    }
}

/// A `w` x `h` view of `colour` and metric `depth`, without labels, seen
/// through a 500-pixel focal length centred on the image: the frame the
/// colour stages' unit tests ([`crate::exposure`], [`crate::white_balance`]) run on.
#[cfg(test)]
pub(crate) fn test_view<'a>(
    colour: &'a [u8],
    depth: &'a [f32],
    w: usize,
    h: usize,
    format: ColorFormat,
) -> FrameView<'a> {
    FrameView {
        intrinsics: Intrinsics {
            fx: 500.0,
            fy: 500.0,
            cx: w as f64 / 2.0,
            cy: h as f64 / 2.0,
            width: w as u32,
            height: h as u32,
        },
        color_format: format,
        color: colour,
        depth: DepthPlane::F32(depth),
        labels: None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const W: u32 = 8;
    const H: u32 = 6;

    fn intrinsics() -> Intrinsics {
        Intrinsics { fx: 500.0, fy: 500.0, cx: 4.0, cy: 3.0, width: W, height: H }
    }

    struct Planes {
        color: Vec<u8>,
        depth: Vec<u16>,
        labels: Vec<u8>,
    }

    fn planes() -> Planes {
        let n = (W * H) as usize;
        Planes { color: vec![0; n * 3], depth: vec![1000; n], labels: vec![0; n] }
    }

    fn frame(p: &Planes) -> FrameView<'_> {
        FrameView {
            intrinsics: intrinsics(),
            color_format: ColorFormat::Rgb8,
            color: &p.color,
            depth: DepthPlane::U16 { data: &p.depth, scale: 0.001 },
            labels: Some(LabelPlane::U8(&p.labels)),
        }
    }

    #[test]
    fn good_frame_passes() {
        let p = planes();
        assert_eq!(frame(&p).validate(), Ok(()));
    }

    #[test]
    fn zero_and_oversized_sizes_are_refused() {
        let p = planes();
        for (w, h) in [(0, H), (W, 0), (4097, H), (W, 5000)] {
            let mut f = frame(&p);
            f.intrinsics.width = w;
            f.intrinsics.height = h;
            assert_eq!(f.validate(), Err(FrameError::BadSize { width: w, height: h }));
        }
    }

    #[test]
    fn bad_focal_lengths_are_refused() {
        let p = planes();
        // 1e-300 and 0.5 are positive and finite but absurd (points at infinity).
        for (fx, fy) in [
            (0.0, 500.0),
            (500.0, -1.0),
            (f64::NAN, 500.0),
            (500.0, f64::INFINITY),
            (1e-300, 500.0),
            (500.0, 0.5),
            (2e6, 500.0),
        ] {
            let mut f = frame(&p);
            f.intrinsics.fx = fx;
            f.intrinsics.fy = fy;
            let e = f.validate().unwrap_err();
            assert!(matches!(e, FrameError::BadFocalLength { .. }), "{fx} {fy}: {e:?}");
            assert_eq!(e.reason_code(), 3);
        }
    }

    #[test]
    fn principal_point_far_outside_is_refused() {
        let p = planes();
        // In range at the edges of the accepted band.
        let mut f = frame(&p);
        f.intrinsics.cx = -0.5 * W as f64;
        f.intrinsics.cy = 1.5 * H as f64;
        assert_eq!(f.validate(), Ok(()));
        for (cx, cy) in [(-4.1, 3.0), (12.1, 3.0), (4.0, -3.1), (4.0, 9.1), (f64::NAN, 3.0)] {
            let mut f = frame(&p);
            f.intrinsics.cx = cx;
            f.intrinsics.cy = cy;
            assert!(matches!(f.validate(), Err(FrameError::BadPrincipalPoint { .. })), "{cx} {cy}");
        }
    }

    #[test]
    fn plane_size_mismatches_name_the_plane() {
        let mut p = planes();
        p.color.pop();
        assert_eq!(frame(&p).validate(), Err(FrameError::PlaneSize { plane: "color", got: 143, expected: 144 }));
        let mut p = planes();
        p.depth.push(0);
        assert_eq!(frame(&p).validate(), Err(FrameError::PlaneSize { plane: "depth", got: 49, expected: 48 }));
        let mut p = planes();
        p.labels.clear();
        assert_eq!(frame(&p).validate(), Err(FrameError::PlaneSize { plane: "labels", got: 0, expected: 48 }));
        // A frame without labels is valid by itself.
        let p = planes();
        let mut f = frame(&p);
        f.labels = None;
        assert_eq!(f.validate(), Ok(()));
    }

    #[test]
    fn bad_depth_scales_are_refused() {
        let p = planes();
        for scale in [0.0, -0.001, f32::NAN, f32::INFINITY] {
            let mut f = frame(&p);
            f.depth = DepthPlane::U16 { data: &p.depth, scale };
            assert!(matches!(f.validate(), Err(FrameError::BadDepthScale(_))), "{scale}");
        }
    }

    #[test]
    fn reason_codes_are_distinct_and_stable() {
        let all = [
            FrameError::BadSize { width: 0, height: 0 },
            FrameError::BadIntrinsics("x"),
            FrameError::BadFocalLength { fx: 0.0, fy: 0.0 },
            FrameError::BadPrincipalPoint { cx: 0.0, cy: 0.0 },
            FrameError::PlaneSize { plane: "color", got: 0, expected: 1 },
            FrameError::BadDepthScale(0.0),
            FrameError::MissingLabels,
            FrameError::DepthEmpty,
            FrameError::DepthNonFinite { values: 1 },
            FrameError::LabelOutOfRange { max: 9, num_classes: 3 },
            FrameError::InstanceBeyondTable { id: 5, entries: 3, u: 0, v: 0 },
            FrameError::InstanceClassUnknown { id: 1, class: 0, num_classes: 3, u: 0, v: 0 },
        ];
        let codes: Vec<u16> = all.iter().map(FrameError::reason_code).collect();
        assert_eq!(codes, vec![1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
        let mut names: Vec<&str> = all.iter().map(FrameError::reason).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), all.len());
    }

    #[test]
    fn content_checks_refuse_empty_depth_and_unknown_labels() {
        let p = planes();
        assert_eq!(frame(&p).check_content(3), Ok(DepthCensus { valid: 48, non_finite: 0 }));
        let mut empty = planes();
        empty.depth.fill(0);
        assert_eq!(frame(&empty).check_content(3), Err(FrameError::DepthEmpty));
        // f32 depth: all NaN/inf is its own reason; some NaN among readings are holes.
        let nan = vec![f32::NAN; 48];
        let mut f = frame(&p);
        f.depth = DepthPlane::F32(&nan);
        assert_eq!(f.check_content(3), Err(FrameError::DepthNonFinite { values: 48 }));
        let mut mixed = vec![0.8f32; 48];
        mixed[..10].fill(f32::INFINITY);
        mixed[10] = f32::NAN;
        f.depth = DepthPlane::F32(&mixed);
        assert_eq!(f.check_content(3), Ok(DepthCensus { valid: 37, non_finite: 11 }));
        // Label ids up to num_classes pass; one pixel above is refused; 0 = no limit.
        let mut labelled = planes();
        labelled.labels[5] = 3;
        assert!(frame(&labelled).check_content(3).is_ok());
        labelled.labels[7] = 4;
        assert_eq!(frame(&labelled).check_content(3), Err(FrameError::LabelOutOfRange { max: 4, num_classes: 3 }));
        assert!(frame(&labelled).check_content(0).is_ok());
    }

    #[test]
    fn instance_planes_give_classes_and_their_own_content_errors() {
        let p = planes();
        let mut ids = vec![0u16; 48];
        ids[9] = 1; // (1, 1)
        ids[10] = 2; // (2, 1)
        let classes = [0u16, 3, 3];
        let mut f = frame(&p);
        f.labels = Some(LabelPlane::Instances { ids: &ids, classes: &classes });
        let labels = f.labels.unwrap();
        assert!(labels.is_instances());
        assert_eq!((labels.class_at(9), labels.class_at(10), labels.class_at(0), labels.class_at(99)), (3, 3, 0, 0));
        assert_eq!(labels.max_class(), 3);
        assert_eq!(f.validate(), Ok(()));
        assert!(f.check_content(3).is_ok());
        // Class 3 is beyond a 2-class object set; with no limit (0) it passes.
        assert_eq!(
            f.check_content(2),
            Err(FrameError::InstanceClassUnknown { id: 1, class: 3, num_classes: 2, u: 1, v: 1 })
        );
        assert!(f.check_content(0).is_ok());
        // An instance without a class (entry 0) is refused even without a limit.
        let no_class = [0u16, 3, 0];
        f.labels = Some(LabelPlane::Instances { ids: &ids, classes: &no_class });
        assert_eq!(
            f.check_content(0),
            Err(FrameError::InstanceClassUnknown { id: 2, class: 0, num_classes: 0, u: 2, v: 1 })
        );
        // An id past the table.
        let mut past = ids.clone();
        past[20] = 7; // (4, 2)
        f.labels = Some(LabelPlane::Instances { ids: &past, classes: &classes });
        assert_eq!(f.check_content(3), Err(FrameError::InstanceBeyondTable { id: 7, entries: 3, u: 4, v: 2 }));
        assert_eq!(f.labels.unwrap().class_at(20), 0);
        // The id plane is checked for its size like any label plane.
        f.labels = Some(LabelPlane::Instances { ids: &ids[1..], classes: &classes });
        assert_eq!(f.validate(), Err(FrameError::PlaneSize { plane: "labels", got: 47, expected: 48 }));
    }

    #[test]
    fn depth_metres_rejects_invalid_values() {
        let d = [0u16, 1500];
        let plane = DepthPlane::U16 { data: &d, scale: 0.001 };
        assert_eq!(plane.metres(0), None);
        assert!((plane.metres(1).unwrap() - 1.5).abs() < 1e-6);
        assert_eq!(plane.metres(2), None);
        let f = [0.7f32, f32::NAN, -1.0, f32::INFINITY, 0.0];
        let plane = DepthPlane::F32(&f);
        assert_eq!(plane.metres(0), Some(0.7));
        for i in 1..5 {
            assert_eq!(plane.metres(i), None);
        }
    }
}
