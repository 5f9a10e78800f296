//! Service names, the one function that opens every fusepose service of a
//! camera with the same options, and the ports on them. The daemon creates
//! the services; any process may come first (each opens or creates them with
//! these options). Options given when opening an existing service are lower
//! bounds that the service must meet (more than it was created with fails)
//! and the overflow setting must match; [`limits`] holds every value, and
//! docs/PROTOCOL.md lists them for clients in other languages. Limits reached
//! come back as [`ClientError::Capacity`].
//!
//! Per camera `<name>`:
//! - `fusepose/camera/<name>/frames`: publish-subscribe `[u8]` + [`FrameHeader`], and an event service of the same name (frame ready);
//! - `fusepose/camera/<name>/poses`: publish-subscribe [`PoseMessage`], and an event service of the same name (poses ready);
//! - `fusepose/camera/<name>/stats`: request-response [`StatsRequest`] → [`StatsSnapshot`].

use iceoryx2::port::client::Client;
use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::server::Server;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::attribute::{AttributeKey, AttributeValue, AttributeVerifier};
use iceoryx2::service::builder::event::EventOpenError;
use iceoryx2::service::builder::event::EventOpenOrCreateError;
use iceoryx2::service::builder::publish_subscribe::{PublishSubscribeOpenError, PublishSubscribeOpenOrCreateError};
use iceoryx2::service::builder::request_response::{RequestResponseOpenError, RequestResponseOpenOrCreateError};
use iceoryx2::service::port_factory::{event, publish_subscribe, request_response};

use crate::{ClientError, FrameHeader, Ipc, PoseMessage, StatsRequest, StatsSnapshot, WIRE_VERSION};

/// The settings every fusepose service is created with (docs/PROTOCOL.md, "Services").
pub mod limits {
    /// Most nodes (processes) that may open one service at once.
    pub const MAX_NODES: usize = 32;
    /// Frames: publishers (cameras), subscribers (the daemon and taps).
    pub const FRAME_PUBLISHERS: usize = 2;
    pub const FRAME_SUBSCRIBERS: usize = 3;
    /// Frames: samples waiting per subscriber, and held at once (the daemon keeps the newest while draining).
    pub const FRAME_BUFFER: usize = 2;
    pub const FRAME_BORROWED: usize = 2;
    /// Poses: publishers (the daemon; a second one only while a restart overlaps), subscribers (consumers).
    pub const POSE_PUBLISHERS: usize = 2;
    pub const POSE_SUBSCRIBERS: usize = 16;
    pub const POSE_BUFFER: usize = 4;
    pub const POSE_BORROWED: usize = 2;
    /// The last pose message is replayed to a new subscriber.
    pub const POSE_HISTORY: usize = 1;
    /// Event services (frames ready, poses ready).
    pub const EVENT_NOTIFIERS: usize = 8;
    pub const EVENT_LISTENERS: usize = 24;
    /// Stats: servers (the daemon), clients, requests in flight per client, answers buffered per request.
    pub const STATS_SERVERS: usize = 2;
    pub const STATS_CLIENTS: usize = 8;
    pub const STATS_ACTIVE_REQUESTS: usize = 2;
    pub const STATS_RESPONSE_BUFFER: usize = 2;
    /// Frames a producer may have loaned and not sent.
    pub const PUBLISHER_LOANS: usize = 2;
    /// Cell poses (`fusepose/cell/poses`): one publisher (the daemon that serves the cell), subscribers, buffer.
    pub const CELL_PUBLISHERS: usize = 1;
    pub const CELL_SUBSCRIBERS: usize = 16;
    pub const CELL_BUFFER: usize = 4;
    pub const CELL_BORROWED: usize = 2;
    /// The last cell message is replayed to a new subscriber.
    pub const CELL_HISTORY: usize = 1;
}
use limits::*;
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

pub(crate) fn version_verifier() -> AttributeVerifier {
    let key = AttributeKey::new(VERSION_ATTRIBUTE.as_bytes()).expect("constant attribute key is valid");
    let value = AttributeValue::new(WIRE_VERSION.to_string().as_bytes()).expect("version string is a valid value");
    AttributeVerifier::new().require(&key, &value).expect("one attribute fits")
}

pub(crate) fn service_name(name: &str) -> Result<ServiceName, ClientError> {
    ServiceName::new(name).map_err(|e| ClientError::ServiceOpen { service: name.to_owned(), detail: format!("{e:?}") })
}

fn open_error(service: &str, detail: String, version_mismatch: bool) -> ClientError {
    if version_mismatch {
        ClientError::WireVersionMismatch { service: service.to_owned(), ours: WIRE_VERSION }
    } else {
        ClientError::capacity(service, &detail)
            .unwrap_or_else(|| ClientError::ServiceOpen { service: service.to_owned(), detail })
    }
}

pub(crate) fn pubsub_error(service: &str, e: PublishSubscribeOpenOrCreateError) -> ClientError {
    // Types are checked before attributes: a fusepose type name with another
    // layout is another wire version too (e.g. a v2 pose message, 2656 bytes).
    let mismatch = matches!(
        e,
        PublishSubscribeOpenOrCreateError::PublishSubscribeOpenError(
            PublishSubscribeOpenError::IncompatibleAttributes | PublishSubscribeOpenError::IncompatibleTypes
        )
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
        RequestResponseOpenOrCreateError::RequestResponseOpenError(
            RequestResponseOpenError::IncompatibleAttributes
                | RequestResponseOpenError::IncompatibleRequestOrResponseType
        )
    );
    open_error(service, format!("{e:?}"), mismatch)
}

pub(crate) fn open_event(ipc: &Ipc, name: &str, verifier: &AttributeVerifier) -> Result<EventService, ClientError> {
    ipc.node()
        .service_builder(&service_name(name)?)
        .event()
        .max_notifiers(EVENT_NOTIFIERS)
        .max_listeners(EVENT_LISTENERS)
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
            .subscriber_max_buffer_size(FRAME_BUFFER)
            .subscriber_max_borrowed_samples(FRAME_BORROWED)
            .history_size(0)
            .max_publishers(FRAME_PUBLISHERS)
            .max_subscribers(FRAME_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(&verifier)
            .map_err(|e| pubsub_error(&frames_name, e))?;
        let frame_events = open_event(ipc, &frames_name, &verifier)?;

        // Poses: small fixed messages; history 1 so a late consumer gets the latest at once.
        let poses = node
            .service_builder(&service_name(&poses_name)?)
            .publish_subscribe::<PoseMessage>()
            .enable_safe_overflow(true)
            .subscriber_max_buffer_size(POSE_BUFFER)
            .subscriber_max_borrowed_samples(POSE_BORROWED)
            .history_size(POSE_HISTORY)
            .max_publishers(POSE_PUBLISHERS)
            .max_subscribers(POSE_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(&verifier)
            .map_err(|e| pubsub_error(&poses_name, e))?;
        let pose_events = open_event(ipc, &poses_name, &verifier)?;

        let stats = node
            .service_builder(&service_name(&stats_name)?)
            .request_response::<StatsRequest, StatsSnapshot>()
            .enable_safe_overflow_for_requests(true)
            .enable_safe_overflow_for_responses(true)
            .max_active_requests_per_client(STATS_ACTIVE_REQUESTS)
            .max_response_buffer_size(STATS_RESPONSE_BUFFER)
            .max_servers(STATS_SERVERS)
            .max_clients(STATS_CLIENTS)
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

    /// A frame publisher (producer side) for frames of up to `max_payload_len` bytes.
    pub fn frame_publisher(
        &self,
        max_payload_len: usize,
    ) -> Result<Publisher<ipc::Service, [u8], FrameHeader>, ClientError> {
        self.frames
            .publisher_builder()
            .initial_max_slice_len(max_payload_len)
            .allocation_strategy(AllocationStrategy::Static)
            .max_loaned_samples(PUBLISHER_LOANS)
            .create()
            .map_err(|e| ClientError::port(&self.frames_name, "publisher", &e))
    }

    /// The frame subscriber (daemon side).
    pub fn frame_subscriber(&self) -> Result<Subscriber<ipc::Service, [u8], FrameHeader>, ClientError> {
        self.frames.subscriber_builder().create().map_err(|e| ClientError::port(&self.frames_name, "subscriber", &e))
    }

    /// Notifies "frame ready" (producer side).
    pub fn frame_notifier(&self) -> Result<Notifier<ipc::Service>, ClientError> {
        self.frame_events.notifier_builder().create().map_err(|e| ClientError::port(&self.frames_name, "notifier", &e))
    }

    /// Wakes on "frame ready" (daemon side).
    pub fn frame_listener(&self) -> Result<Listener<ipc::Service>, ClientError> {
        self.frame_events.listener_builder().create().map_err(|e| ClientError::port(&self.frames_name, "listener", &e))
    }

    /// The pose publisher (daemon side).
    pub fn pose_publisher(&self) -> Result<Publisher<ipc::Service, PoseMessage, ()>, ClientError> {
        self.poses.publisher_builder().create().map_err(|e| ClientError::port(&self.poses_name, "publisher", &e))
    }

    /// A pose subscriber (consumer side).
    pub fn pose_subscriber(&self) -> Result<Subscriber<ipc::Service, PoseMessage, ()>, ClientError> {
        self.poses.subscriber_builder().create().map_err(|e| ClientError::port(&self.poses_name, "subscriber", &e))
    }

    /// Notifies "poses ready" (daemon side).
    pub fn pose_notifier(&self) -> Result<Notifier<ipc::Service>, ClientError> {
        self.pose_events.notifier_builder().create().map_err(|e| ClientError::port(&self.poses_name, "notifier", &e))
    }

    /// Wakes on "poses ready" (consumer side).
    pub fn pose_listener(&self) -> Result<Listener<ipc::Service>, ClientError> {
        self.pose_events.listener_builder().create().map_err(|e| ClientError::port(&self.poses_name, "listener", &e))
    }

    /// The stats server (daemon side).
    pub fn stats_server(&self) -> Result<Server<ipc::Service, StatsRequest, (), StatsSnapshot, ()>, ClientError> {
        self.stats.server_builder().create().map_err(|e| ClientError::port(&self.stats_name, "server", &e))
    }

    /// A stats client.
    pub fn stats_client(&self) -> Result<Client<ipc::Service, StatsRequest, (), StatsSnapshot, ()>, ClientError> {
        self.stats.client_builder().create().map_err(|e| ClientError::port(&self.stats_name, "client", &e))
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
