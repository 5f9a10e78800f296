//! Pose wire format: one fixed-size `#[repr(C)]` message per processed frame.

use iceoryx2::prelude::ZeroCopySend;

/// Most object poses one message carries.
pub const MAX_OBJECTS: usize = 32;

/// One object's pose in the camera optical frame (88 bytes, no padding).
///
/// Entries of [`PoseMessage::objects`] beyond `object_count` are all zero.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("fusepose::WireObjectPose")]
pub struct WireObjectPose {
    /// Class id in the daemon's object set (1-based).
    pub class_id: u16,
    /// Index of the instance among this frame's instances (0-based, largest
    /// mask first); in tracking mode an id that stays with its object while
    /// it is in view. See `docs/PROTOCOL.md`, "Poses".
    pub instance_id: u16,
    /// ICP iterations, or refiner iterations of the network.
    pub refine_iterations: u16,
    /// [`PoseFlags`] bits.
    pub flags: u16,
    /// Estimator confidence in [0, 1].
    pub confidence: f32,
    /// Pixels of the instance mask.
    pub mask_pixels: u32,
    /// [u_min, v_min, u_max, v_max] inclusive, pixels.
    pub bbox: [u16; 4],
    /// Rotation object → camera, unit quaternion `[x, y, z, w]`.
    pub quaternion: [f64; 4],
    /// Translation object → camera, metres.
    pub translation_m: [f64; 3],
    /// How well the pose explains the observed depth and mask, 0..1 (1 =
    /// perfectly); NaN when the pose was not verified.
    pub fit_score: f32,
    /// Median absolute depth residual over the visible model surface, metres;
    /// NaN when the pose was not verified.
    pub depth_residual_m: f32,
}

const _: () = assert!(core::mem::size_of::<WireObjectPose>() == 88);
const _: () = assert!(core::mem::align_of::<WireObjectPose>() == 8);

/// Bits of [`WireObjectPose::flags`] (the other bits are 0).
pub struct PoseFlags;

impl PoseFlags {
    /// The pose passed the daemon's verification. (`fit_score` and
    /// `depth_residual_m` hold the result whenever verification ran, passed
    /// or not; NaN when it did not run.)
    pub const VERIFIED: u16 = 1 << 0;
    /// The object's mask came from the frame's own instance-label plane
    /// (label format 3), not from class labels or the built-in segmenter.
    pub const FROM_INSTANCE_LABELS: u16 = 1 << 1;
    /// A pose of the same class lay within `estimator.confirm_within_m`
    /// (default 1 cm) of this one in the camera's previous processed frame
    /// that looked at its class (frames that shed an instance of the class
    /// to keep their deadline are skipped), in the camera frame: the pose
    /// was seen twice in a row.
    pub const CONFIRMED: u16 = 1 << 2;
}

impl WireObjectPose {
    pub fn is_verified(&self) -> bool {
        self.flags & PoseFlags::VERIFIED != 0
    }

    pub fn is_confirmed(&self) -> bool {
        self.flags & PoseFlags::CONFIRMED != 0
    }
}

/// Bits of [`PoseMessage::status`].
pub struct PoseStatus;

impl PoseStatus {
    /// The estimator ran and the poses are valid.
    pub const OK: u32 = 1 << 0;
    /// The frame was rejected; see [`PoseMessage::invalid_reason`]. No objects.
    pub const INVALID_FRAME: u32 = 1 << 1;
    /// Published later than the configured deadline after capture.
    pub const DEADLINE_MISSED: u32 = 1 << 2;
    /// Results are usable but reduced (more instances than fit, an estimator error on some objects,
    /// or fewer refiner iterations / points than configured to meet the deadline; see each object's
    /// `refine_iterations`).
    pub const DEGRADED: u32 = 1 << 3;
    /// The estimator failed on this frame (no objects), or returned a
    /// non-finite pose (dropped; see `StatsSnapshot::poses_non_finite`).
    pub const ESTIMATOR_FAILED: u32 = 1 << 4;
}

/// Why a frame was rejected (wire code in [`PoseMessage::invalid_reason`], index in stats).
///
/// Codes are never reused or renumbered; new reasons are appended (and bump
/// [`crate::WIRE_VERSION`], since the stats array grows).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum InvalidReason {
    None = 0,
    BadMagic = 1,
    VersionMismatch = 2,
    HeaderSize = 3,
    BadSize = 4,
    UnknownFormat = 5,
    /// fx or fy zero, negative, NaN, infinite or outside the sane pixel range.
    BadFocalLength = 6,
    BadDepthScale = 7,
    PlaneOutOfBounds = 8,
    PlaneLength = 9,
    PlaneMisaligned = 10,
    PlaneOverlap = 11,
    WrongCamera = 12,
    EstimatorRefused = 13,
    /// cx or cy non-finite or far outside the image.
    BadPrincipalPoint = 14,
    /// The header describes the standard plane layout but the payload ends before it.
    PayloadTruncated = 15,
    /// `has_labels = 1` but the label plane is empty.
    LabelsMissing = 16,
    /// Not one depth reading in the frame (all zero).
    DepthEmpty = 17,
    /// Not one depth reading in the frame, NaN/infinite values among them (f32 depth).
    DepthNonFinite = 18,
    /// A label id larger than the daemon's number of object classes.
    LabelOutOfRange = 19,
    /// Sequence number not larger than the previous one from the same publisher.
    SequenceRegression = 20,
    /// Capture time later than the daemon's clock.
    CaptureInFuture = 21,
    /// Capture time too far in the past to be worth a pose.
    CaptureTooOld = 22,
    /// Label format 3 (instance ids) without an instance class table.
    InstanceTableMissing = 23,
    /// The instance class table is not `instance_count + 1` u16 entries long.
    InstanceTableLength = 24,
    /// The instance class table starts at an odd offset.
    InstanceTableMisaligned = 25,
    /// Label format 3 with `has_labels = 0`, or an instance count / class
    /// table on a frame without instance labels.
    InstanceLabelsInconsistent = 26,
    /// A pixel's instance id is larger than `instance_count` (no table entry).
    InstanceBeyondTable = 27,
    /// An instance in the plane has class 0 or a class id larger than the
    /// daemon's number of object classes.
    InstanceClassUnknown = 28,
}

impl InvalidReason {
    /// Number of codes (size of per-reason counters).
    pub const COUNT: usize = 29;

    pub const ALL: [InvalidReason; Self::COUNT] = [
        Self::None,
        Self::BadMagic,
        Self::VersionMismatch,
        Self::HeaderSize,
        Self::BadSize,
        Self::UnknownFormat,
        Self::BadFocalLength,
        Self::BadDepthScale,
        Self::PlaneOutOfBounds,
        Self::PlaneLength,
        Self::PlaneMisaligned,
        Self::PlaneOverlap,
        Self::WrongCamera,
        Self::EstimatorRefused,
        Self::BadPrincipalPoint,
        Self::PayloadTruncated,
        Self::LabelsMissing,
        Self::DepthEmpty,
        Self::DepthNonFinite,
        Self::LabelOutOfRange,
        Self::SequenceRegression,
        Self::CaptureInFuture,
        Self::CaptureTooOld,
        Self::InstanceTableMissing,
        Self::InstanceTableLength,
        Self::InstanceTableMisaligned,
        Self::InstanceLabelsInconsistent,
        Self::InstanceBeyondTable,
        Self::InstanceClassUnknown,
    ];

    pub fn from_code(code: u32) -> Option<Self> {
        Self::ALL.get(code as usize).copied()
    }

    /// snake_case name for logs, tables and JSON.
    pub fn name(self) -> &'static str {
        match self {
            Self::None => "none",
            Self::BadMagic => "bad_magic",
            Self::VersionMismatch => "version_mismatch",
            Self::HeaderSize => "header_size",
            Self::BadSize => "bad_size",
            Self::UnknownFormat => "unknown_format",
            Self::BadFocalLength => "bad_focal_length",
            Self::BadDepthScale => "bad_depth_scale",
            Self::PlaneOutOfBounds => "plane_out_of_bounds",
            Self::PlaneLength => "plane_length",
            Self::PlaneMisaligned => "plane_misaligned",
            Self::PlaneOverlap => "plane_overlap",
            Self::WrongCamera => "wrong_camera",
            Self::EstimatorRefused => "estimator_refused",
            Self::BadPrincipalPoint => "bad_principal_point",
            Self::PayloadTruncated => "payload_truncated",
            Self::LabelsMissing => "labels_missing",
            Self::DepthEmpty => "depth_empty",
            Self::DepthNonFinite => "depth_non_finite",
            Self::LabelOutOfRange => "label_out_of_range",
            Self::SequenceRegression => "sequence_regression",
            Self::CaptureInFuture => "capture_in_future",
            Self::CaptureTooOld => "capture_too_old",
            Self::InstanceTableMissing => "instance_table_missing",
            Self::InstanceTableLength => "instance_table_length",
            Self::InstanceTableMisaligned => "instance_table_misaligned",
            Self::InstanceLabelsInconsistent => "instance_labels_inconsistent",
            Self::InstanceBeyondTable => "instance_beyond_table",
            Self::InstanceClassUnknown => "instance_class_unknown",
        }
    }
}

/// The poses of one frame, published on `fusepose/camera/<name>/poses`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("fusepose::PoseMessage")]
pub struct PoseMessage {
    /// [`crate::WIRE_VERSION`].
    pub format_version: u16,
    /// Valid entries at the start of `objects`.
    pub object_count: u16,
    /// [`PoseStatus`] bits.
    pub status: u32,
    /// [`InvalidReason`] code when `status` has [`PoseStatus::INVALID_FRAME`], else 0.
    pub invalid_reason: u32,
    pub camera_id: u32,
    /// Sequence number of the frame these poses belong to.
    pub frame_sequence: u64,
    /// Frame capture time (from the frame header), `CLOCK_MONOTONIC` ns.
    pub capture_time_ns: u64,
    /// When the daemon took the frame from shared memory.
    pub received_time_ns: u64,
    /// When the daemon published this message.
    pub published_time_ns: u64,
    /// Duration of each [`crate::Stage`] (ingest … publish) for this frame, ns; 0 = stage not run.
    pub stage_ns: [u64; 6],
    pub objects: [WireObjectPose; MAX_OBJECTS],
}

const _: () = assert!(core::mem::size_of::<PoseMessage>() == 2912);

impl Default for PoseMessage {
    fn default() -> Self {
        Self {
            format_version: crate::WIRE_VERSION,
            object_count: 0,
            status: 0,
            invalid_reason: 0,
            camera_id: 0,
            frame_sequence: 0,
            capture_time_ns: 0,
            received_time_ns: 0,
            published_time_ns: 0,
            stage_ns: [0; 6],
            objects: [WireObjectPose::default(); MAX_OBJECTS],
        }
    }
}

impl PoseMessage {
    /// The valid object poses (`object_count` clamped to [`MAX_OBJECTS`]).
    pub fn objects(&self) -> &[WireObjectPose] {
        &self.objects[..(self.object_count as usize).min(MAX_OBJECTS)]
    }

    pub fn is_ok(&self) -> bool {
        self.status & PoseStatus::OK != 0
    }

    /// The rejection reason, when the frame was rejected.
    pub fn invalid(&self) -> Option<InvalidReason> {
        if self.status & PoseStatus::INVALID_FRAME == 0 {
            return None;
        }
        Some(InvalidReason::from_code(self.invalid_reason).unwrap_or(InvalidReason::None))
    }

    /// Capture → publish latency, ns.
    pub fn latency_ns(&self) -> u64 {
        self.published_time_ns.saturating_sub(self.capture_time_ns)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reason_codes_round_trip() {
        for r in InvalidReason::ALL {
            assert_eq!(InvalidReason::from_code(r as u32), Some(r));
        }
        assert_eq!(InvalidReason::from_code(99), None);
        let mut names: Vec<&str> = InvalidReason::ALL.iter().map(|r| r.name()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), InvalidReason::COUNT, "reason names must be distinct");
        // Codes are positions in ALL: appended, never renumbered.
        for (i, r) in InvalidReason::ALL.iter().enumerate() {
            assert_eq!(*r as usize, i);
        }
        assert_eq!(InvalidReason::CaptureTooOld as u32, 22);
        assert_eq!(InvalidReason::InstanceClassUnknown as u32, 28);
    }

    #[test]
    fn object_pose_layout_has_the_verification_fields_last() {
        use core::mem::offset_of;
        assert_eq!(offset_of!(WireObjectPose, flags), 6);
        assert_eq!(offset_of!(WireObjectPose, quaternion), 24);
        assert_eq!(offset_of!(WireObjectPose, translation_m), 56);
        assert_eq!(offset_of!(WireObjectPose, fit_score), 80);
        assert_eq!(offset_of!(WireObjectPose, depth_residual_m), 84);
        assert_eq!(offset_of!(PoseMessage, objects), 96);
        let p = WireObjectPose { flags: PoseFlags::VERIFIED | PoseFlags::FROM_INSTANCE_LABELS, ..Default::default() };
        assert!(p.is_verified() && !p.is_confirmed());
        assert!(!WireObjectPose::default().is_verified());
        assert!(WireObjectPose { flags: PoseFlags::CONFIRMED, ..Default::default() }.is_confirmed());
    }

    #[test]
    fn objects_clamps_a_corrupt_count() {
        let msg = PoseMessage { object_count: 1000, ..PoseMessage::default() };
        assert_eq!(msg.objects().len(), MAX_OBJECTS);
    }
}
