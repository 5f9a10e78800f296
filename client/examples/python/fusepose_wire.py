"""fusepose wire types (wire version 3) as ctypes structures, written from docs/PROTOCOL.md.

Every structure is little-endian `#[repr(C)]` without implicit padding; iceoryx2 matches
a type by its name (`type_name()`), size and alignment only, so the sizes and field
offsets are checked at import against the numbers of PROTOCOL.md.
"""

import ctypes
import math

WIRE_VERSION = 3
FRAME_MAGIC = int.from_bytes(b"FPFR", "little")
HEADER_SIZE = 128
MAX_OBJECTS = 32
# Cell poses (PROTOCOL.md, "Cell poses"): objects per message, views listed per object.
MAX_CELL_OBJECTS = 64
MAX_CELL_VIEWS = 4

# FrameHeader format codes.
COLOR_RGB8, COLOR_BGR8 = 1, 2
DEPTH_U16, DEPTH_F32 = 1, 2
LABELS_U8, LABELS_U16, LABELS_INSTANCE_U16 = 1, 2, 3

# PoseMessage.status bits.
STATUS_OK = 1
STATUS_INVALID_FRAME = 2
STATUS_DEADLINE_MISSED = 4
STATUS_DEGRADED = 8
STATUS_ESTIMATOR_FAILED = 16

# WireObjectPose.flags bits.
POSE_VERIFIED = 1
POSE_FROM_INSTANCE_LABELS = 2
POSE_CONFIRMED = 4  # a pose of its class lay within estimator.confirm_within_m in the previous frame

# Rejection reason codes (PoseMessage.invalid_reason, and the index into
# StatsSnapshot.invalid_by_reason).
REASONS = [
    "none", "bad_magic", "version_mismatch", "header_size", "bad_size", "unknown_format",
    "bad_focal_length", "bad_depth_scale", "plane_out_of_bounds", "plane_length",
    "plane_misaligned", "plane_overlap", "wrong_camera", "estimator_refused",
    "bad_principal_point", "payload_truncated", "labels_missing", "depth_empty",
    "depth_non_finite", "label_out_of_range", "sequence_regression", "capture_in_future",
    "capture_too_old", "instance_table_missing", "instance_table_length",
    "instance_table_misaligned", "instance_labels_inconsistent", "instance_beyond_table",
    "instance_class_unknown",
]

# Stats timelines: the six stages of stage_ns, then end to end.
TIMELINES = ["ingest", "segmentation", "sampling", "network", "refine", "publish", "end_to_end"]


def camera_id(name: str) -> int:
    """FNV-1a (32 bit) of the camera name: the id in frame headers and pose messages."""
    h = 0x811C9DC5
    for b in name.encode():
        h = ((h ^ b) * 0x01000193) & 0xFFFFFFFF
    return h


class PlaneRef(ctypes.Structure):
    """Where one plane lies, in bytes from the payload start."""

    _fields_ = [("offset", ctypes.c_uint32), ("len", ctypes.c_uint32)]

    @staticmethod
    def type_name() -> str:
        return "fusepose::PlaneRef"


class FrameHeader(ctypes.Structure):
    """The user header of every frame sample (128 bytes, alignment 8)."""

    _fields_ = [
        ("magic", ctypes.c_uint32),
        ("format_version", ctypes.c_uint16),
        ("header_size", ctypes.c_uint16),
        ("camera_id", ctypes.c_uint32),
        ("width", ctypes.c_uint32),
        ("height", ctypes.c_uint32),
        ("depth_scale", ctypes.c_float),
        ("color_format", ctypes.c_uint8),
        ("depth_format", ctypes.c_uint8),
        ("has_labels", ctypes.c_uint8),
        ("label_format", ctypes.c_uint8),
        ("instance_count", ctypes.c_uint16),
        ("_reserved", ctypes.c_uint16),
        ("sequence", ctypes.c_uint64),
        ("capture_time_ns", ctypes.c_uint64),
        ("fx", ctypes.c_double),
        ("fy", ctypes.c_double),
        ("cx", ctypes.c_double),
        ("cy", ctypes.c_double),
        ("color", PlaneRef),
        ("depth", PlaneRef),
        ("labels", PlaneRef),
        ("instance_classes", PlaneRef),
        ("_reserved_end", ctypes.c_uint8 * 16),
    ]

    @staticmethod
    def type_name() -> str:
        return "fusepose::FrameHeader"


class WireObjectPose(ctypes.Structure):
    """One object's pose, object -> camera (88 bytes)."""

    _fields_ = [
        ("class_id", ctypes.c_uint16),
        ("instance_id", ctypes.c_uint16),
        ("refine_iterations", ctypes.c_uint16),
        ("flags", ctypes.c_uint16),
        ("confidence", ctypes.c_float),
        ("mask_pixels", ctypes.c_uint32),
        ("bbox", ctypes.c_uint16 * 4),
        ("quaternion", ctypes.c_double * 4),
        ("translation_m", ctypes.c_double * 3),
        ("fit_score", ctypes.c_float),
        ("depth_residual_m", ctypes.c_float),
    ]

    @staticmethod
    def type_name() -> str:
        return "fusepose::WireObjectPose"


class PoseMessage(ctypes.Structure):
    """The poses of one frame (2912 bytes, alignment 8)."""

    _fields_ = [
        ("format_version", ctypes.c_uint16),
        ("object_count", ctypes.c_uint16),
        ("status", ctypes.c_uint32),
        ("invalid_reason", ctypes.c_uint32),
        ("camera_id", ctypes.c_uint32),
        ("frame_sequence", ctypes.c_uint64),
        ("capture_time_ns", ctypes.c_uint64),
        ("received_time_ns", ctypes.c_uint64),
        ("published_time_ns", ctypes.c_uint64),
        ("stage_ns", ctypes.c_uint64 * 6),
        ("objects", WireObjectPose * MAX_OBJECTS),
    ]

    @staticmethod
    def type_name() -> str:
        return "fusepose::PoseMessage"


class StatsRequest(ctypes.Structure):
    """A stats query (8 bytes, alignment 2)."""

    _fields_ = [("format_version", ctypes.c_uint16), ("_reserved", ctypes.c_uint8 * 6)]

    @staticmethod
    def type_name() -> str:
        return "fusepose::StatsRequest"


class LatencySummary(ctypes.Structure):
    """Percentiles of one latency histogram, ns (48 bytes)."""

    _fields_ = [
        ("count", ctypes.c_uint64),
        ("p50_ns", ctypes.c_uint64),
        ("p90_ns", ctypes.c_uint64),
        ("p99_ns", ctypes.c_uint64),
        ("p999_ns", ctypes.c_uint64),
        ("max_ns", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "fusepose::LatencySummary"


class StatsSnapshot(ctypes.Structure):
    """The daemon's counters and latency percentiles for one camera (1032 bytes, alignment 8)."""

    _fields_ = [
        ("format_version", ctypes.c_uint16),
        ("_reserved", ctypes.c_uint16),
        ("camera_id", ctypes.c_uint32),
        ("uptime_ns", ctypes.c_uint64),
        ("window_ns", ctypes.c_uint64),
        ("deadline_ns", ctypes.c_uint64),
        ("frames_received", ctypes.c_uint64),
        ("frames_processed", ctypes.c_uint64),
        ("frames_skipped_stale", ctypes.c_uint64),
        ("frames_missed_sequence", ctypes.c_uint64),
        ("frames_invalid", ctypes.c_uint64),
        ("invalid_by_reason", ctypes.c_uint64 * len(REASONS)),
        ("deadline_misses", ctypes.c_uint64),
        ("estimator_failures", ctypes.c_uint64),
        ("poses_non_finite", ctypes.c_uint64),
        ("producer_restarts", ctypes.c_uint64),
        ("since_start", LatencySummary * len(TIMELINES)),
        ("last_window", LatencySummary * len(TIMELINES)),
        ("poses_failed_verification", ctypes.c_uint64),
        ("objects_shed", ctypes.c_uint64),
        ("frames_degraded", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "fusepose::StatsSnapshot"


class CellView(ctypes.Structure):
    """One camera's sight of a cell object (32 bytes)."""

    _fields_ = [
        ("camera_id", ctypes.c_uint32),
        ("instance_id", ctypes.c_uint16),
        ("flags", ctypes.c_uint16),
        ("confidence", ctypes.c_float),
        ("offset_m", ctypes.c_float),
        ("frame_sequence", ctypes.c_uint64),
        ("capture_time_ns", ctypes.c_uint64),
    ]

    @staticmethod
    def type_name() -> str:
        return "fusepose::CellView"


class CellObject(ctypes.Structure):
    """One object in the cell frame (216 bytes)."""

    _fields_ = [
        ("class_id", ctypes.c_uint16),
        ("view_count", ctypes.c_uint16),
        ("flags", ctypes.c_uint16),
        ("reserved", ctypes.c_uint16),
        ("confidence", ctypes.c_float),
        ("spread_m", ctypes.c_float),
        ("quaternion", ctypes.c_double * 4),
        ("translation_m", ctypes.c_double * 3),
        ("newest_capture_time_ns", ctypes.c_uint64),
        ("oldest_capture_time_ns", ctypes.c_uint64),
        ("views", CellView * MAX_CELL_VIEWS),
    ]

    @staticmethod
    def type_name() -> str:
        return "fusepose::CellObject"


class CellPoseMessage(ctypes.Structure):
    """Every camera's objects in the cell frame (13856 bytes, alignment 8)."""

    _fields_ = [
        ("format_version", ctypes.c_uint16),
        ("object_count", ctypes.c_uint16),
        ("camera_count", ctypes.c_uint16),
        ("truncated", ctypes.c_uint16),
        ("trigger_camera_id", ctypes.c_uint32),
        ("reserved", ctypes.c_uint32),
        ("sequence", ctypes.c_uint64),
        ("published_time_ns", ctypes.c_uint64),
        ("objects", CellObject * MAX_CELL_OBJECTS),
    ]

    @staticmethod
    def type_name() -> str:
        return "fusepose::CellPoseMessage"


def _check(struct, size, align, offsets):
    assert ctypes.sizeof(struct) == size, f"{struct.__name__}: size {ctypes.sizeof(struct)} != {size}"
    assert ctypes.alignment(struct) == align, f"{struct.__name__}: alignment {ctypes.alignment(struct)} != {align}"
    for field, offset in offsets.items():
        got = getattr(struct, field).offset
        assert got == offset, f"{struct.__name__}.{field}: offset {got} != {offset}"


# The numbers of docs/PROTOCOL.md ("Frames", "Poses", "Stats").
_check(FrameHeader, 128, 8, {"label_format": 27, "instance_count": 28, "sequence": 32, "fx": 48,
                             "color": 80, "depth": 88, "labels": 96, "instance_classes": 104})
_check(WireObjectPose, 88, 8, {"flags": 6, "confidence": 8, "bbox": 16, "quaternion": 24,
                               "translation_m": 56, "fit_score": 80, "depth_residual_m": 84})
_check(PoseMessage, 2912, 8, {"status": 4, "frame_sequence": 16, "published_time_ns": 40,
                              "stage_ns": 48, "objects": 96})
_check(StatsRequest, 8, 2, {"_reserved": 2})
_check(LatencySummary, 48, 8, {"max_ns": 40})
_check(StatsSnapshot, 1032, 8, {"frames_received": 32, "invalid_by_reason": 72, "deadline_misses": 304,
                                "producer_restarts": 328, "since_start": 336, "last_window": 672,
                                "poses_failed_verification": 1008, "objects_shed": 1016, "frames_degraded": 1024})
_check(CellView, 32, 8, {"instance_id": 4, "flags": 6, "confidence": 8, "offset_m": 12, "frame_sequence": 16,
                         "capture_time_ns": 24})
_check(CellObject, 216, 8, {"confidence": 8, "spread_m": 12, "quaternion": 16, "translation_m": 48,
                            "newest_capture_time_ns": 72, "oldest_capture_time_ns": 80, "views": 88})
_check(CellPoseMessage, 13856, 8, {"camera_count": 4, "truncated": 6, "trigger_camera_id": 8, "sequence": 16,
                                   "published_time_ns": 24, "objects": 32})


def align8(n: int) -> int:
    return (n + 7) // 8 * 8


def _finite_or_none(x: float):
    """JSON has no NaN: unverified poses carry NaN fit values (PROTOCOL.md, "Poses")."""
    return x if math.isfinite(x) else None


def pose_to_dict(msg: PoseMessage) -> dict:
    """A pose message as plain values (the valid objects only)."""
    count = min(msg.object_count, MAX_OBJECTS)
    return {
        "format_version": msg.format_version,
        "camera_id": msg.camera_id,
        "frame_sequence": msg.frame_sequence,
        "status": msg.status,
        "invalid_reason": REASONS[msg.invalid_reason] if msg.status & STATUS_INVALID_FRAME and msg.invalid_reason < len(REASONS) else "",
        "capture_time_ns": msg.capture_time_ns,
        "received_time_ns": msg.received_time_ns,
        "published_time_ns": msg.published_time_ns,
        "stage_ns": list(msg.stage_ns),
        "objects": [
            {
                "class_id": o.class_id,
                "instance_id": o.instance_id,
                "refine_iterations": o.refine_iterations,
                "flags": o.flags,
                "confidence": o.confidence,
                "mask_pixels": o.mask_pixels,
                "bbox": list(o.bbox),
                "quaternion_xyzw": list(o.quaternion),
                "translation_m": list(o.translation_m),
                "fit_score": _finite_or_none(o.fit_score),
                "depth_residual_m": _finite_or_none(o.depth_residual_m),
            }
            for o in msg.objects[:count]
        ],
    }


def stats_to_dict(s: StatsSnapshot) -> dict:
    """A stats snapshot as plain values; rejections by reason name, latencies in ms."""
    def summary(t):
        return {"count": t.count, "p50_ms": t.p50_ns / 1e6, "p99_ms": t.p99_ns / 1e6, "max_ms": t.max_ns / 1e6}

    return {
        "format_version": s.format_version,
        "camera_id": s.camera_id,
        "uptime_s": s.uptime_ns / 1e9,
        "deadline_ms": s.deadline_ns / 1e6,
        "frames_received": s.frames_received,
        "frames_processed": s.frames_processed,
        "frames_skipped_stale": s.frames_skipped_stale,
        "frames_missed_sequence": s.frames_missed_sequence,
        "frames_invalid": s.frames_invalid,
        "invalid_by_reason": {REASONS[i]: n for i, n in enumerate(s.invalid_by_reason) if n},
        "deadline_misses": s.deadline_misses,
        "estimator_failures": s.estimator_failures,
        "since_start": {TIMELINES[i]: summary(t) for i, t in enumerate(s.since_start) if t.count},
    }


def cell_to_dict(msg: CellPoseMessage) -> dict:
    """A cell message as plain values (the valid objects and their listed views only)."""
    def view(v):
        return {"camera_id": v.camera_id, "instance_id": v.instance_id, "flags": v.flags, "confidence": v.confidence,
                "offset_m": v.offset_m, "frame_sequence": v.frame_sequence, "capture_time_ns": v.capture_time_ns}

    return {
        "format_version": msg.format_version,
        "camera_count": msg.camera_count,
        "truncated": msg.truncated,
        "trigger_camera_id": msg.trigger_camera_id,
        "sequence": msg.sequence,
        "published_time_ns": msg.published_time_ns,
        "objects": [
            {
                "class_id": o.class_id,
                "view_count": o.view_count,
                "flags": o.flags,
                "confidence": o.confidence,
                "spread_m": o.spread_m,
                "quaternion_xyzw": list(o.quaternion),
                "translation_m": list(o.translation_m),
                "newest_capture_time_ns": o.newest_capture_time_ns,
                "oldest_capture_time_ns": o.oldest_capture_time_ns,
                "views": [view(v) for v in o.views[: min(o.view_count, MAX_CELL_VIEWS)]],
            }
            for o in msg.objects[: min(msg.object_count, MAX_CELL_OBJECTS)]
        ],
    }
