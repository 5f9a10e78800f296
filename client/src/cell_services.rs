//! The cell service `fusepose/cell/poses`: publish-subscribe
//! [`CellPoseMessage`] plus an event service of the same name ("cell poses
//! ready"). The daemon that serves the cell's cameras publishes; any process
//! may subscribe first.

use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::notifier::Notifier;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use iceoryx2::service::port_factory::publish_subscribe;

use crate::arrival::{ArrivalPredictor, WaitStrategy};
use crate::consumer::wait_for_samples;
use crate::services::limits::*;
use crate::services::{EventService, open_event, pubsub_error, service_name, version_verifier};
use crate::{CellPoseMessage, ClientError, Ipc};

/// Name of the cell pose service (and of its event service).
pub const CELL_POSES_SERVICE: &str = "fusepose/cell/poses";

pub type CellPoseService = publish_subscribe::PortFactory<ipc::Service, CellPoseMessage, ()>;

/// The cell pose service and its event service.
pub struct CellServices {
    pub poses: CellPoseService,
    pub events: EventService,
}

impl CellServices {
    /// Opens (creating where missing) the cell services with the options of
    /// docs/PROTOCOL.md, "Cell poses".
    pub fn open(ipc: &Ipc) -> Result<Self, ClientError> {
        let verifier = version_verifier();
        let poses = ipc
            .node()
            .service_builder(&service_name(CELL_POSES_SERVICE)?)
            .publish_subscribe::<CellPoseMessage>()
            .enable_safe_overflow(true)
            .subscriber_max_buffer_size(CELL_BUFFER)
            .subscriber_max_borrowed_samples(CELL_BORROWED)
            .history_size(CELL_HISTORY)
            .max_publishers(CELL_PUBLISHERS)
            .max_subscribers(CELL_SUBSCRIBERS)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(&verifier)
            .map_err(|e| pubsub_error(CELL_POSES_SERVICE, e))?;
        let events = open_event(ipc, CELL_POSES_SERVICE, &verifier)?;
        Ok(Self { poses, events })
    }

    /// The cell publisher (daemon side); one per namespace.
    pub fn publisher(&self) -> Result<Publisher<ipc::Service, CellPoseMessage, ()>, ClientError> {
        self.poses.publisher_builder().create().map_err(|e| ClientError::port(CELL_POSES_SERVICE, "publisher", &e))
    }

    pub fn notifier(&self) -> Result<Notifier<ipc::Service>, ClientError> {
        self.events.notifier_builder().create().map_err(|e| ClientError::port(CELL_POSES_SERVICE, "notifier", &e))
    }

    pub fn subscriber(&self) -> Result<Subscriber<ipc::Service, CellPoseMessage, ()>, ClientError> {
        self.poses.subscriber_builder().create().map_err(|e| ClientError::port(CELL_POSES_SERVICE, "subscriber", &e))
    }

    pub fn listener(&self) -> Result<Listener<ipc::Service>, ClientError> {
        self.events.listener_builder().create().map_err(|e| ClientError::port(CELL_POSES_SERVICE, "listener", &e))
    }
}

/// Receives cell pose messages (the robot side of a multi-camera cell).
pub struct CellConsumer {
    _services: CellServices,
    subscriber: Subscriber<ipc::Service, CellPoseMessage, ()>,
    listener: Listener<ipc::Service>,
    predictor: ArrivalPredictor,
}

impl CellConsumer {
    /// Subscribes to `fusepose/cell/poses` (the daemon need not run yet).
    pub fn open(ipc: &Ipc) -> Result<Self, ClientError> {
        let services = CellServices::open(ipc)?;
        let subscriber = services.subscriber()?;
        let listener = services.listener()?;
        Ok(Self { _services: services, subscriber, listener, predictor: ArrivalPredictor::default() })
    }

    /// Every cell message received since the last call, oldest first.
    pub fn drain(&mut self, out: &mut Vec<CellPoseMessage>) -> Result<(), ClientError> {
        while let Some(sample) =
            self.subscriber.receive().map_err(|e| ClientError::transfer(CELL_POSES_SERVICE, "receive", &e))?
        {
            let msg = *sample.payload();
            ClientError::check_version(CELL_POSES_SERVICE, "cell pose message", msg.format_version)?;
            out.push(msg);
        }
        Ok(())
    }

    /// Blocks until a cell message is waiting or `timeout` passes; returns
    /// whether one is (take them with [`CellConsumer::drain`]).
    pub fn wait_ready(&mut self, timeout: Duration) -> Result<bool, ClientError> {
        let subscriber = &self.subscriber;
        wait_for_samples(&self.listener, || subscriber.has_samples(), &mut self.predictor, WaitStrategy::Block, timeout)
            .map_err(|(operation, detail)| ClientError::Transfer {
                service: CELL_POSES_SERVICE.to_owned(),
                operation,
                detail,
            })
    }

    /// Blocks until a cell message arrives or `timeout` passes; returns the
    /// newest (older ones waiting beside it are dropped).
    pub fn wait(&mut self, timeout: Duration) -> Result<Option<CellPoseMessage>, ClientError> {
        if !self.wait_ready(timeout)? {
            return Ok(None);
        }
        let mut all = Vec::with_capacity(CELL_BUFFER);
        self.drain(&mut all)?;
        Ok(all.pop())
    }
}
