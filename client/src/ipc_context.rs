//! The process's iceoryx2 node, created from explicit options (root path and
//! prefix move every shared-memory resource, which isolates tests and lets
//! several fusepose installations share a machine).

use std::path::PathBuf;

use iceoryx2::config::Config;
use iceoryx2::node::{Node, NodeBuilder, NodeState};
use iceoryx2::prelude::*;

use crate::ClientError;

/// Environment variable overriding the iceoryx2 root path for all fusepose tools.
pub const ROOT_ENV: &str = "FUSEPOSE_IOX2_ROOT";
/// Environment variable overriding the iceoryx2 resource prefix for all fusepose tools.
pub const PREFIX_ENV: &str = "FUSEPOSE_IOX2_PREFIX";

/// How to create the iceoryx2 node.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct IpcOptions {
    /// Directory for iceoryx2's service and node files (iceoryx2 default `/tmp/iceoryx2/`).
    pub root_path: Option<PathBuf>,
    /// Prefix of every shared-memory object and file (iceoryx2 default `iox2_`).
    pub prefix: Option<String>,
    /// Node name shown by iceoryx2 tools.
    pub node_name: Option<String>,
    /// Let iceoryx2 catch SIGINT/SIGTERM (the daemon's WaitSet then reports them).
    /// Off for tools, so Ctrl-C ends them as usual.
    pub handle_signals: bool,
}

impl IpcOptions {
    /// Options from `FUSEPOSE_IOX2_ROOT` and `FUSEPOSE_IOX2_PREFIX` (unset = iceoryx2 defaults).
    pub fn from_env() -> Self {
        Self {
            root_path: std::env::var_os(ROOT_ENV).filter(|v| !v.is_empty()).map(PathBuf::from),
            prefix: std::env::var(PREFIX_ENV).ok().filter(|v| !v.is_empty()),
            ..Self::default()
        }
    }

    pub fn with_node_name(mut self, name: &str) -> Self {
        self.node_name = Some(name.to_owned());
        self
    }

    /// The iceoryx2 config these options describe (no config file is read).
    pub fn config(&self) -> Result<Config, ClientError> {
        let mut config = Config::default();
        if let Some(root) = &self.root_path {
            let mut text = root.to_string_lossy().into_owned();
            if !text.ends_with('/') {
                text.push('/');
            }
            let path = Path::new(text.as_bytes())
                .map_err(|_| ClientError::InvalidIpcOption { setting: "root_path", value: text.clone() })?;
            config.global.set_root_path(&path);
        }
        if let Some(prefix) = &self.prefix {
            config.global.prefix = FileName::new(prefix.as_bytes())
                .map_err(|_| ClientError::InvalidIpcOption { setting: "prefix", value: prefix.clone() })?;
        }
        Ok(config)
    }
}

/// One iceoryx2 node per process; services and ports are created from it.
pub struct Ipc {
    node: Node<ipc::Service>,
}

impl Ipc {
    /// Creates the node (which also removes resources of dead nodes, iceoryx2's default).
    pub fn new(options: &IpcOptions) -> Result<Self, ClientError> {
        let config = options.config()?;
        let mut builder = NodeBuilder::new().config(&config).signal_handling_mode(if options.handle_signals {
            SignalHandlingMode::HandleTerminationRequests
        } else {
            SignalHandlingMode::Disabled
        });
        if let Some(name) = &options.node_name {
            let name = NodeName::new(name)
                .map_err(|_| ClientError::InvalidIpcOption { setting: "node_name", value: name.clone() })?;
            builder = builder.name(&name);
        }
        let node = builder.create::<ipc::Service>().map_err(|e| ClientError::Node(format!("{e:?}")))?;
        restrict_node_counter(&config);
        Ok(Self { node })
    }

    pub fn node(&self) -> &Node<ipc::Service> {
        &self.node
    }

    /// Removes shared-memory resources of crashed processes; returns (removed, dead but not removable).
    pub fn cleanup_dead_nodes(&self) -> (usize, usize) {
        let state = self.node.try_cleanup_dead_nodes();
        (state.cleanups as usize, state.failed_cleanups as usize)
    }

    /// Number of nodes iceoryx2 currently sees as dead (not yet cleaned up).
    pub fn dead_node_count(&self) -> usize {
        let mut dead = 0;
        let _ = Node::<ipc::Service>::list(self.node.config(), |state| {
            if let NodeState::Dead(_) = state {
                dead += 1;
            }
            CallbackProgression::Continue
        });
        dead
    }
}

/// Where iceoryx2 0.10 puts its shared-memory segments on Linux.
const SHM_DIR: &str = "/dev/shm";

/// iceoryx2 0.10 creates its node-id counter segment
/// (`<prefix>…_node.<version>.global_mgmt`, one u32) readable and writable by
/// every local user on purpose (`GlobalManagementSegment::open_or_create`);
/// another user could disturb node-id generation through it. fusepose's
/// processes run as one user, so each node narrows the counters of its own
/// prefix that it owns to 0600. Best effort: a file of another user or a
/// failed chmod is left as it is (docs/RELIABILITY.md).
fn restrict_node_counter(config: &Config) {
    use std::os::unix::fs::{MetadataExt, PermissionsExt};
    let prefix = config.global.prefix.to_string();
    let Ok(dir) = std::fs::read_dir(SHM_DIR) else { return };
    // SAFETY: geteuid has no preconditions.
    let me = unsafe { libc::geteuid() };
    for entry in dir.flatten() {
        let name = entry.file_name();
        let name = name.to_string_lossy();
        if !name.starts_with(&prefix) || !name.ends_with(".global_mgmt") {
            continue;
        }
        let Ok(meta) = entry.metadata() else { continue };
        if meta.uid() == me && meta.permissions().mode() & 0o077 != 0 {
            let _ = std::fs::set_permissions(entry.path(), std::fs::Permissions::from_mode(0o600));
        }
    }
}
