#!/usr/bin/env python3
"""Feed a running `pssba run --input live --instance NAME` from another process, in Python.

  python3 tools/pssba_live.py publish DIR --instance NAME [--rate HZ] [--timeout S]
  python3 tools/pssba_live.py poses --instance NAME --out FILE.tum [--timeout S]

`publish` streams a dataset folder (frames/*.pcd as binary x y z float32, poses.txt in TUM,
optional gt.txt) into the instance's frames service; `poses` writes each frame's final pose
as it becomes final (pssba/final_poses), in TUM with the frames' stamps. Both follow
docs/interface.md, implemented here from that document on the PyPI package iceoryx2 (pin:
0.10.0, the version the pssba binary is built with; iceoryx2 refuses other versions).

Only the package `iceoryx2==0.10.0` is needed (no numpy). `publish` exits 0 once every frame
and the end-of-stream marker are sent and the system has detached; `poses` once the
end-of-stream marker of the final poses has arrived.
"""

import argparse
import ctypes
import math
import os
import signal
import sys
import time
from pathlib import Path

import iceoryx2 as iox2

# Every service of an instance is pssba/<instance>/<suffix> (docs/interface.md).
FRAMES = "frames"
FRAMES_READY = "frames/ready"
# Ready ids of the system's frame consumers (smooth, record): sending starts once both are in.
SYSTEM_CONSUMERS = {1, 2}
# Frames queued per consumer before the publisher waits (lossless 'block' policy).
FRAME_BUFFER = 8


class PointXyz(ctypes.Structure):
    _fields_ = [("xyz_m", ctypes.c_float * 3)]

    @staticmethod
    def type_name() -> str:
        return "pssba::PointXyz"


class IsometryMsg(ctypes.Structure):
    _fields_ = [("quaternion_xyzw", ctypes.c_double * 4), ("translation_m", ctypes.c_double * 3)]

    @staticmethod
    def type_name() -> str:
        return "pssba::IsometryMsg"


class FrameHeader(ctypes.Structure):
    _fields_ = [
        ("sequence", ctypes.c_uint64),
        ("stamp_s", ctypes.c_double),
        ("world_from_lidar", IsometryMsg),
        ("ground_truth", IsometryMsg),
        ("has_ground_truth", ctypes.c_uint32),
        ("end_of_stream", ctypes.c_uint32),
        ("sent_unix_ns", ctypes.c_uint64),
        ("layout_version", ctypes.c_uint32),
        ("timed_points", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name() -> str:
        return "pssba::FrameHeader"


class FinalPoseMsg(ctypes.Structure):
    _fields_ = [
        ("sequence", ctypes.c_uint64),
        ("stamp_s", ctypes.c_double),
        ("world_from_lidar", IsometryMsg),
        ("window", ctypes.c_uint64),
        ("kept_initial", ctypes.c_uint32),
        ("end_of_stream", ctypes.c_uint32),
    ]

    @staticmethod
    def type_name() -> str:
        return "pssba::FinalPoseMsg"


assert ctypes.sizeof(PointXyz) == 12 and ctypes.sizeof(FrameHeader) == 152
# The frames layout this tool writes (docs/interface.md): version 2, each point's time after
# the stamp (the PCD's `time` field, float32 s) packed after the points; a frame whose PCD has
# no time field goes with timed_points 0 (taken at one instant). The system reads versions 1
# and 2 and refuses any other.
FRAME_LAYOUT_VERSION = 2
assert ctypes.sizeof(FinalPoseMsg) == 88

FINAL_POSES = "final_poses"
FINAL_POSE_SUBSCRIBERS = 8
FINAL_POSE_HISTORY = 4096


def live_prefix(instance: str) -> str:
    return f"pssba-live-{instance}-"


def create_node(instance: str, name: str):
    config = iox2.config.default()
    config.global_cfg.prefix = iox2.FileName.new(live_prefix(instance))
    return (iox2.NodeBuilder.new().name(iox2.NodeName.new(name)).config(config)
            .create(iox2.ServiceType.Ipc))


def service_name(instance: str, suffix: str):
    return iox2.ServiceName.new(f"pssba/{instance}/{suffix}")


def frames_service(node, instance: str):
    return (node.service_builder(service_name(instance, FRAMES))
            .publish_subscribe(iox2.Slice[PointXyz]).user_header(FrameHeader)
            .max_publishers(1).max_subscribers(len(SYSTEM_CONSUMERS)).history_size(0)
            .subscriber_max_buffer_size(FRAME_BUFFER).subscriber_max_borrowed_samples(1)
            .enable_safe_overflow(False).open_or_create())


def event_service(node, instance: str, suffix: str):
    return (node.service_builder(service_name(instance, suffix + "/event")).event()
            .max_notifiers(4).max_listeners(4).open_or_create())


# --- the dataset folder -------------------------------------------------------------------

def read_pcd(path: Path):
    """x y z of a binary PCD with float32 x, y, z fields, packed as 12 bytes per point, and
    its float32 `time` field (s after the stamp) packed as 4 bytes per point, or None."""
    raw = path.read_bytes()
    header = {}
    offset = 0
    while True:
        end = raw.index(b"\n", offset)
        line = raw[offset:end].decode("ascii").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, _, value = line.partition(" ")
        header[key.upper()] = value.split()
        if key.upper() == "DATA":
            break
    if header["DATA"][0] != "binary":
        sys.exit(f"{path}: DATA {header['DATA'][0]}: only binary PCD is read here")
    fields, sizes, types = header["FIELDS"], [int(s) for s in header["SIZE"]], header["TYPE"]
    counts = [int(c) for c in header.get("COUNT", ["1"] * len(fields))]
    points = int(header["POINTS"][0])
    step = sum(s * c for s, c in zip(sizes, counts))
    offsets, at = {}, 0
    for name, size, kind, count in zip(fields, sizes, types, counts):
        offsets[name] = (at, size, kind)
        at += size * count
    for name in "xyz":
        if offsets.get(name, (0, 0, ""))[1:] != (4, "F"):
            sys.exit(f"{path}: field {name} must be float32 (SIZE 4, TYPE F)")
    if "time" in offsets and offsets["time"][1:] != (4, "F"):
        sys.exit(f"{path}: field time must be float32 (SIZE 4, TYPE F)")
    body = raw[offset:offset + points * step]
    if len(body) != points * step:
        sys.exit(f"{path}: {len(body)} data bytes, {points} points x {step} expected")
    times = None
    if "time" in offsets:
        at = offsets["time"][0]
        times = b"".join(body[k * step + at:k * step + at + 4] for k in range(points))
    if step == 12 and [offsets[n][0] for n in "xyz"] == [0, 4, 8]:
        return body, times
    out = bytearray(points * 12)
    for k in range(points):
        for j, name in enumerate("xyz"):
            o = k * step + offsets[name][0]
            out[k * 12 + 4 * j:k * 12 + 4 * j + 4] = body[o:o + 4]
    return bytes(out), times


def payload_elements(points: int, timed: bool) -> int:
    """Elements (12 bytes) of a frame's payload: the points, then their times three to one."""
    return points + ((points + 2) // 3 if timed else 0)


def read_tum(path: Path):
    poses = []
    for number, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        values = [float(v) for v in line.split()]
        if len(values) != 8 or not all(math.isfinite(v) for v in values):
            sys.exit(f"{path}: line {number}: expected 8 finite numbers")
        stamp, tx, ty, tz, qx, qy, qz, qw = values
        # The system accepts |q| within 1e-9 of 1: normalise what TUM rounded, summing the
        # squares in the order pssba's reader does (nalgebra: (x²+z²) + (y²+w²)), so that the
        # same file gives the same bits here as through `pssba run --dataset`.
        norm = math.sqrt((qx * qx + qz * qz) + (qy * qy + qw * qw))
        poses.append((stamp, (tx, ty, tz), (qx / norm, qy / norm, qz / norm, qw / norm)))
    return poses


def set_isometry(msg: IsometryMsg, pose) -> None:
    _, t, q = pose
    msg.quaternion_xyzw[:] = list(q)
    msg.translation_m[:] = list(t)


# --- publish ------------------------------------------------------------------------------

def publish(args) -> int:
    folder = Path(args.dir)
    frames = sorted((folder / "frames").glob("*.pcd"))
    poses = read_tum(folder / "poses.txt")
    gt_path = folder / "gt.txt"
    gt = read_tum(gt_path) if gt_path.exists() else None
    if not frames or len(poses) != len(frames) or (gt is not None and len(gt) != len(frames)):
        sys.exit(f"{folder}: {len(frames)} frames, {len(poses)} poses"
                 + (f", {len(gt)} ground-truth poses" if gt is not None else ""))
    capacity = max(payload_elements(len(xyz) // 12, times is not None)
                   for xyz, times in map(read_pcd, frames))

    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    node = create_node(args.instance, "pssba_live_py_publisher")
    # The listener exists before the publisher, so no consumer's ready report is missed.
    ready = event_service(node, args.instance, FRAMES_READY).listener_builder().create()
    service = frames_service(node, args.instance)
    publisher = (service.publisher_builder().initial_max_slice_len(max(capacity, 1))
                 .allocation_strategy(iox2.AllocationStrategy.Static).max_loaned_samples(1)
                 .backpressure_strategy(iox2.BackpressureStrategy.RetryUntilDelivered).create())
    notifier = event_service(node, args.instance, FRAMES).notifier_builder().create()

    seen = set()
    deadline = time.monotonic() + args.timeout
    while not SYSTEM_CONSUMERS <= seen:
        if time.monotonic() > deadline:
            sys.exit(f"instance {args.instance}: the system's frame consumers did not report "
                     f"ready within {args.timeout} s (ready: {sorted(seen)}); is "
                     f"`pssba run --input live --instance {args.instance}` running?")
        for activation in ready.timed_wait(iox2.Duration.from_millis(100)):
            seen.add(activation.id.as_value)

    def send(header: FrameHeader, points: bytes, times=None) -> None:
        n = len(points) // 12
        payload = points
        if times is not None and n:
            # n float32 times padded with zeros to whole 12-byte elements.
            payload += times + bytes(payload_elements(n, True) * 12 - len(points) - len(times))
            header.timed_points = n
        sample = publisher.loan_slice_uninit(len(payload) // 12)
        if payload:
            ctypes.memmove(sample.payload_ptr, payload, len(payload))
        header.sent_unix_ns = time.time_ns()
        header.layout_version = FRAME_LAYOUT_VERSION
        sample.user_header()[0] = header  # ptr[0] = ... writes shared memory; .contents does not
        sample.assume_init().send()
        notifier.notify()

    period = 1.0 / args.rate if args.rate else 0.0
    started = time.monotonic()
    for k, path in enumerate(frames):
        if period:
            time.sleep(max(0.0, started + k * period - time.monotonic()))
        header = FrameHeader(sequence=k, stamp_s=poses[k][0])
        set_isometry(header.world_from_lidar, poses[k])
        if gt is not None:
            set_isometry(header.ground_truth, gt[k])
            header.has_ground_truth = 1
        send(header, *read_pcd(path))
        if args.die_after is not None and k + 1 == args.die_after:
            # A crashed producer, for tests: no end-of-stream marker, no clean-up.
            os.kill(os.getpid(), signal.SIGKILL)
    send(FrameHeader(sequence=len(frames), end_of_stream=1), b"")
    print(f"pssba_live: sent {len(frames)} frames and the end-of-stream marker to instance "
          f"{args.instance}", file=sys.stderr)
    # Samples live in this process's shared memory: stay until the consumers detach.
    deadline = time.monotonic() + args.timeout
    while service.dynamic_config.number_of_subscribers > 0 and time.monotonic() < deadline:
        node.wait(iox2.Duration.from_millis(10))
    del notifier, publisher, service, ready, node
    return 0


def poses(args) -> int:
    """Writes each final pose as it arrives, in TUM with the frames' stamps; exits after the
    end-of-stream marker (or after --timeout s without a message)."""
    iox2.set_log_level_from_env_or(iox2.LogLevel.Warn)
    node = create_node(args.instance, "pssba_live_py_poses")
    service = (node.service_builder(service_name(args.instance, FINAL_POSES))
               .publish_subscribe(FinalPoseMsg).max_publishers(1)
               .max_subscribers(FINAL_POSE_SUBSCRIBERS).history_size(FINAL_POSE_HISTORY)
               .subscriber_max_buffer_size(FINAL_POSE_HISTORY).subscriber_max_borrowed_samples(8)
               .enable_safe_overflow(True).open_or_create())
    subscriber = service.subscriber_builder().create()
    received, kept_initial, last_message = 0, 0, time.monotonic()
    with open(args.out, "w") as out:
        while True:
            sample = subscriber.receive()
            if sample is None:
                if time.monotonic() - last_message > args.timeout:
                    sys.exit(f"instance {args.instance}: no final pose for {args.timeout} s "
                             f"({received} received); is the system running?")
                node.wait(iox2.Duration.from_millis(5))
                continue
            last_message = time.monotonic()
            message = FinalPoseMsg.from_buffer_copy(sample.payload().contents)
            sample.delete()
            if message.end_of_stream:
                if message.sequence != received:
                    sys.exit(f"end of stream after {message.sequence} final poses, "
                             f"{received} received (a slow reader loses the oldest)")
                break
            q, t = message.world_from_lidar.quaternion_xyzw, message.world_from_lidar.translation_m
            # 12 decimals: the poses as the system holds them (to 5e-13), not TUM's usual 9.
            out.write(f"{message.stamp_s:.9f} {t[0]:.12f} {t[1]:.12f} {t[2]:.12f} "
                      f"{q[0]:.12f} {q[1]:.12f} {q[2]:.12f} {q[3]:.12f}\n")
            out.flush()
            received += 1
            kept_initial += message.kept_initial
    print(f"pssba_live: wrote {received} final poses to {args.out}"
          + (f" ({kept_initial} from failed windows kept their initial pose)" if kept_initial else ""),
          file=sys.stderr)
    del subscriber, service, node
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    pub = sub.add_parser("publish", help="stream a dataset folder into a live instance")
    pub.add_argument("dir", help="dataset folder (frames/*.pcd, poses.txt, optional gt.txt)")
    pub.add_argument("--instance", required=True, help="the instance of `pssba run --input live`")
    pub.add_argument("--rate", type=float, help="frames per second (default: as fast as taken)")
    pub.add_argument("--timeout", type=float, default=60.0,
                     help="seconds to wait for the system to be ready, and to detach")
    pub.add_argument("--die-after", type=int, metavar="N",
                     help="SIGKILL this process right after sending frame N (tests: a producer "
                          "that crashes mid-stream)")
    sub_poses = sub.add_parser("poses", help="write each final pose as it arrives (TUM)")
    sub_poses.add_argument("--instance", required=True, help="the instance of `pssba run --input live`")
    sub_poses.add_argument("--out", required=True, help="TUM file to write")
    sub_poses.add_argument("--timeout", type=float, default=600.0,
                           help="give up after this many seconds without a final pose")
    args = parser.parse_args()
    if args.command == "publish":
        return publish(args)
    if args.command == "poses":
        return poses(args)
    return 2


if __name__ == "__main__":
    sys.exit(main())
