#!/usr/bin/env python3
"""A ROS 2 peer for tests/tests/ros2_bridge.rs, written against an independent
DDS implementation: Eclipse Cyclone DDS's Python binding (PyPI `cyclonedds`),
with ROS 2 Jazzy message IDL written here and ROS 2's DDS names
(`rt/<topic>`, `pkg::msg::dds_::Name_`), classic CDR (XCDR1), no ROS install.

Publishes rendered frames as a realsense2_camera would (colour, aligned depth,
CameraInfo, all with the same stamp), one frame at a time, and waits for the
`vision_msgs/Detection3DArray` the pose bridge publishes for that stamp on
`rt/fusepose/<camera>/detections` (and, with --cell, every array the cell
bridge publishes on `rt/fusepose/cell/detections`). Prints JSON lines on stdout:
  {"event": "ready"}                         all readers and writers matched
  {"event": "sent", "index": i, "stamp_ns": s}
  {"event": "detections", "stamp_ns": s, "frame_id": f, "detections": [...]}
  {"event": "cell", "stamp_ns": s, "frame_id": f, "detections": [...]}   with --cell
  {"event": "error", "message": m}

Exit status 3 when cyclonedds cannot be imported (the test then skips).

Frames come from DIR/frames.json: [{"color": file, "depth": file, "width": w,
"height": h, "color_encoding": e, "depth_encoding": e, "k": [fx, fy, cx, cy]}].
Runs on loopback only (CYCLONEDDS_URI below) in the given domain.
"""

import argparse
import json
import os
import sys
import time
from dataclasses import dataclass, field

LOOPBACK = (
    "<CycloneDDS><Domain id='any'><General><Interfaces><NetworkInterface address='127.0.0.1'/></Interfaces>"
    "<AllowMulticast>false</AllowMulticast></General><Discovery><ParticipantIndex>auto</ParticipantIndex>"
    "<MaxAutoParticipantIndex>30</MaxAutoParticipantIndex><Peers><Peer address='127.0.0.1'/></Peers>"
    "</Discovery></Domain></CycloneDDS>"
)


def emit(**event):
    print(json.dumps(event), flush=True)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--domain", type=int, required=True)
    ap.add_argument("--frames", required=True, help="folder with frames.json")
    ap.add_argument("--camera", default="cam0")
    ap.add_argument("--match-timeout", type=float, default=60.0)
    ap.add_argument("--frame-timeout", type=float, default=120.0)
    ap.add_argument("--cell", action="store_true", help="also read rt/fusepose/cell/detections")
    ap.add_argument("--check-import", action="store_true", help="only check that cyclonedds imports")
    args = ap.parse_args()

    os.environ.setdefault("CYCLONEDDS_URI", LOOPBACK)
    try:
        from cyclonedds.core import Qos, Policy
        from cyclonedds.domain import DomainParticipant
        from cyclonedds.idl import IdlStruct
        from cyclonedds.idl.types import array, float64, int32, sequence, uint8, uint32
        from cyclonedds.pub import DataWriter
        from cyclonedds.sub import DataReader
        from cyclonedds.topic import Topic
        from cyclonedds.util import duration
    except ImportError as e:
        print(f"cyclonedds not importable: {e}", file=sys.stderr)
        sys.exit(3)
    if args.check_import:
        return

    # ROS 2 Jazzy messages, field by field.
    @dataclass
    class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
        sec: int32
        nanosec: uint32

    @dataclass
    class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
        stamp: Time
        frame_id: str

    @dataclass
    class Image(IdlStruct, typename="sensor_msgs::msg::dds_::Image_"):
        header: Header
        height: uint32
        width: uint32
        encoding: str
        is_bigendian: uint8
        step: uint32
        data: sequence[uint8]

    @dataclass
    class RegionOfInterest(IdlStruct, typename="sensor_msgs::msg::dds_::RegionOfInterest_"):
        x_offset: uint32
        y_offset: uint32
        height: uint32
        width: uint32
        do_rectify: bool

    @dataclass
    class CameraInfo(IdlStruct, typename="sensor_msgs::msg::dds_::CameraInfo_"):
        header: Header
        height: uint32
        width: uint32
        distortion_model: str
        d: sequence[float64]
        k: array[float64, 9]
        r: array[float64, 9]
        p: array[float64, 12]
        binning_x: uint32
        binning_y: uint32
        roi: RegionOfInterest

    @dataclass
    class Point(IdlStruct, typename="geometry_msgs::msg::dds_::Point_"):
        x: float64
        y: float64
        z: float64

    @dataclass
    class Quaternion(IdlStruct, typename="geometry_msgs::msg::dds_::Quaternion_"):
        x: float64
        y: float64
        z: float64
        w: float64

    @dataclass
    class Vector3(IdlStruct, typename="geometry_msgs::msg::dds_::Vector3_"):
        x: float64
        y: float64
        z: float64

    @dataclass
    class Pose(IdlStruct, typename="geometry_msgs::msg::dds_::Pose_"):
        position: Point
        orientation: Quaternion

    @dataclass
    class PoseWithCovariance(IdlStruct, typename="geometry_msgs::msg::dds_::PoseWithCovariance_"):
        pose: Pose
        covariance: array[float64, 36]

    @dataclass
    class ObjectHypothesis(IdlStruct, typename="vision_msgs::msg::dds_::ObjectHypothesis_"):
        class_id: str
        score: float64

    @dataclass
    class ObjectHypothesisWithPose(IdlStruct, typename="vision_msgs::msg::dds_::ObjectHypothesisWithPose_"):
        hypothesis: ObjectHypothesis
        pose: PoseWithCovariance

    @dataclass
    class BoundingBox3D(IdlStruct, typename="vision_msgs::msg::dds_::BoundingBox3D_"):
        center: Pose
        size: Vector3

    @dataclass
    class Detection3D(IdlStruct, typename="vision_msgs::msg::dds_::Detection3D_"):
        header: Header
        results: sequence[ObjectHypothesisWithPose]
        bbox: BoundingBox3D
        id: str

    @dataclass
    class Detection3DArray(IdlStruct, typename="vision_msgs::msg::dds_::Detection3DArray_"):
        header: Header
        detections: sequence[Detection3D]

    frames = json.load(open(os.path.join(args.frames, "frames.json")))
    dp = DomainParticipant(args.domain)
    xcdr1 = Policy.DataRepresentation(use_cdrv0_representation=True)
    # realsense2_camera: images SYSTEM_DEFAULT (reliable, keep last 1), camera_info default (reliable, keep last 10).
    image_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1),
                    Policy.Durability.Volatile, xcdr1)
    info_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10),
                   Policy.Durability.Volatile, xcdr1)
    det_qos = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10),
                  Policy.Durability.Volatile, xcdr1)
    color_w = DataWriter(dp, Topic(dp, "rt/camera/camera/color/image_raw", Image), image_qos)
    depth_w = DataWriter(dp, Topic(dp, "rt/camera/camera/aligned_depth_to_color/image_raw", Image), image_qos)
    info_w = DataWriter(dp, Topic(dp, "rt/camera/camera/color/camera_info", CameraInfo), info_qos)
    det_r = DataReader(dp, Topic(dp, f"rt/fusepose/{args.camera}/detections", Detection3DArray), det_qos)
    cell_r = DataReader(dp, Topic(dp, "rt/fusepose/cell/detections", Detection3DArray), det_qos) if args.cell else None

    # Camera bridge reads colour, depth and info; the pose bridge reads info and writes detections.
    deadline = time.monotonic() + args.match_timeout
    while True:
        counts = (len(color_w.get_matched_subscriptions()), len(depth_w.get_matched_subscriptions()),
                  len(info_w.get_matched_subscriptions()), len(det_r.get_matched_publications()))
        cell_ok = cell_r is None or len(cell_r.get_matched_publications()) >= 1
        if counts[0] >= 1 and counts[1] >= 1 and counts[2] >= 2 and counts[3] >= 1 and cell_ok:
            break
        if time.monotonic() > deadline:
            emit(event="error", message=f"DDS peers never matched (colour, depth, info readers; detection writers): {counts}")
            sys.exit(2)
        time.sleep(0.05)
    time.sleep(0.5)  # let the bridges' side of discovery settle too
    emit(event="ready")

    def header(stamp_ns, frame_id):
        return Header(stamp=Time(sec=stamp_ns // 1_000_000_000, nanosec=stamp_ns % 1_000_000_000), frame_id=frame_id)

    def listed(arr):
        return [{
            "id": d.id,
            "frame_id": d.header.frame_id,
            "stamp_ns": d.header.stamp.sec * 1_000_000_000 + d.header.stamp.nanosec,
            "results": len(d.results),
            "class_id": d.results[0].hypothesis.class_id if d.results else "",
            "score": d.results[0].hypothesis.score if d.results else 0.0,
            "position": [d.results[0].pose.pose.position.x, d.results[0].pose.pose.position.y,
                         d.results[0].pose.pose.position.z] if d.results else [],
            "orientation": [d.results[0].pose.pose.orientation.x, d.results[0].pose.pose.orientation.y,
                            d.results[0].pose.pose.orientation.z,
                            d.results[0].pose.pose.orientation.w] if d.results else [],
            "bbox_center": [d.bbox.center.position.x, d.bbox.center.position.y, d.bbox.center.position.z],
            "bbox_size": [d.bbox.size.x, d.bbox.size.y, d.bbox.size.z],
        } for d in arr.detections]

    def take_cell():
        for arr in (cell_r.take(N=16) if cell_r is not None else []):
            s = arr.header.stamp.sec * 1_000_000_000 + arr.header.stamp.nanosec
            emit(event="cell", stamp_ns=s, frame_id=arr.header.frame_id, detections=listed(arr))

    for index, f in enumerate(frames):
        w, h = f["width"], f["height"]
        color = open(os.path.join(args.frames, f["color"]), "rb").read()
        depth = open(os.path.join(args.frames, f["depth"]), "rb").read()
        dbpp = 2 if f["depth_encoding"] == "16UC1" else 4
        fx, fy, cx, cy = f["k"]
        stamp = time.time_ns()  # ROS clock = CLOCK_REALTIME, as drivers stamp
        frame_id = "camera_color_optical_frame"
        info_w.write(CameraInfo(header=header(stamp, frame_id), height=h, width=w, distortion_model="plumb_bob",
                                d=[0.0] * 5, k=[fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
                                r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
                                p=[fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0], binning_x=0, binning_y=0,
                                roi=RegionOfInterest(x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)))
        depth_w.write(Image(header=header(stamp, frame_id), height=h, width=w, encoding=f["depth_encoding"],
                            is_bigendian=0, step=w * dbpp, data=depth))
        color_w.write(Image(header=header(stamp, frame_id), height=h, width=w, encoding=f["color_encoding"],
                            is_bigendian=0, step=w * 3, data=color))
        emit(event="sent", index=index, stamp_ns=stamp)
        deadline = time.monotonic() + args.frame_timeout
        got = False
        while not got and time.monotonic() < deadline:
            for arr in det_r.take(N=16):
                s = arr.header.stamp.sec * 1_000_000_000 + arr.header.stamp.nanosec
                emit(event="detections", stamp_ns=s, frame_id=arr.header.frame_id, detections=listed(arr))
                got = got or s == stamp
            take_cell()
            if not got:
                time.sleep(0.005)
        if not got:
            emit(event="error", message=f"no detections with stamp {stamp} within {args.frame_timeout} s")
            sys.exit(2)
    # The cell array of the last frame may come just after its camera's.
    end = time.monotonic() + 2.0
    while cell_r is not None and time.monotonic() < end:
        take_cell()
        time.sleep(0.01)
    emit(event="done")


if __name__ == "__main__":
    main()
