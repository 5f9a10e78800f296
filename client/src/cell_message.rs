//! Cell wire format: every camera's objects in one robot-cell frame, the same
//! physical object seen by several cameras merged into one entry
//! (`fusepose/cell/poses`, docs/PROTOCOL.md "Cell poses").

use iceoryx2::prelude::ZeroCopySend;

/// Most objects one cell message carries.
pub const MAX_CELL_OBJECTS: usize = 64;
/// Most camera views listed per cell object (more views still count in `view_count`).
pub const MAX_CELL_VIEWS: usize = 4;

/// One camera's sight of a cell object (32 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("fusepose::CellView")]
pub struct CellView {
    /// The camera (FNV-1a 32 of its name, as in its pose messages).
    pub camera_id: u32,
    /// The pose's `instance_id` in that camera's pose message of `frame_sequence`.
    pub instance_id: u16,
    /// That pose's [`crate::PoseFlags`].
    pub flags: u16,
    /// That pose's confidence.
    pub confidence: f32,
    /// Distance of this view's translation from the fused one, metres.
    pub offset_m: f32,
    /// The camera frame the pose came from.
    pub frame_sequence: u64,
    /// Its capture time, `CLOCK_MONOTONIC` ns.
    pub capture_time_ns: u64,
}

/// One object in the cell frame (216 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, ZeroCopySend)]
#[type_name("fusepose::CellObject")]
pub struct CellObject {
    /// Class id in the daemon's object set (`[estimator] objects`; 1-based).
    pub class_id: u16,
    /// Cameras that saw the object (may exceed [`MAX_CELL_VIEWS`]; `views` lists the most confident).
    pub view_count: u16,
    /// [`CellFlags`] bits.
    pub flags: u16,
    pub reserved: u16,
    /// The highest confidence of the views.
    pub confidence: f32,
    /// Largest distance between a view's translation and the fused one, metres
    /// (0 for one view): how far the cameras disagree.
    pub spread_m: f32,
    /// Rotation object → cell, unit quaternion `[x, y, z, w]`.
    pub quaternion: [f64; 4],
    /// Translation object → cell, metres.
    pub translation_m: [f64; 3],
    /// Capture time of the newest view, `CLOCK_MONOTONIC` ns.
    pub newest_capture_time_ns: u64,
    /// Capture time of the oldest view, `CLOCK_MONOTONIC` ns.
    pub oldest_capture_time_ns: u64,
    /// The view whose pose the entry carries, then the others most confident
    /// first; entries beyond `min(view_count, 4)` are zero.
    pub views: [CellView; MAX_CELL_VIEWS],
}

/// Bits of [`CellObject::flags`].
pub struct CellFlags;

impl CellFlags {
    /// Every view passed the daemon's depth verification.
    pub const VERIFIED: u16 = 1 << 0;
    /// `cell.fusion = "mean"`: views whose rotation disagreed with the best
    /// view's by more than `cell.max_rotation_deg` (e.g. a symmetric object's
    /// equivalent rotations) were left out of the rotation.
    pub const ROTATION_FROM_BEST_VIEW: u16 = 1 << 1;
}

const _: () = assert!(core::mem::size_of::<CellView>() == 32);
const _: () = assert!(core::mem::size_of::<CellObject>() == 216);
const _: () = assert!(core::mem::align_of::<CellObject>() == 8);

/// The cell's objects, published on `fusepose/cell/poses` after every camera
/// frame the daemon posed (13 856 bytes).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, ZeroCopySend)]
#[type_name("fusepose::CellPoseMessage")]
pub struct CellPoseMessage {
    /// [`crate::WIRE_VERSION`].
    pub format_version: u16,
    /// Valid entries at the start of `objects`.
    pub object_count: u16,
    /// Cameras whose latest poses went into this message (fresh enough: `cell.max_age_ms`).
    pub camera_count: u16,
    /// 1 when some object did not fit ([`MAX_CELL_OBJECTS`]; the least confident were left out).
    pub truncated: u16,
    /// The camera whose frame triggered this message.
    pub trigger_camera_id: u32,
    pub reserved: u32,
    /// Counts cell messages from 0 since the daemon started.
    pub sequence: u64,
    /// When the daemon published this message, `CLOCK_MONOTONIC` ns.
    pub published_time_ns: u64,
    pub objects: [CellObject; MAX_CELL_OBJECTS],
}

const _: () = assert!(core::mem::size_of::<CellPoseMessage>() == 13_856);

impl Default for CellPoseMessage {
    fn default() -> Self {
        Self {
            format_version: crate::WIRE_VERSION,
            object_count: 0,
            camera_count: 0,
            truncated: 0,
            trigger_camera_id: 0,
            reserved: 0,
            sequence: 0,
            published_time_ns: 0,
            objects: [CellObject::default(); MAX_CELL_OBJECTS],
        }
    }
}

impl CellPoseMessage {
    /// The valid objects (`object_count` clamped to [`MAX_CELL_OBJECTS`]).
    pub fn objects(&self) -> &[CellObject] {
        &self.objects[..(self.object_count as usize).min(MAX_CELL_OBJECTS)]
    }
}

impl CellObject {
    /// The listed views (`view_count` clamped to [`MAX_CELL_VIEWS`]).
    pub fn views(&self) -> &[CellView] {
        &self.views[..(self.view_count as usize).min(MAX_CELL_VIEWS)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_fixed() {
        use core::mem::offset_of;
        assert_eq!(offset_of!(CellView, frame_sequence), 16);
        assert_eq!(offset_of!(CellObject, quaternion), 16);
        assert_eq!(offset_of!(CellObject, translation_m), 48);
        assert_eq!(offset_of!(CellObject, newest_capture_time_ns), 72);
        assert_eq!(offset_of!(CellObject, views), 88);
        assert_eq!(offset_of!(CellPoseMessage, sequence), 16);
        assert_eq!(offset_of!(CellPoseMessage, objects), 32);
        let msg = CellPoseMessage { object_count: 500, ..CellPoseMessage::default() };
        assert_eq!(msg.objects().len(), MAX_CELL_OBJECTS);
        let obj = CellObject { view_count: 9, ..CellObject::default() };
        assert_eq!(obj.views().len(), MAX_CELL_VIEWS);
    }
}
