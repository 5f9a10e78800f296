#!/usr/bin/env python3
"""A fusepose client in Python, written from docs/PROTOCOL.md with the PyPI `iceoryx2`
package (pip install iceoryx2==0.10.0): a camera that publishes synthetic RGB-D frames,
a consumer of the daemon's pose messages, and a stats query.

    python3 fusepose_example.py run --frames 20 --fps 10      # all three against a running fuseposed
    python3 fusepose_example.py produce --frames 100 --fps 30
    python3 fusepose_example.py consume --count 10
    python3 fusepose_example.py stats

The namespace comes from FUSEPOSE_IOX2_ROOT / FUSEPOSE_IOX2_PREFIX like every fusepose
tool. Output: one JSON line per pose message (`pose {...}`), the stats snapshot
(`stats {...}`), and `done ...` at the end of `run`.
"""

import argparse
import array
import ctypes
import json
import sys
import time

import iceoryx2 as iox2

import fusepose_wire as w
from fusepose_ipc import CameraServices, CellServices, create_node


def monotonic_ns() -> int:
    """CLOCK_MONOTONIC, the clock of every fusepose timestamp."""
    return time.clock_gettime_ns(time.CLOCK_MONOTONIC)


class Camera:
    """Publishes 640x480 RGB8 + u16 depth (mm) + u8 class labels: one 100x80 px box of
    class 1 on a table 0.8 m away (a stand-in for a real camera SDK)."""

    WIDTH, HEIGHT, FX, CX, CY = 640, 480, 525.0, 319.5, 239.5

    def __init__(self, services: CameraServices, camera: str, labels: bool = True):
        self.camera_id = w.camera_id(camera)
        n = self.WIDTH * self.HEIGHT
        self.color = w.PlaneRef(0, n * 3)
        self.depth = w.PlaneRef(w.align8(self.color.len), n * 2)
        self.labels = w.PlaneRef(w.align8(self.depth.offset + self.depth.len), n) if labels else w.PlaneRef(0, 0)
        self.payload_len = max(self.depth.offset + self.depth.len, self.labels.offset + self.labels.len)
        # Plane bytes, prepared once; planes are row-major, top row first, little-endian.
        depth = array.array("H", [800]) * n
        box = array.array("H", [700]) * 100
        label_plane = bytearray(n)
        for v in range(200, 280):
            depth[v * self.WIDTH + 270 : v * self.WIDTH + 370] = box
            label_plane[v * self.WIDTH + 270 : v * self.WIDTH + 370] = b"\x01" * 100
        if sys.byteorder != "little":
            depth.byteswap()
        self.depth_bytes = depth.tobytes()
        self.label_bytes = bytes(label_plane)
        self.publisher = (
            services.frames.publisher_builder()
            .initial_max_slice_len(self.payload_len)
            .allocation_strategy(iox2.AllocationStrategy.Static)
            .max_loaned_samples(2)
            .create()
        )
        self.notifier = services.frame_events.notifier_builder().create()

    def send(self, sequence: int) -> None:
        sample = self.publisher.loan_slice_uninit(self.payload_len)
        h = sample.user_header().contents
        ctypes.memset(ctypes.addressof(h), 0, ctypes.sizeof(h))
        h.magic, h.format_version, h.header_size = w.FRAME_MAGIC, w.WIRE_VERSION, w.HEADER_SIZE
        h.camera_id, h.width, h.height = self.camera_id, self.WIDTH, self.HEIGHT
        h.depth_scale, h.color_format, h.depth_format = 0.001, w.COLOR_RGB8, w.DEPTH_U16
        h.has_labels = 1 if self.labels.len else 0
        h.label_format = w.LABELS_U8 if self.labels.len else 0  # 0 without labels
        h.sequence, h.capture_time_ns = sequence, monotonic_ns()
        h.fx, h.fy, h.cx, h.cy = self.FX, self.FX, self.CX, self.CY
        h.color, h.depth, h.labels = self.color, self.depth, self.labels
        base = sample.payload().as_ptr()
        # Every byte of the payload is written: the slot holds an older frame's bytes.
        ctypes.memset(base, 0, self.payload_len)
        ctypes.memset(base + self.color.offset, (sequence * 7) % 251, self.color.len)
        ctypes.memmove(base + self.depth.offset, self.depth_bytes, self.depth.len)
        if self.labels.len:
            ctypes.memmove(base + self.labels.offset, self.label_bytes, self.labels.len)
        sample.assume_init().send()
        self.notifier.notify()  # event id 0; the daemon only needs the wake-up


def drain(subscriber, to_dict, what: str) -> list:
    """Every message waiting on `subscriber`, oldest first, as dicts; refuses another wire version."""
    out = []
    while True:
        sample = subscriber.receive()
        if sample is None:
            return out
        msg = sample.payload().contents
        if msg.format_version != w.WIRE_VERSION:
            raise RuntimeError(f"{what} of wire version {msg.format_version}, this client speaks {w.WIRE_VERSION}")
        out.append(to_dict(msg))
        sample.delete()  # give the sample back at once (2 may be held)


class PoseReader:
    """Receives every pose message of the camera."""

    def __init__(self, services: CameraServices):
        self.subscriber = services.poses.subscriber_builder().create()
        self.listener = services.pose_events.listener_builder().create()

    def wait(self, timeout_s: float) -> list:
        """Pose messages (as dicts) received within `timeout_s`, oldest first."""
        out = self.drain()
        if not out:
            self.listener.timed_wait(iox2.Duration.from_secs_f64(timeout_s))
            out = self.drain()
        return out

    def drain(self) -> list:
        return drain(self.subscriber, w.pose_to_dict, "pose message")


class CellReader:
    """Receives the cell's messages (every camera's objects in the cell frame)."""

    def __init__(self, node):
        self.subscriber = CellServices(node).poses.subscriber_builder().create()

    def drain(self) -> list:
        return drain(self.subscriber, w.cell_to_dict, "cell message")


def query_stats(services: CameraServices, timeout_s: float = 2.0) -> dict:
    client = services.stats.client_builder().create()
    request = w.StatsRequest(w.WIRE_VERSION)
    pending = client.send_copy(request)
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        response = pending.receive()
        if response is not None:
            snapshot = response.payload().contents
            if snapshot.format_version != w.WIRE_VERSION:
                raise RuntimeError(f"stats of wire version {snapshot.format_version}")
            return w.stats_to_dict(snapshot)
        time.sleep(0.005)
    raise TimeoutError(f"no answer on {services.stats_name} within {timeout_s} s (is fuseposed running?)")


def print_line(kind: str, value) -> None:
    print(kind, json.dumps(value, sort_keys=True, allow_nan=False), flush=True)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--camera", default="cam0")
    sub = parser.add_subparsers(dest="role", required=True)
    run = sub.add_parser("run", help="produce frames, print the poses answering them, then the stats")
    produce = sub.add_parser("produce", help="publish frames")
    for p in (run, produce):
        p.add_argument("--frames", type=int, default=20)
        p.add_argument("--fps", type=float, default=10.0)
        p.add_argument("--no-labels", action="store_true", help="send no label plane (the daemon segments)")
    consume = sub.add_parser("consume", help="print pose messages")
    consume.add_argument("--count", type=int, default=10)
    consume.add_argument("--timeout-s", type=float, default=10.0)
    sub.add_parser("stats", help="print the daemon's stats snapshot")
    args = parser.parse_args()

    iox2.set_log_level(iox2.LogLevel.Warn)
    node = create_node(f"fusepose-python-{args.role}")
    services = CameraServices(node, args.camera)
    print("ready", flush=True)

    if args.role == "stats":
        print_line("stats", query_stats(services))
        return 0
    if args.role == "consume":
        reader, seen = PoseReader(services), 0
        deadline = time.monotonic() + args.timeout_s
        while seen < args.count and time.monotonic() < deadline:
            for msg in reader.wait(0.5):
                print_line("pose", msg)
                seen += 1
        return 0 if seen >= args.count else 1

    camera = Camera(services, args.camera, labels=not args.no_labels)
    reader = PoseReader(services) if args.role == "run" else None
    cell = CellReader(node) if args.role == "run" else None
    started = monotonic_ns()
    answered = set()
    period = 1.0 / args.fps
    t0 = time.monotonic()
    for i in range(args.frames):
        camera.send(i)
        if reader is not None:
            for msg in reader.drain():
                # History 1 replays the newest message of an earlier run: skip anything older than us.
                if msg["published_time_ns"] >= started:
                    answered.add(msg["frame_sequence"])
                    print_line("pose", msg)
        time.sleep(max(0.0, t0 + (i + 1) * period - time.monotonic()))
    if reader is None:
        print(f"done sent={args.frames}", flush=True)
        return 0
    # The last frames' answers.
    deadline = time.monotonic() + 5.0
    while args.frames - 1 not in answered and time.monotonic() < deadline:
        for msg in reader.wait(0.2):
            if msg["published_time_ns"] >= started:
                answered.add(msg["frame_sequence"])
                print_line("pose", msg)
    for msg in cell.drain():
        if msg["published_time_ns"] >= started:
            print_line("cell", msg)
    print_line("stats", query_stats(services))
    print(f"done sent={args.frames} answered={len(answered)}", flush=True)
    return 0 if answered else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except iox2.ListenerWaitError:  # SIGINT / SIGTERM while waiting
        sys.exit(130)
