//! Errors of the client API (iceoryx2 failures carried as text, with the service named;
//! capacity limits as [`ClientError::Capacity`], which says which limit, why and what to do).

/// What went wrong talking to fusepose over iceoryx2.
#[derive(Debug, thiserror::Error)]
pub enum ClientError {
    #[error("camera name {0:?} is invalid: use 1 to 64 characters of [A-Za-z0-9_-]")]
    InvalidCameraName(String),
    #[error("iceoryx2 setting {setting} = {value:?} is invalid")]
    InvalidIpcOption { setting: &'static str, value: String },
    #[error("cannot create the iceoryx2 node: {0}")]
    Node(String),
    #[error(
        "service {service} was created with a different fusepose wire-format version (this process speaks v{ours}); \
         upgrade/downgrade all fusepose processes together"
    )]
    WireVersionMismatch { service: String, ours: u16 },
    #[error("received a {what} of wire-format version {got} on {service}; this process speaks v{ours}")]
    MessageVersionMismatch { service: String, what: &'static str, got: u16, ours: u16 },
    #[error("cannot open service {service}: {detail}")]
    ServiceOpen { service: String, detail: String },
    #[error("cannot create a {port} port on {service}: {detail}")]
    Port { service: String, port: &'static str, detail: String },
    #[error("iceoryx2 {operation} failed on {service}: {detail}")]
    Transfer { service: String, operation: &'static str, detail: String },
    #[error("frame layout invalid: {0}")]
    Layout(String),
    #[error("no answer from {service} within {timeout_ms} ms (is fuseposed running?)")]
    Timeout { service: String, timeout_ms: u64 },
    /// An iceoryx2 limit of the service was reached (see [`CapacityLimit`]).
    #[error("service {service}: {limit} ({detail}); likely cause: {cause}; what to do: {fix}")]
    Capacity {
        service: String,
        limit: CapacityLimit,
        /// The limit's value and iceoryx2's own error name.
        detail: String,
        cause: String,
        fix: String,
    },
}

/// Which iceoryx2 limit of a fusepose service a request ran into. The
/// limits are fixed when the service is created (docs/PROTOCOL.md, "Services").
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CapacityLimit {
    /// Publishers of one service (frames: cameras; poses: daemons).
    Publishers,
    /// Subscribers of one service (frames: the daemon and taps; poses: consumers).
    Subscribers,
    /// Notifiers of an event service.
    Notifiers,
    /// Listeners of an event service.
    Listeners,
    /// Servers of the stats service (daemons).
    Servers,
    /// Clients of the stats service.
    Clients,
    /// Processes (iceoryx2 nodes) that have the service open.
    Nodes,
    /// The service exists with smaller settings (buffer, history, borrowed
    /// samples, ports) than this process asks for.
    ServiceSettings,
    /// Samples one publisher has loaned and not sent.
    Loans,
    /// Samples one subscriber holds at once.
    Borrows,
    /// Every sample of the publisher's shared memory is held by subscribers.
    SampleMemory,
    /// Stats requests one client has in flight.
    ActiveRequests,
}

impl std::fmt::Display for CapacityLimit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            Self::Publishers => "too many publishers",
            Self::Subscribers => "too many subscribers",
            Self::Notifiers => "too many notifiers",
            Self::Listeners => "too many listeners",
            Self::Servers => "too many servers",
            Self::Clients => "too many clients",
            Self::Nodes => "too many processes (iceoryx2 nodes) on the service",
            Self::ServiceSettings => "the service was created with smaller settings than this process needs",
            Self::Loans => "too many samples loaned at once",
            Self::Borrows => "too many samples held at once",
            Self::SampleMemory => "no free sample in the publisher's shared memory",
            Self::ActiveRequests => "too many stats requests in flight",
        })
    }
}

/// iceoryx2 error names (their `Debug` text) that mean a capacity limit. Every
/// error type of iceoryx2 0.10 that can carry one is matched by these names, so
/// one table covers service opening, port creation, loans and receives.
const CAPACITY_ERRORS: &[(&str, CapacityLimit)] = &[
    ("ExceedsMaxSupportedPublishers", CapacityLimit::Publishers),
    ("ExceedsMaxSupportedSubscribers", CapacityLimit::Subscribers),
    ("ExceedsMaxSupportedNotifiers", CapacityLimit::Notifiers),
    ("ExceedsMaxSupportedListeners", CapacityLimit::Listeners),
    ("ExceedsMaxSupportedServers", CapacityLimit::Servers),
    ("ExceedsMaxSupportedClients", CapacityLimit::Clients),
    ("ExceedsMaxNumberOfNodes", CapacityLimit::Nodes),
    ("DoesNotSupportRequested", CapacityLimit::ServiceSettings),
    ("BufferSizeExceedsMaxSupportedBufferSizeOfService", CapacityLimit::ServiceSettings),
    ("HistoryRequestExceedsHistorySizeOfService", CapacityLimit::ServiceSettings),
    ("MaxActiveRequestsExceedsMaxSupportedActiveRequestsOfService", CapacityLimit::ServiceSettings),
    ("ExceedsMaxLoans", CapacityLimit::Loans),
    ("ExceedsMaxLoanSize", CapacityLimit::Loans),
    ("ExceedsMaxBorrows", CapacityLimit::Borrows),
    ("OutOfMemory", CapacityLimit::SampleMemory),
    ("ExceedsMaxActiveRequests", CapacityLimit::ActiveRequests),
];

/// The capacity limit an iceoryx2 error's `Debug` text names, if any.
pub(crate) fn capacity_limit_of(debug: &str) -> Option<(CapacityLimit, &'static str)> {
    CAPACITY_ERRORS.iter().find(|(name, _)| debug.contains(name)).map(|&(name, limit)| (limit, name))
}

/// Which kind of fusepose service a name is (its last path element).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum ServiceKind {
    Frames,
    CellPoses,
    Poses,
    Stats,
    Other,
}

fn kind_of(service: &str) -> ServiceKind {
    if service.starts_with("fusepose/cell/") {
        return ServiceKind::CellPoses;
    }
    match service.rsplit('/').next() {
        Some("frames") => ServiceKind::Frames,
        Some("poses") => ServiceKind::Poses,
        Some("stats") => ServiceKind::Stats,
        _ => ServiceKind::Other,
    }
}

/// The limit's value on a fusepose service, why it is usually reached and what to do.
fn advice(kind: ServiceKind, limit: CapacityLimit) -> (Option<usize>, &'static str, &'static str) {
    use crate::services::limits as l;
    use CapacityLimit as C;
    use ServiceKind as K;
    const CLEANUP: &str = "stop the processes you no longer need (those of crashed processes are freed at the next \
                           fusepose process start and by fuseposed every ipc.cleanup_interval_s)";
    match (kind, limit) {
        (K::Frames, C::Publishers) => (
            Some(l::FRAME_PUBLISHERS),
            "another camera process publishes frames under this camera name (or a crashed one is not cleaned up yet)",
            "stop the other producer or give each camera its own name; resources of crashed processes are freed at \
             the next fusepose process start and by fuseposed every ipc.cleanup_interval_s",
        ),
        (K::Poses, C::Publishers) | (K::Stats, C::Servers) => (
            Some(if limit == C::Servers { l::STATS_SERVERS } else { l::POSE_PUBLISHERS }),
            "a second fuseposed serves this camera in the same iceoryx2 namespace (root path and prefix), or a \
             foreign program publishes on it",
            "run one daemon per camera (fuseposed refuses a second one itself; an older daemon may not): stop the other",
        ),
        (K::CellPoses, C::Publishers) => (
            Some(l::CELL_PUBLISHERS),
            "another fuseposed publishes the cell's poses in this iceoryx2 namespace",
            "serve all cameras of a cell from one fuseposed, or set [cell] enabled = false in the others",
        ),
        (K::CellPoses, C::Subscribers) => (
            Some(l::CELL_SUBSCRIBERS),
            "more consumers of the cell's poses run than the service allows",
            "close consumers you no longer need or fan poses out inside one process",
        ),
        (K::Frames, C::Subscribers) => (
            Some(l::FRAME_SUBSCRIBERS),
            "more processes read this camera's frames than fuseposed plus two taps",
            "close the other frame readers",
        ),
        (K::Poses, C::Subscribers) => (
            Some(l::POSE_SUBSCRIBERS),
            "more consumers of this camera's poses run than the service allows (every Consumer and `fusepose watch` \
             is one; crashed ones count until cleaned up)",
            "close consumers you no longer need or fan poses out inside one process",
        ),
        (_, C::Notifiers) => (
            Some(l::EVENT_NOTIFIERS),
            "more processes signal this event (producers, daemons) than the service allows",
            "stop the processes you no longer need",
        ),
        (_, C::Listeners) => (
            Some(l::EVENT_LISTENERS),
            "more processes wait on this event (the daemon, consumers) than the service allows",
            "stop the processes you no longer need",
        ),
        (_, C::Clients) => (
            Some(l::STATS_CLIENTS),
            "more stats clients (`fusepose stats`, dashboards) are open at once than the service allows",
            "query from fewer processes, or drop each StatsClient when done",
        ),
        (_, C::Nodes) => (
            Some(l::MAX_NODES),
            "more processes have this camera's services open than the service allows (crashed processes count \
             until cleaned up)",
            CLEANUP,
        ),
        (_, C::ServiceSettings) => (
            None,
            "the service was created by a process with other settings: another fusepose release, or a raw iceoryx2 \
             client that created it first with smaller limits",
            "stop every process of this camera so that the service is removed, then start them from one fusepose \
             release; raw clients must create the services with exactly the settings of docs/PROTOCOL.md",
        ),
        (_, C::Loans) => (
            Some(l::PUBLISHER_LOANS),
            "this producer holds more loaned frames than it sent, or asked for a frame larger than its layout",
            "send (or drop) each loaned frame before loaning the next; create the producer with the frame layout it sends",
        ),
        (_, C::Borrows) => (
            None,
            "this process holds more received samples at once than the service allows (it keeps samples alive)",
            "drop received samples before receiving more",
        ),
        (_, C::SampleMemory) => (
            None,
            "readers hold every sample of this publisher's shared memory (a reader that never releases, e.g. one \
             stopped with SIGSTOP)",
            "find the process that holds samples; the memory comes back when it receives again or exits",
        ),
        (_, C::ActiveRequests) => (
            Some(l::STATS_ACTIVE_REQUESTS),
            "this client sent stats requests that were never answered (no daemon, or a stalled one)",
            "wait for answers before asking again; check that fuseposed runs",
        ),
        (_, C::Publishers | C::Subscribers | C::Servers) => {
            (None, "more ports of this kind than the service allows", "stop the processes you no longer need")
        }
    }
}

impl ClientError {
    /// The typed capacity error for an iceoryx2 error on `service`, when it is one.
    pub fn capacity(service: &str, error: &dyn std::fmt::Debug) -> Option<Self> {
        let debug = format!("{error:?}");
        let debug = debug.trim_matches('"');
        let (limit, name) = capacity_limit_of(debug)?;
        let (max, cause, fix) = advice(kind_of(service), limit);
        let detail = match max {
            Some(max) => format!("limit {max}; iceoryx2 {name}"),
            None => format!("iceoryx2 {debug}"),
        };
        Some(Self::Capacity {
            service: service.to_owned(),
            limit,
            detail,
            cause: cause.to_owned(),
            fix: fix.to_owned(),
        })
    }

    /// A failed port creation: [`ClientError::Capacity`] for a capacity limit, else [`ClientError::Port`].
    pub fn port(service: &str, port: &'static str, error: &dyn std::fmt::Debug) -> Self {
        Self::capacity(service, error).unwrap_or_else(|| Self::Port {
            service: service.to_owned(),
            port,
            detail: format!("{error:?}"),
        })
    }

    /// `Ok` when a received message's `format_version` is ours, else
    /// [`ClientError::MessageVersionMismatch`] naming the service and what was received.
    pub fn check_version(service: &str, what: &'static str, got: u16) -> Result<(), Self> {
        if got == crate::WIRE_VERSION {
            Ok(())
        } else {
            Err(Self::MessageVersionMismatch { service: service.to_owned(), what, got, ours: crate::WIRE_VERSION })
        }
    }

    /// A failed loan, send or receive: [`ClientError::Capacity`] for a capacity limit, else [`ClientError::Transfer`].
    pub fn transfer(service: &str, operation: &'static str, error: &dyn std::fmt::Debug) -> Self {
        Self::capacity(service, error).unwrap_or_else(|| Self::Transfer {
            service: service.to_owned(),
            operation,
            detail: format!("{error:?}"),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn capacity_errors_name_service_limit_cause_and_fix() {
        #[derive(Debug)]
        #[allow(dead_code)] // only its Debug text matters
        enum Fake {
            ExceedsMaxSupportedSubscribers,
            PublishSubscribeOpenError(u8),
        }
        let e = ClientError::port("fusepose/camera/cam0/poses", "subscriber", &Fake::ExceedsMaxSupportedSubscribers);
        match &e {
            ClientError::Capacity { limit: CapacityLimit::Subscribers, .. } => {}
            other => panic!("{other}"),
        }
        let text = e.to_string();
        assert!(text.starts_with("service fusepose/camera/cam0/poses: too many subscribers (limit 16;"), "{text}");
        assert!(text.contains("consumers") && text.contains("what to do"), "{text}");
        // Not a capacity limit: the plain port error.
        let e = ClientError::port("fusepose/camera/cam0/poses", "subscriber", &Fake::PublishSubscribeOpenError(3));
        assert!(matches!(e, ClientError::Port { port: "subscriber", .. }), "{e}");
        // The same limit reads differently per service.
        let frames = ClientError::capacity("fusepose/camera/a/frames", &"ExceedsMaxSupportedPublishers").unwrap();
        let poses = ClientError::capacity("fusepose/camera/a/poses", &"ExceedsMaxSupportedPublishers").unwrap();
        assert!(frames.to_string().contains("limit 2") && frames.to_string().contains("producer"), "{frames}");
        assert!(poses.to_string().contains("second fuseposed"), "{poses}");
    }

    #[test]
    fn every_table_entry_maps_to_its_limit() {
        for &(name, limit) in CAPACITY_ERRORS {
            assert_eq!(capacity_limit_of(&format!("Outer({name})")).map(|(l, _)| l), Some(limit), "{name}");
        }
        assert_eq!(capacity_limit_of("IncompatibleTypes"), None);
        assert_eq!(capacity_limit_of("IncompatibleAttributes"), None);
    }
}
