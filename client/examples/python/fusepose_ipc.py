"""The fusepose services of one camera over the PyPI `iceoryx2` package (0.10.0, the
version of the Rust crate), opened exactly as docs/PROTOCOL.md ("Services") says:
open-or-create with the protocol's settings and the `fusepose.wire_version` attribute,
so this process may start before or after fuseposed.
"""

import ctypes
import os

import iceoryx2 as iox2

from fusepose_wire import WIRE_VERSION, CellPoseMessage, FrameHeader, PoseMessage, StatsRequest, StatsSnapshot

MAX_NODES = 32


def create_node(name: str) -> "iox2.Node":
    """A node in the namespace of FUSEPOSE_IOX2_ROOT / FUSEPOSE_IOX2_PREFIX (the daemon's
    `[ipc] root_path` / `prefix`); unset: iceoryx2's defaults /tmp/iceoryx2/ and iox2_."""
    config = iox2.config.default()
    root = os.environ.get("FUSEPOSE_IOX2_ROOT")
    prefix = os.environ.get("FUSEPOSE_IOX2_PREFIX")
    if root:
        config.global_cfg.root_path = iox2.Path.new(root if root.endswith("/") else root + "/")
    if prefix:
        config.global_cfg.prefix = iox2.FileName.new(prefix)
    return (
        iox2.NodeBuilder.new()
        .name(iox2.NodeName.new(name))
        .config(config)
        # Ctrl-C / SIGTERM end blocking waits with an exception instead of being swallowed.
        .signal_handling_mode(iox2.SignalHandlingMode.Disabled)
        .create(iox2.ServiceType.Ipc)
    )


def _attributes() -> "iox2.AttributeVerifier":
    return iox2.AttributeVerifier.new().require(
        iox2.AttributeKey.new("fusepose.wire_version"), iox2.AttributeValue.new(str(WIRE_VERSION))
    )


def _event(node, name):
    return (
        node.service_builder(iox2.ServiceName.new(name))
        .event()
        .max_notifiers(8)
        .max_listeners(24)
        .max_nodes(MAX_NODES)
        .open_or_create_with_attributes(_attributes())
    )


class CameraServices:
    """The five services of camera `camera`."""

    def __init__(self, node, camera: str):
        base = f"fusepose/camera/{camera}"
        self.frames_name, self.poses_name, self.stats_name = f"{base}/frames", f"{base}/poses", f"{base}/stats"
        # Frames: a dynamic slice of u8 (size 1, alignment 1) with the 128-byte header.
        self.frames = (
            node.service_builder(iox2.ServiceName.new(self.frames_name))
            .publish_subscribe(iox2.Slice[ctypes.c_uint8])
            .user_header(FrameHeader)
            .enable_safe_overflow(True)
            .subscriber_max_buffer_size(2)
            .subscriber_max_borrowed_samples(2)
            .history_size(0)
            .max_publishers(2)
            .max_subscribers(3)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(_attributes())
        )
        self.frame_events = _event(node, self.frames_name)
        self.poses = (
            node.service_builder(iox2.ServiceName.new(self.poses_name))
            .publish_subscribe(PoseMessage)
            .enable_safe_overflow(True)
            .subscriber_max_buffer_size(4)
            .subscriber_max_borrowed_samples(2)
            .history_size(1)
            .max_publishers(2)
            .max_subscribers(16)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(_attributes())
        )
        self.pose_events = _event(node, self.poses_name)
        self.stats = (
            node.service_builder(iox2.ServiceName.new(self.stats_name))
            .request_response(StatsRequest, StatsSnapshot)
            .enable_safe_overflow_for_requests(True)
            .enable_safe_overflow_for_responses(True)
            .max_active_requests_per_client(2)
            .max_response_buffer_size(2)
            .max_servers(2)
            .max_clients(8)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(_attributes())
        )


class CellServices:
    """`fusepose/cell/poses`: every camera's objects in the cell frame (PROTOCOL.md, "Cell poses")."""

    NAME = "fusepose/cell/poses"

    def __init__(self, node):
        self.poses = (
            node.service_builder(iox2.ServiceName.new(self.NAME))
            .publish_subscribe(CellPoseMessage)
            .enable_safe_overflow(True)
            .subscriber_max_buffer_size(4)
            .subscriber_max_borrowed_samples(2)
            .history_size(1)
            .max_publishers(1)
            .max_subscribers(16)
            .max_nodes(MAX_NODES)
            .open_or_create_with_attributes(_attributes())
        )
        self.events = _event(node, self.NAME)
