//! Errors of the client API (iceoryx2 failures carried as text, with the service named).

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
}
