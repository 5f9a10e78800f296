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
pub use clock::monotonic_ns;
pub use consumer::{Consumer, StatsClient, wait_for_samples};
pub use error::ClientError;
pub use frame_decode::{DepthData, FramePlanes, FrameRejection, LabelData, decode_frame};
pub use frame_header::{
    ColorFormat, DepthFormat, FOCAL_RANGE_PX, FRAME_MAGIC, FrameHeader, FrameLayout, LabelFormat, MAX_IMAGE_SIDE,
    PlaneRef,
};
pub use ipc_context::{Ipc, IpcOptions};
pub use pose_message::{InvalidReason, MAX_OBJECTS, PoseMessage, PoseStatus, WireObjectPose};
pub use producer::{DepthMut, FrameWriter, LabelsMut, PlanesMut, Producer};
pub use services::{CameraServices, camera_id, validate_camera_name};
pub use stats::{LatencySummary, STAGE_COUNT, Stage, StatsRequest, StatsSnapshot, TIMELINE_COUNT};

/// Version of every wire type in this crate. Bumped on any layout change;
/// checked in each message and as a service attribute when opening services.
pub const WIRE_VERSION: u16 = 2;
