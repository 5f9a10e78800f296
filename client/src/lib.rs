//! # fusepose-client — the wire contract and the producer/consumer API
//!
//! Frame header, pose message and stats types (`#[repr(C)]`, little-endian,
//! fixed layout, see `docs/PROTOCOL.md`) and the one function that builds
//! every iceoryx2 service ([`CameraServices::open`]), so all processes open
//! them with identical options. Touches iceoryx2 shared memory only; never
//! the estimator: [`decode_frame`] yields validated plane slices that the
//! daemon turns into the estimator's frame view.
//!
//! Units: metres, nanoseconds of `CLOCK_MONOTONIC` ([`monotonic_ns`]), camera
//! optical frame (x right, y down, z forward), quaternions `[x, y, z, w]`.

pub mod arrival;
mod cell_message;
mod cell_services;
mod clock;
mod consumer;
mod error;
mod frame_decode;
mod frame_header;
mod ipc_context;
mod pose_message;
mod producer;
mod services;
mod stats;

pub use arrival::{ArrivalPredictor, WaitPlan, WaitStrategy, poll_until};
pub use cell_message::{CellFlags, CellObject, CellPoseMessage, CellView, MAX_CELL_OBJECTS, MAX_CELL_VIEWS};
pub use cell_services::{CELL_POSES_SERVICE, CellConsumer, CellServices};
pub use clock::monotonic_ns;
pub use consumer::{Consumer, StatsClient, wait_for_samples};
pub use error::{CapacityLimit, ClientError};
pub use frame_decode::{DepthData, FramePlanes, FrameRejection, LabelData, decode_frame};
pub use frame_header::{
    ColorFormat, DepthFormat, FOCAL_RANGE_PX, FRAME_MAGIC, FrameHeader, FrameLayout, LABELS_INSTANCE_U16, LABELS_U8,
    LABELS_U16, LabelFormat, MAX_IMAGE_SIDE, PlaneRef,
};
pub use ipc_context::{Ipc, IpcOptions};
pub use pose_message::{InvalidReason, MAX_OBJECTS, PoseFlags, PoseMessage, PoseStatus, WireObjectPose};
pub use producer::{DepthMut, FrameWriter, LabelsMut, PlanesMut, Producer};
pub use services::{CameraServices, camera_id, limits, validate_camera_name};
pub use stats::{LatencySummary, STAGE_COUNT, Stage, StatsRequest, StatsSnapshot, TIMELINE_COUNT};

/// Version of every wire type in this crate. Bumped on any layout change;
/// checked in each message and as a service attribute when opening services.
///
/// 3: instance-label frames (label format 3 + instance class table, 32-bit
/// plane references), pose verification fields and flags, reasons 23–28.
pub const WIRE_VERSION: u16 = 3;

#[cfg(test)]
mod tests {
    use iceoryx2::prelude::*;
    use iceoryx2::service::attribute::{AttributeKey, AttributeSpecifier, AttributeValue};

    use super::*;

    /// A pose message as wire version 2 laid it out (2656 bytes, same type name).
    #[repr(C)]
    #[derive(Debug, ZeroCopySend)]
    #[type_name("fusepose::PoseMessage")]
    struct PoseMessageV2 {
        bytes: [u64; 332],
    }

    /// A peer of wire version 2 created one of the camera's services first: a
    /// version-3 process gets the version error naming the service (not an
    /// iceoryx2 type or attribute detail), whichever service that peer opened.
    #[test]
    fn services_of_an_older_wire_version_are_refused_by_name() {
        let dir = tempfile::tempdir().unwrap();
        let prefix = format!("fpv{}_", std::process::id());
        let options =
            IpcOptions { root_path: Some(dir.path().to_owned()), prefix: Some(prefix.clone()), ..Default::default() };
        let ipc = Ipc::new(&options).unwrap();
        let key = AttributeKey::new(b"fusepose.wire_version").unwrap();
        let v2 = AttributeSpecifier::new().define(&key, &AttributeValue::new(b"2").unwrap()).unwrap();
        let name = |s: &str| ServiceName::new(s).unwrap();

        // A version-2 process: its frame header is 128 bytes too, so only the attribute differs.
        let _frames = ipc
            .node()
            .service_builder(&name("fusepose/camera/old/frames"))
            .publish_subscribe::<[u8]>()
            .user_header::<FrameHeader>()
            .create_with_attributes(&v2)
            .unwrap();
        // A version-2 C consumer that opened only the poses service: there the payload size differs too.
        let _poses = ipc
            .node()
            .service_builder(&name("fusepose/camera/oldc/poses"))
            .publish_subscribe::<PoseMessageV2>()
            .create_with_attributes(&v2)
            .unwrap();

        for (camera, service) in [("old", "fusepose/camera/old/frames"), ("oldc", "fusepose/camera/oldc/poses")] {
            match CameraServices::open(&ipc, camera) {
                Err(ClientError::WireVersionMismatch { service: s, ours }) => {
                    assert_eq!((s.as_str(), ours), (service, WIRE_VERSION))
                }
                Err(e) => panic!("camera {camera}: expected a wire version mismatch, got {e}"),
                Ok(_) => panic!("camera {camera}: a version-2 service was opened"),
            }
        }
        drop(ipc);
        for entry in std::fs::read_dir("/dev/shm").into_iter().flatten().flatten() {
            if entry.file_name().to_string_lossy().starts_with(&prefix) {
                let _ = std::fs::remove_file(entry.path());
            }
        }
    }
}
