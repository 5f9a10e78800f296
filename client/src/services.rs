//! Service names and the one function that opens every fusepose service of a
//! camera with identical options (iceoryx2 refuses to open a service with
//! options other than those it was created with).
//!
//! Per camera `<name>`:
//! - `fusepose/camera/<name>/frames`: publish-subscribe `[u8]` + [`FrameHeader`], and an event service of the same name (frame ready);
//! - `fusepose/camera/<name>/poses`: publish-subscribe [`PoseMessage`], and an event service of the same name (poses ready);
//! - `fusepose/camera/<name>/stats`: request-response [`StatsRequest`] → [`StatsSnapshot`].

use iceoryx2::prelude::*;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue, AttributeVerifier};
use iceoryx2::service::builder::event::EventOpenError;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::{PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError};
use iceoryx2::service::builder::request_response::{RequestResponseOpenError, RequestResponseOpenOrCreateError};
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};

use crate::{ClientError, FrameHeader, Ipc, PoseMessage, StatsRequest, StatsSnapshot, WIRE_VERSION};

/// Most nodes (processes) that may open one camera's services at once.
const MAX_NODES: usize = 32;
/// Attribute every fusepose service carries; opening checks it.
const VERSION_ATTRIBUTE: &str = "fusepose.wire_version";

pub type FrameService = publish_subscribe::PortFactory<ipc::Service, [u8], FrameHeader>;
pub type PoseService = publish_subscribe::PortFactory<ipc::Service, PoseMessage, ()>;
pub type EventService = event::PortFactory<ipc::Service>;
pub type StatsService = request_response::PortFactory<ipc::Service, StatsRequest, (), StatsSnapshot, ()>;

/// The services of one camera.
pub struct CameraServices {
    pub camera: String,
    pub camera_id: u32,
    pub frames: FrameService,
    pub frame_events: EventService,
    pub poses: PoseService,
    pub pose_events: EventService,
    pub stats: StatsService,
    pub frames_name: String,
    pub poses_name: String,
    pub stats_name: String,
}

/// Checks a camera name: 1 to 64 characters of `[A-Za-z0-9_-]`.
pub fn validate_camera_name(name: &str) -> Result<(), ClientError> {
    let ok = !name.is_empty()
        && name.len() <= 64
        && name.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_' || b == b'-');
    if ok { Ok(()) } else { Err(ClientError::InvalidCameraName(name.to_owned())) }
}

/// The camera id carried in frame headers and pose messages: FNV-1a (32 bit) of the name.
pub fn camera_id(name: &str) -> u32 {
    name.bytes().fold(0x811c_9dc5u32, |h, b| (h ^ b as u32).wrapping_mul(0x0100_0193))
}

fn version_verifier() -> AttributeVerifier {
    let key = AttributeKey::new(VERSION_ATTRIBUTE.as_bytes()).expect("constant attribute key is valid");
    let value = AttributeValue::new(WIRE_VERSION.to_string().as_bytes()).expect("version string is a valid value");
    AttributeVerifier::new().require(&key, &value).expect("one attribute fits")
}

fn service_name(name: &str) -> Result<ServiceName, ClientError> {
    ServiceName::new(name).map_err(|e| ClientError::ServiceOpen { service: name.to_owned(), detail: format!("{e:?}") })
}

fn open_error(service: &str, detail: String, version_mismatch: bool) -> ClientError {
    if version_mismatch {
        ClientError::WireVersionMismatch { service: service.to_owned(), ours: WIRE_VERSION }
    } else {
        ClientError::ServiceOpen { service: service.to_owned(), detail }
    }
}

fn pubsub_error(service: &str, e: PublishSubscribeOpenOrCreateError) -> ClientError {
    let mismatch = matches!(
        e,
        PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(PublishSubscribeOpenError::IncompatibleAttributes)
    );
    open_error(service, format!("{e:?}"), mismatch)
}

fn event_error(service: &str, e: EventOpenOrCreateError) -> ClientError {
    let mismatch = matches!(e, EventOpenOrCreateError::EventOpenError(EventOpenError::IncompatibleAttributes));
    open_error(service, format!("{e:?}"), mismatch)
}

fn request_response_error(service: &str, e: RequestResponseOpenOrCreateError) -> ClientError {
    let mismatch = matches!(
        e,
        RequestResponseOpenOrCreateError::RequestResponseOpenError(RequestResponseOpenError::IncompatibleAttributes)
    );
    open_error(service, format!("{e:?}"), mismatch)
}

fn open_event(ipc: &Ipc, name: &str, verifier: &AttributeVerifier) -> Result<EventService, ClientError> {
    ipc.node()
        .service_builder(&service_name(name)?)
        .event()
        .max_notifiers(8)
        .max_listeners(24)
        .max_nodes(MAX_NODES)
        .open_or_create_with_attributes(verifier)
        .map_err(|e| event_error(name, e))
}

impl CameraServices {
    /// Opens (creating where missing) all services of `camera`. Every fusepose
    /// process calls this, so all of them agree on the options.
    pub fn open(ipc: &Ipc, camera: &str) -> Result<Self, ClientError> {
        validate_camera_name(camera)?;
        let verifier = version_verifier();
        let frames_name = format!("fusepose/camera/{camera}/frames");
        let poses_name = format!("fusepose/camera/{camera}/poses");
        let stats_name = format!("fusepose/camera/{camera}/stats");
        let node = ipc.node();

        // Frames: newest wins (safe overflow; a stopped daemon never blocks a camera),
        // two borrowed samples so the daemon can drain keeping only the newest.
        let frames = node
            .service_builder(&service_name(&frames_name)?)
            .publish_subscribe::<[u8]>()
            .user_header::<FrameHeader>()
            .enable_safe_overflow(true)
            .subscriber_max_buffer_size(2)
            .subscriber_max_borrowed_samples(2)
            .history_size(0)
            .max_publishers(2)
            .max_subscribers(3)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(&verifier)
            .map_err(|e| pubsub_error(&frames_name, e))?;
        let frame_events = open_event(ipc, &frames_name, &verifier)?;

        // Poses: small fixed messages; history 1 so a late consumer gets the latest at once.
        let poses = node
            .service_builder(&service_name(&poses_name)?)
            .publish_subscribe::<PoseMessage>()
            .enable_safe_overflow(true)
            .subscriber_max_buffer_size(4)
            .subscriber_max_borrowed_samples(2)
            .history_size(1)
            .max_publishers(2)
            .max_subscribers(16)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(&verifier)
            .map_err(|e| pubsub_error(&poses_name, e))?;
        let pose_events = open_event(ipc, &poses_name, &verifier)?;

        let stats = node
            .service_builder(&service_name(&stats_name)?)
            .request_response::<StatsRequest, StatsSnapshot>()
            .enable_safe_overflow_for_requests(true)
            .enable_safe_overflow_for_responses(true)
            .max_active_requests_per_client(2)
            .max_response_buffer_size(2)
            .max_servers(2)
            .max_clients(8)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(&verifier)
            .map_err(|e| request_response_error(&stats_name, e))?;

        Ok(Self {
            camera: camera.to_owned(),
            camera_id: camera_id(camera),
            frames,
            frame_events,
            poses,
            pose_events,
            stats,
            frames_name,
            poses_name,
            stats_name,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camera_names_are_checked() {
        assert!(validate_camera_name("cam0").is_ok());
        assert!(validate_camera_name("left-wrist_2").is_ok());
        for bad in ["", "a/b", "cam 0", &"x".repeat(65)] {
            assert!(validate_camera_name(bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn camera_ids_are_stable_fnv1a() {
        assert_eq!(camera_id(""), 0x811c_9dc5);
        assert_eq!(camera_id("a"), 0xe40c_292c);
        assert_ne!(camera_id("cam0"), camera_id("cam1"));
    }
}
