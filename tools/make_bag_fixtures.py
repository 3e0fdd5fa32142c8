#!/usr/bin/env python3
"""Write small ROS bag test fixtures for pssba's bag reader, with an independent writer.

The bags are written with the PyPI package `rosbags` (pinned in
tools/requirements-fixtures.txt), not with pssba's own code, so a reader test
against them is not a round trip through one implementation.

Usage:
    python3 tools/make_bag_fixtures.py SOURCE_DIR OUT_DIR           # write, then verify
    python3 tools/make_bag_fixtures.py --verify SOURCE_DIR OUT_DIR  # verify only

SOURCE_DIR is a pssba dataset folder (frames/NNNNNN.pcd as binary PCD with x y z
float32, poses.txt = noisy world_from_lidar in TUM format). The script reads the
PCD frames with its own tiny binary PCD reader and poses.txt, and writes into
OUT_DIR (replacing only these names, nothing else in OUT_DIR):

  ros1_lz4.bag          ROS 1, LZ4 chunks (64 KiB threshold, several chunks):
                        /points_raw sensor_msgs/PointCloud2 (x y z intensity float32,
                        3 NaN points appended per cloud, is_dense false),
                        /Odometry nav_msgs/Odometry at 25 Hz (camera_init -> body),
                        /tf_static tf2_msgs/TFMessage (body -> livox_frame, latched)
  ros1_bz2_livox.bag    ROS 1, BZ2 chunks: /livox/lidar livox_ros_driver/CustomMsg,
                        /pose geometry_msgs/PoseStamped (world_from_lidar at cloud stamps)
  ros2_mcap/            rosbag2 (MCAP storage, uncompressed): /points organized
                        PointCloud2 (4 rows, float64 x y z, NaN padding),
                        /pose geometry_msgs/msg/PoseStamped
  ros2_sqlite3/         rosbag2 (sqlite3 storage): /livox/lidar
                        livox_ros_driver2/msg/CustomMsg, /Odometry 25 Hz, /tf_static
  small/bigendian.bag   ROS 1, 3 frames x 60 points, big-endian float32 x y z
  small/no_z.bag        ROS 1, PointCloud2 with only x y fields
  small/bad_row_step.bag ROS 1, row_step*height != len(data)
  small/nan_pose.bag    ROS 1, little-endian, second /pose has NaN position.x
  small/no_overlap.bag  ROS 1, /pose stamps 100 s after the last cloud
  small/cloud_registered.bag ROS 1, clouds already in the world frame (frame_id camera_init,
                        float32 world_from_lidar * p, as FAST-LIO's /cloud_registered)
  small/ros2.mcap       bare MCAP file (ros2 profile, cdr) with /points + /pose
  expected_odometry_world_from_lidar.txt
                        TUM (source stamps, no offset): world_from_lidar a reader
                        gets at each cloud stamp by interpolating the written
                        /Odometry samples (lerp + slerp) and applying the
                        /tf_static extrinsic. It differs from poses.txt at odd
                        frames, whose stamps fall between two 25 Hz samples that
                        lie on different TUM segments.

All bag stamps (header stamps and bag record/log times) are STAMP_OFFSET_S + the
TUM stamp. Poses in body frame are world_from_body = world_from_lidar *
inverse(body_from_lidar). Output is deterministic (no randomness; the same
rosbags version gives byte-identical files).
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
from rosbags.highlevel import AnyReader
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

# ---------------------------------------------------------------------------
# Constants

STAMP_OFFSET_S = 1_700_000_000.0
STAMP_OFFSET_NS = 1_700_000_000 * 1_000_000_000  # the same offset, as an exact integer

WORLD_FRAME = 'camera_init'
BODY_FRAME = 'body'
LIDAR_FRAME = 'livox_frame'

ODOM_PERIOD_NS = 40_000_000  # 25 Hz

# body_from_lidar: translation (m) and 10 deg about the normalized axis (1, 2, 3)
EXTRINSIC_T = np.array([0.10, -0.05, 0.20])
_AXIS = np.array([1.0, 2.0, 3.0]) / math.sqrt(14.0)
_HALF = math.radians(10.0) / 2.0
EXTRINSIC_Q = np.array([*(math.sin(_HALF) * _AXIS), math.cos(_HALF)])  # x y z w

N_NAN_APPENDED = 3  # ros1_lz4.bag: NaN points at the end of each cloud
ORGANIZED_ROWS = 4  # ros2_mcap: rows of the organized cloud
SMALL_FRAMES = 3
SMALL_POINTS = 60
NO_OVERLAP_SHIFT_NS = 100 * 1_000_000_000

LIVOX_POINT_MSG = """uint32 offset_time
float32 x
float32 y
float32 z
uint8 reflectivity
uint8 tag
uint8 line
"""
LIVOX_MSG = """Header header
uint64 timebase
uint32 point_num
uint8 lidar_id
uint8[3] rsvd
CustomPoint[] points
"""
TF_MSG_ROS1 = 'geometry_msgs/TransformStamped[] transforms\n'
LIVOX_TAG = 0x10  # first return, no noise flags (what FAST-LIO keeps)

PF_FLOAT32 = 7
PF_FLOAT64 = 8

# Names this script owns inside OUT_DIR.
OUTPUTS = [
    'ros1_lz4.bag',
    'ros1_bz2_livox.bag',
    'ros2_mcap',
    'ros2_sqlite3',
    'small',
    'expected_odometry_world_from_lidar.txt',
]

# ---------------------------------------------------------------------------
# Input


def read_pcd(path: Path) -> np.ndarray:
    """Read x y z from a binary PCD file as an (n, 3) float32 array."""
    raw = path.read_bytes()
    fields: list[str] = []
    sizes: list[int] = []
    types: list[str] = []
    counts: list[int] = []
    points = None
    pos = 0
    while True:
        end = raw.index(b'\n', pos)
        line = raw[pos:end].decode('ascii').strip()
        pos = end + 1
        if not line or line.startswith('#'):
            continue
        key, *vals = line.split()
        key = key.upper()
        if key == 'FIELDS':
            fields = vals
        elif key == 'SIZE':
            sizes = [int(v) for v in vals]
        elif key == 'TYPE':
            types = vals
        elif key == 'COUNT':
            counts = [int(v) for v in vals]
        elif key == 'POINTS':
            points = int(vals[0])
        elif key == 'DATA':
            if vals[0] != 'binary':
                msg = f'{path}: only DATA binary is supported, got {vals[0]}'
                raise ValueError(msg)
            break
    if not counts:
        counts = [1] * len(fields)
    kinds = {'F': 'f', 'I': 'i', 'U': 'u'}
    dtype = np.dtype(
        [
            (name, f'<{kinds[t]}{s}', (c,)) if c > 1 else (name, f'<{kinds[t]}{s}')
            for name, s, t, c in zip(fields, sizes, types, counts, strict=True)
        ],
    )
    assert points is not None
    arr = np.frombuffer(raw, dtype=dtype, count=points, offset=pos)
    return np.stack([arr['x'], arr['y'], arr['z']], axis=1).astype(np.float32)


def read_tum(path: Path) -> tuple[list[int], np.ndarray, np.ndarray]:
    """Read a TUM file: stamps in ns (rounded from the text), translations, quaternions xyzw."""
    stamps: list[int] = []
    ts: list[list[float]] = []
    qs: list[list[float]] = []
    for line in path.read_text().splitlines():
        line = line.strip()
        if not line or line.startswith('#'):
            continue
        v = line.split()
        stamps.append(round(float(v[0]) * 1e9))
        ts.append([float(x) for x in v[1:4]])
        qs.append([float(x) for x in v[4:8]])
    return stamps, np.array(ts), np.array(qs)


def load_source(src: Path) -> tuple[list[np.ndarray], list[int], np.ndarray, np.ndarray]:
    """Frames (lidar frame), TUM stamps (ns, no offset), world_from_lidar t and q."""
    frame_files = sorted((src / 'frames').glob('*.pcd'))
    frames = [read_pcd(p) for p in frame_files]
    stamps, ts, qs = read_tum(src / 'poses.txt')
    if len(stamps) != len(frames):
        msg = f'{len(frames)} frames but {len(stamps)} poses in poses.txt'
        raise ValueError(msg)
    return frames, stamps, ts, qs


# ---------------------------------------------------------------------------
# Quaternion / pose math (quaternions are x y z w)


def qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array(
        [
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz,
        ],
    )


def qconj(q: np.ndarray) -> np.ndarray:
    return np.array([-q[0], -q[1], -q[2], q[3]])


def qrot(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    return qmul(qmul(q, np.array([*v, 0.0])), qconj(q))[:3]


def qmat(q: np.ndarray) -> np.ndarray:
    return np.stack([qrot(q, e) for e in np.eye(3)], axis=1)


def slerp(q0: np.ndarray, q1: np.ndarray, a: float) -> np.ndarray:
    """Slerp along the shorter arc; a outside [0, 1] extrapolates along the same geodesic."""
    q0 = q0 / np.linalg.norm(q0)
    q1 = q1 / np.linalg.norm(q1)
    d = float(np.dot(q0, q1))
    if d < 0.0:
        q1, d = -q1, -d
    theta = math.acos(min(1.0, d))
    if theta < 1e-12:
        q = (1 - a) * q0 + a * q1
    else:
        q = (math.sin((1 - a) * theta) * q0 + math.sin(a * theta) * q1) / math.sin(theta)
    return q / np.linalg.norm(q)


def compose(ta, qa, tb, qb):
    """(ta, qa) * (tb, qb)."""
    return ta + qrot(qa, tb), qmul(qa, qb)


def inverse(t, q):
    qi = qconj(q)
    return -qrot(qi, t), qi


def body_from_lidar_pose(t_wl: np.ndarray, q_wl: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """world_from_body = world_from_lidar * inverse(body_from_lidar)."""
    ti, qi = inverse(EXTRINSIC_T, EXTRINSIC_Q)
    return compose(t_wl, q_wl, ti, qi)


def lidar_from_body_pose(t_wb: np.ndarray, q_wb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """world_from_lidar = world_from_body * body_from_lidar."""
    return compose(t_wb, q_wb, EXTRINSIC_T, EXTRINSIC_Q)


def interpolate(stamps: list[int], ts: np.ndarray, qs: np.ndarray, t_ns: int):
    """Pose at t_ns: lerp + slerp on the bracketing segment (first/last segment beyond the ends)."""
    i = int(np.searchsorted(np.array(stamps), t_ns, side='right')) - 1
    i = max(0, min(i, len(stamps) - 2))
    a = (t_ns - stamps[i]) / (stamps[i + 1] - stamps[i])
    if a == 0.0:
        return ts[i].copy(), qs[i] / np.linalg.norm(qs[i])
    if a == 1.0:
        return ts[i + 1].copy(), qs[i + 1] / np.linalg.norm(qs[i + 1])
    return (1 - a) * ts[i] + a * ts[i + 1], slerp(qs[i], qs[i + 1], a)


def odometry_stamps(stamps: list[int]) -> list[int]:
    """25 Hz grid from the first cloud stamp, up to the first sample at or after the last."""
    n = math.ceil((stamps[-1] - stamps[0]) / ODOM_PERIOD_NS)
    return [stamps[0] + k * ODOM_PERIOD_NS for k in range(n + 1)]


def odometry_samples(stamps, ts, qs):
    """(stamp_ns, t_wb, q_wb) at 25 Hz from interpolated world_from_lidar."""
    out = []
    for s in odometry_stamps(stamps):
        t_wl, q_wl = interpolate(stamps, ts, qs, s)
        t_wb, q_wb = body_from_lidar_pose(t_wl, q_wl)
        out.append((s, t_wb, q_wb))
    return out


# ---------------------------------------------------------------------------
# Message builders


class Msgs:
    """Message constructors for one typestore (ROS 1 noetic or ROS 2 humble)."""

    def __init__(self, ros1: bool) -> None:
        self.ros1 = ros1
        self.store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
        pkg = 'livox_ros_driver' if ros1 else 'livox_ros_driver2'
        self.livox_point_type = f'{pkg}/msg/CustomPoint'
        self.livox_type = f'{pkg}/msg/CustomMsg'
        types = {}
        types.update(get_types_from_msg(LIVOX_POINT_MSG, self.livox_point_type))
        types.update(get_types_from_msg(LIVOX_MSG, self.livox_type))
        if ros1:  # the noetic store lacks tf2_msgs
            types.update(get_types_from_msg(TF_MSG_ROS1, 'tf2_msgs/msg/TFMessage'))
        self.store.register(types)
        self.T = self.store.types

    def serialize(self, msg, typename: str) -> bytes:
        if self.ros1:
            return bytes(self.store.serialize_ros1(msg, typename))
        return bytes(self.store.serialize_cdr(msg, typename))

    def header(self, stamp_ns: int, frame_id: str, seq: int):
        t = self.T['builtin_interfaces/msg/Time'](
            sec=stamp_ns // 1_000_000_000,
            nanosec=stamp_ns % 1_000_000_000,
        )
        if self.ros1:  # ROS 1 std_msgs/Header has seq
            return self.T['std_msgs/msg/Header'](seq=seq, stamp=t, frame_id=frame_id)
        return self.T['std_msgs/msg/Header'](stamp=t, frame_id=frame_id)

    def pose(self, t, q):
        return self.T['geometry_msgs/msg/Pose'](
            position=self.T['geometry_msgs/msg/Point'](x=float(t[0]), y=float(t[1]), z=float(t[2])),
            orientation=self.T['geometry_msgs/msg/Quaternion'](
                x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]),
            ),
        )

    def pose_stamped(self, stamp_ns, t, q, seq):
        return self.T['geometry_msgs/msg/PoseStamped'](
            header=self.header(stamp_ns, WORLD_FRAME, seq), pose=self.pose(t, q),
        )

    def odometry(self, stamp_ns, t, q, seq):
        T = self.T
        zero3 = T['geometry_msgs/msg/Vector3'](x=0.0, y=0.0, z=0.0)
        return T['nav_msgs/msg/Odometry'](
            header=self.header(stamp_ns, WORLD_FRAME, seq),
            child_frame_id=BODY_FRAME,
            pose=T['geometry_msgs/msg/PoseWithCovariance'](
                pose=self.pose(t, q), covariance=np.zeros(36, dtype=np.float64),
            ),
            twist=T['geometry_msgs/msg/TwistWithCovariance'](
                twist=T['geometry_msgs/msg/Twist'](linear=zero3, angular=zero3),
                covariance=np.zeros(36, dtype=np.float64),
            ),
        )

    def tf_static(self, stamp_ns):
        T = self.T
        tf = T['geometry_msgs/msg/TransformStamped'](
            header=self.header(stamp_ns, BODY_FRAME, 0),
            child_frame_id=LIDAR_FRAME,
            transform=T['geometry_msgs/msg/Transform'](
                translation=T['geometry_msgs/msg/Vector3'](
                    x=float(EXTRINSIC_T[0]), y=float(EXTRINSIC_T[1]), z=float(EXTRINSIC_T[2]),
                ),
                rotation=T['geometry_msgs/msg/Quaternion'](
                    x=float(EXTRINSIC_Q[0]), y=float(EXTRINSIC_Q[1]),
                    z=float(EXTRINSIC_Q[2]), w=float(EXTRINSIC_Q[3]),
                ),
            ),
        )
        return T['tf2_msgs/msg/TFMessage'](transforms=[tf])

    def point_cloud2(
        self, stamp_ns, seq, *, fields, data: bytes, height, width, point_step, row_step,
        is_bigendian=False, is_dense=True, frame_id=LIDAR_FRAME,
    ):
        T = self.T
        pf = T['sensor_msgs/msg/PointField']
        return T['sensor_msgs/msg/PointCloud2'](
            header=self.header(stamp_ns, frame_id, seq),
            height=height,
            width=width,
            fields=[pf(name=n, offset=o, datatype=d, count=1) for n, o, d in fields],
            is_bigendian=is_bigendian,
            point_step=point_step,
            row_step=row_step,
            data=np.frombuffer(data, dtype=np.uint8).copy(),
            is_dense=is_dense,
        )

    def livox(self, stamp_ns, seq, pts: np.ndarray):
        T = self.T
        cp = T[self.livox_point_type]
        points = [
            cp(
                offset_time=i * 10,
                x=float(p[0]), y=float(p[1]), z=float(p[2]),
                reflectivity=(i * 7) % 256, tag=LIVOX_TAG, line=i % 4,
            )
            for i, p in enumerate(pts)
        ]
        return T[self.livox_type](
            header=self.header(stamp_ns, LIDAR_FRAME, seq),
            timebase=stamp_ns,
            point_num=len(points),
            lidar_id=0,
            rsvd=np.zeros(3, dtype=np.uint8),
            points=points,
        )


def cloud_xyzi_f32(msgs: Msgs, stamp_ns, seq, pts: np.ndarray):
    """ros1_lz4: x y z intensity float32 + N_NAN_APPENDED NaN points at the end."""
    n = len(pts)
    arr = np.zeros((n + N_NAN_APPENDED, 4), dtype='<f4')
    arr[:n, :3] = pts
    arr[:n, 3] = (np.arange(n) * 7 % 256).astype(np.float32)
    arr[n:, :3] = np.nan
    arr[n:, 3] = 0.0
    w = n + N_NAN_APPENDED
    return msgs.point_cloud2(
        stamp_ns, seq,
        fields=[('x', 0, PF_FLOAT32), ('y', 4, PF_FLOAT32), ('z', 8, PF_FLOAT32),
                ('intensity', 12, PF_FLOAT32)],
        data=arr.tobytes(), height=1, width=w, point_step=16, row_step=16 * w,
        is_dense=False,
    )


def cloud_organized_f64(msgs: Msgs, stamp_ns, seq, pts: np.ndarray):
    """ros2_mcap: ORGANIZED_ROWS rows, width ceil(n / rows), NaN padding at the end."""
    n = len(pts)
    w = math.ceil(n / ORGANIZED_ROWS)
    arr = np.full((ORGANIZED_ROWS * w, 3), np.nan, dtype='<f8')
    arr[:n] = pts.astype(np.float64)
    return msgs.point_cloud2(
        stamp_ns, seq,
        fields=[('x', 0, PF_FLOAT64), ('y', 8, PF_FLOAT64), ('z', 16, PF_FLOAT64)],
        data=arr.tobytes(), height=ORGANIZED_ROWS, width=w, point_step=24, row_step=24 * w,
        is_dense=False,
    )


def cloud_xyz_f32(msgs: Msgs, stamp_ns, seq, pts: np.ndarray, *, big=False, row_step_extra=0,
                  frame_id=LIDAR_FRAME):
    n = len(pts)
    arr = np.asarray(pts, dtype='>f4' if big else '<f4')
    return msgs.point_cloud2(
        stamp_ns, seq,
        fields=[('x', 0, PF_FLOAT32), ('y', 4, PF_FLOAT32), ('z', 8, PF_FLOAT32)],
        data=arr.tobytes(), height=1, width=n, point_step=12, row_step=12 * n + row_step_extra,
        is_bigendian=big, frame_id=frame_id,
    )


def to_world(pts: np.ndarray, t: np.ndarray, q: np.ndarray) -> np.ndarray:
    """world_from_lidar applied to lidar-frame points (as FAST-LIO's /cloud_registered)."""
    return np.array([qrot(q, p) + t for p in np.asarray(pts, dtype=np.float64)])


def cloud_xy_f32(msgs: Msgs, stamp_ns, seq, pts: np.ndarray):
    n = len(pts)
    arr = np.asarray(pts[:, :2], dtype='<f4')
    return msgs.point_cloud2(
        stamp_ns, seq,
        fields=[('x', 0, PF_FLOAT32), ('y', 4, PF_FLOAT32)],
        data=arr.tobytes(), height=1, width=n, point_step=8, row_step=8 * n,
    )


# ---------------------------------------------------------------------------
# Writers


PCL2 = 'sensor_msgs/msg/PointCloud2'
POSE = 'geometry_msgs/msg/PoseStamped'
ODOM = 'nav_msgs/msg/Odometry'
TF = 'tf2_msgs/msg/TFMessage'

TF_STATIC_QOS = Qos(
    QosHistory.KEEP_LAST, 1, QosReliability.RELIABLE, QosDurability.TRANSIENT_LOCAL,
    QosTime(0, 0), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False,
)


def write_ros1(path: Path, topics, messages, *, compression=None, chunk_threshold=None):
    """topics: [(topic, type, msgs, latching)]; messages: [(stamp_ns, topic, payload bytes)]."""
    w = Writer1(path)
    if compression is not None:
        w.set_compression(compression)
    if chunk_threshold is not None:
        w.chunk_threshold = chunk_threshold
    with w:
        conns = {}
        for topic, typ, msgs, latching in topics:
            conns[topic] = w.add_connection(
                topic, typ, typestore=msgs.store, callerid='/make_bag_fixtures',
                latching=latching,
            )
        for stamp, topic, data in sorted(messages, key=lambda m: m[0]):
            w.write(conns[topic], STAMP_OFFSET_NS + stamp, data)


def write_ros2(path: Path, plugin, topics, messages):
    """topics: [(topic, type, msgs, qos list)]; messages: [(stamp_ns, topic, payload)]."""
    with Writer2(path, version=Writer2.VERSION_LATEST, storage_plugin=plugin) as w:
        conns = {}
        for topic, typ, msgs, qos in topics:
            conns[topic] = w.add_connection(
                topic, typ, typestore=msgs.store, offered_qos_profiles=qos,
            )
        for stamp, topic, data in sorted(messages, key=lambda m: m[0]):
            w.write(conns[topic], STAMP_OFFSET_NS + stamp, data)


def abs_ns(stamp: int) -> int:
    return STAMP_OFFSET_NS + stamp


def pose_msgs(msgs: Msgs, stamps, ts, qs, topic='/pose', *, shift_ns=0, nan_index=None):
    out = []
    for j, (s, t, q) in enumerate(zip(stamps, ts, qs, strict=True)):
        t = np.array(t, dtype=np.float64)
        if j == nan_index:
            t[0] = np.nan
        m = msgs.pose_stamped(abs_ns(s + shift_ns), t, q, j)
        out.append((s + shift_ns, topic, msgs.serialize(m, POSE)))
    return out


def odom_msgs(msgs: Msgs, samples):
    return [
        (s, '/Odometry', msgs.serialize(msgs.odometry(abs_ns(s), t, q, k), ODOM))
        for k, (s, t, q) in enumerate(samples)
    ]


def generate(src: Path, out: Path) -> None:
    frames, stamps, ts, qs = load_source(src)
    out.mkdir(parents=True, exist_ok=True)
    for name in OUTPUTS:
        p = out / name
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()

    r1 = Msgs(ros1=True)
    r2 = Msgs(ros1=False)
    odom = odometry_samples(stamps, ts, qs)

    # A. ros1_lz4.bag
    m = [(s, '/points_raw', r1.serialize(cloud_xyzi_f32(r1, abs_ns(s), j, f), PCL2))
         for j, (s, f) in enumerate(zip(stamps, frames, strict=True))]
    m += odom_msgs(r1, odom)
    m.insert(0, (stamps[0], '/tf_static', r1.serialize(r1.tf_static(abs_ns(stamps[0])), TF)))
    write_ros1(
        out / 'ros1_lz4.bag',
        [('/tf_static', TF, r1, 1), ('/points_raw', PCL2, r1, None), ('/Odometry', ODOM, r1, None)],
        m, compression=Writer1.CompressionFormat.LZ4, chunk_threshold=64 * 1024,
    )

    # B. ros1_bz2_livox.bag
    m = [(s, '/livox/lidar', r1.serialize(r1.livox(abs_ns(s), j, f), r1.livox_type))
         for j, (s, f) in enumerate(zip(stamps, frames, strict=True))]
    m += pose_msgs(r1, stamps, ts, qs)
    write_ros1(
        out / 'ros1_bz2_livox.bag',
        [('/livox/lidar', r1.livox_type, r1, None), ('/pose', POSE, r1, None)],
        m, compression=Writer1.CompressionFormat.BZ2, chunk_threshold=128 * 1024,
    )

    # C. ros2_mcap/
    m = [(s, '/points', r2.serialize(cloud_organized_f64(r2, abs_ns(s), j, f), PCL2))
         for j, (s, f) in enumerate(zip(stamps, frames, strict=True))]
    m += pose_msgs(r2, stamps, ts, qs)
    write_ros2(out / 'ros2_mcap', StoragePlugin.MCAP,
               [('/points', PCL2, r2, []), ('/pose', POSE, r2, [])], m)

    # D. ros2_sqlite3/
    m = [(s, '/livox/lidar', r2.serialize(r2.livox(abs_ns(s), j, f), r2.livox_type))
         for j, (s, f) in enumerate(zip(stamps, frames, strict=True))]
    m += odom_msgs(r2, odom)
    m.insert(0, (stamps[0], '/tf_static', r2.serialize(r2.tf_static(abs_ns(stamps[0])), TF)))
    write_ros2(out / 'ros2_sqlite3', StoragePlugin.SQLITE3,
               [('/tf_static', TF, r2, [TF_STATIC_QOS]), ('/livox/lidar', r2.livox_type, r2, []),
                ('/Odometry', ODOM, r2, [])], m)

    # E. small/
    small = out / 'small'
    small.mkdir()
    sst = stamps[:SMALL_FRAMES]
    sts, sqs = ts[:SMALL_FRAMES], qs[:SMALL_FRAMES]
    sfr = [f[:SMALL_POINTS] for f in frames[:SMALL_FRAMES]]
    small_topics = [('/points', PCL2, r1, None), ('/pose', POSE, r1, None)]

    def small_bag(name, cloud_fn, **pose_kw):
        msgs = [(s, '/points', r1.serialize(cloud_fn(abs_ns(s), j, f), PCL2))
                for j, (s, f) in enumerate(zip(sst, sfr, strict=True))]
        msgs += pose_msgs(r1, sst, sts, sqs, **pose_kw)
        write_ros1(small / name, small_topics, msgs)

    small_bag('bigendian.bag', lambda s, j, f: cloud_xyz_f32(r1, s, j, f, big=True))
    small_bag('no_z.bag', lambda s, j, f: cloud_xy_f32(r1, s, j, f))
    small_bag('bad_row_step.bag', lambda s, j, f: cloud_xyz_f32(r1, s, j, f, row_step_extra=12))
    small_bag('nan_pose.bag', lambda s, j, f: cloud_xyz_f32(r1, s, j, f), nan_index=1)
    small_bag('no_overlap.bag', lambda s, j, f: cloud_xyz_f32(r1, s, j, f),
              shift_ns=sst[-1] - sst[0] + NO_OVERLAP_SHIFT_NS)
    small_bag('cloud_registered.bag',
              lambda s, j, f: cloud_xyz_f32(r1, s, j, to_world(f, sts[j], sqs[j]), frame_id=WORLD_FRAME))

    with tempfile.TemporaryDirectory() as tmp:
        bag2 = Path(tmp) / 'ros2'
        m = [(s, '/points', r2.serialize(cloud_xyz_f32(r2, abs_ns(s), j, f), PCL2))
             for j, (s, f) in enumerate(zip(sst, sfr, strict=True))]
        m += pose_msgs(r2, sst, sts, sqs)
        write_ros2(bag2, StoragePlugin.MCAP, [('/points', PCL2, r2, []), ('/pose', POSE, r2, [])], m)
        shutil.copyfile(bag2 / 'ros2.mcap', small / 'ros2.mcap')

    # What a reader interpolating /Odometry gets at the cloud stamps.
    write_expected_odometry(out / 'expected_odometry_world_from_lidar.txt', stamps, odom)


def odometry_at(odom, t_ns):
    return interpolate([o[0] for o in odom], np.array([o[1] for o in odom]),
                       np.array([o[2] for o in odom]), t_ns)


def write_expected_odometry(path: Path, stamps, odom) -> None:
    lines = []
    for s in stamps:
        t_wb, q_wb = odometry_at(odom, s)
        t, q = lidar_from_body_pose(t_wb, q_wb)
        if q[3] < 0:
            q = -q
        lines.append(f'{s / 1e9:.9f} ' + ' '.join(f'{v:.9f}' for v in [*t, *q]))
    path.write_text('\n'.join(lines) + '\n')


# ---------------------------------------------------------------------------
# Verification (reads everything back with rosbags' AnyReader)


class Check:
    def __init__(self) -> None:
        self.failures: list[str] = []
        self.passed = 0

    def __call__(self, cond: bool, what: str) -> None:
        if cond:
            self.passed += 1
        else:
            self.failures.append(what)
            print(f'  FAIL: {what}')


def decode_cloud(msg) -> np.ndarray:
    """Generic PointCloud2 -> (n, k) float64 of its x y (z) fields, NaN points dropped."""
    names = [f.name for f in msg.fields]
    wanted = [n for n in ('x', 'y', 'z') if n in names]
    endian = '>' if msg.is_bigendian else '<'
    kinds = {7: 'f4', 8: 'f8'}
    dt = np.dtype({
        'names': [f.name for f in msg.fields if f.name in wanted],
        'formats': [endian + kinds[f.datatype] for f in msg.fields if f.name in wanted],
        'offsets': [f.offset for f in msg.fields if f.name in wanted],
        'itemsize': msg.point_step,
    })
    n = msg.width * msg.height
    data = np.asarray(msg.data, dtype=np.uint8).tobytes()
    arr = np.frombuffer(data, dtype=dt, count=n)
    xyz = np.stack([arr[w].astype(np.float64) for w in wanted], axis=1)
    return xyz[~np.isnan(xyz).any(axis=1)]


def stamp_ns(header) -> int:
    return header.stamp.sec * 1_000_000_000 + header.stamp.nanosec


def read_all(path: Path):
    """{topic: [(bag_ns, msgtype, msg)]}, plus connection info."""
    out: dict[str, list] = {}
    with AnyReader([path]) as reader:
        conns = {c.topic: c for c in reader.connections}
        for conn, t, raw in reader.messages():
            out.setdefault(conn.topic, []).append((t, conn.msgtype, reader.deserialize(raw, conn.msgtype)))
    return out, conns


def pose_of(p):
    return (np.array([p.position.x, p.position.y, p.position.z]),
            np.array([p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w]))


def same_rot(qa, qb, tol=1e-12) -> bool:
    qa, qb = qa / np.linalg.norm(qa), qb / np.linalg.norm(qb)
    return abs(abs(float(np.dot(qa, qb))) - 1.0) < tol


def check_stamps(ck: Check, name, topic, items, expected_ns):
    ck(len(items) == len(expected_ns), f'{name} {topic}: {len(items)} messages, expected {len(expected_ns)}')
    ck(all(t == e for (t, _, _), e in zip(items, expected_ns, strict=False)),
       f'{name} {topic}: bag times != expected')
    ck(all(stamp_ns(m.header) == t for t, _, m in items if hasattr(m, 'header')),
       f'{name} {topic}: header stamps != bag times')


def check_poses(ck, name, items, stamps, ts, qs, *, nan_index=None):
    ok = True
    for j, (_, _, m) in enumerate(items):
        t, q = pose_of(m.pose)
        if j == nan_index:
            ok &= bool(np.isnan(t[0])) and np.array_equal(t[1:], ts[j][1:])
        else:
            ok &= np.array_equal(t, ts[j]) and np.array_equal(q, qs[j])
        ok &= m.header.frame_id == WORLD_FRAME
    ck(ok, f'{name} /pose: values != poses.txt')


def check_odometry(ck, name, items, stamps, ts, qs):
    samples = odometry_samples(stamps, ts, qs)
    check_stamps(ck, name, '/Odometry', items, [abs_ns(s) for s, _, _ in samples])
    ok = all(m.header.frame_id == WORLD_FRAME and m.child_frame_id == BODY_FRAME for _, _, m in items)
    ck(ok, f'{name} /Odometry: frame ids')
    # At cloud stamps that are on the 25 Hz grid, odometry * extrinsic == poses.txt.
    by_stamp = {t: m for t, _, m in items}
    exact = 0
    for j, s in enumerate(stamps):
        if (m := by_stamp.get(abs_ns(s))) is not None:
            t, q = lidar_from_body_pose(*pose_of(m.pose.pose))
            ck(np.allclose(t, ts[j], rtol=0, atol=1e-9) and same_rot(q, qs[j]),
               f'{name} /Odometry at frame {j}: odometry*extrinsic != poses.txt')
            exact += 1
    ck(exact == (len(stamps) + 1) // 2, f'{name} /Odometry: {exact} cloud stamps on the 25 Hz grid')
    ck(items[0][0] <= abs_ns(stamps[0]) and items[-1][0] >= abs_ns(stamps[-1]),
       f'{name} /Odometry does not cover the cloud stamps')


def check_tf(ck, name, items):
    ck(len(items) == 1, f'{name} /tf_static: {len(items)} messages')
    tf = items[0][2].transforms[0]
    tr, rot = tf.transform.translation, tf.transform.rotation
    ck(tf.header.frame_id == BODY_FRAME and tf.child_frame_id == LIDAR_FRAME, f'{name} tf frames')
    ck(np.array_equal([tr.x, tr.y, tr.z], EXTRINSIC_T)
       and np.array_equal([rot.x, rot.y, rot.z, rot.w], EXTRINSIC_Q), f'{name} tf values')


def check_livox(ck, name, items, stamps, frames):
    ok = True
    for j, (t, typ, m) in enumerate(items):
        pts = np.array([[p.x, p.y, p.z] for p in m.points], dtype=np.float32)
        ok &= np.array_equal(pts, frames[j]) and m.point_num == len(frames[j])
        ok &= m.timebase == abs_ns(stamps[j]) and m.header.frame_id == LIDAR_FRAME
        ok &= all(p.offset_time == i * 10 and p.line == i % 4 for i, p in enumerate(m.points))
    ck(ok, f'{name} /livox/lidar: points/timebase/frame_id != source')
    return items[0][1] if items else None


def check_clouds(ck, name, topic, items, frames, ncols=3):
    ok = True
    for j, (_, _, m) in enumerate(items):
        xyz = decode_cloud(m)
        ok &= xyz.shape == (len(frames[j]), ncols)
        ok &= np.array_equal(xyz, frames[j][:, :ncols].astype(np.float64))
        ok &= m.header.frame_id == LIDAR_FRAME
    ck(ok, f'{name} {topic}: decoded points != source')


def verify(src: Path, out: Path) -> bool:
    frames, stamps, ts, qs = load_source(src)
    ck = Check()
    cloud_ns = [abs_ns(s) for s in stamps]
    n_odom = len(odometry_stamps(stamps))
    lines = []

    def report(name, data, extra=''):
        counts = ', '.join(f'{k} {len(v)} x {v[0][1]}' for k, v in sorted(data.items()))
        lines.append(f'{name}: {counts}{extra}')

    # A
    name = 'ros1_lz4.bag'
    data, conns = read_all(out / name)
    ck(set(data) == {'/points_raw', '/Odometry', '/tf_static'}, f'{name} topics {sorted(data)}')
    check_stamps(ck, name, '/points_raw', data['/points_raw'], cloud_ns)
    check_clouds(ck, name, '/points_raw', data['/points_raw'], frames)
    m0 = data['/points_raw'][0][2]
    ck(m0.width == len(frames[0]) + N_NAN_APPENDED and not m0.is_dense and m0.point_step == 16,
       f'{name}: NaN tail / is_dense / point_step')
    raw0 = np.frombuffer(np.asarray(m0.data, dtype=np.uint8).tobytes(), dtype='<f4').reshape(-1, 4)
    ck(np.isnan(raw0[-N_NAN_APPENDED:, :3]).all() and not np.isnan(raw0[:-N_NAN_APPENDED]).any(),
       f'{name}: NaN points only at the end')
    check_odometry(ck, name, data['/Odometry'], stamps, ts, qs)
    ck(len(data['/Odometry']) == n_odom, f'{name} odometry count')
    check_tf(ck, name, data['/tf_static'])
    ck(conns['/tf_static'].ext.latching == 1, f'{name} /tf_static latching')
    nchunks = count_ros1_chunks(out / name)
    ck(nchunks >= 3, f'{name}: {nchunks} chunks')
    report(name, data, f'; {nchunks} LZ4 chunks')

    # B
    name = 'ros1_bz2_livox.bag'
    data, conns = read_all(out / name)
    ck(set(data) == {'/livox/lidar', '/pose'}, f'{name} topics {sorted(data)}')
    check_stamps(ck, name, '/livox/lidar', data['/livox/lidar'], cloud_ns)
    check_livox(ck, name, data['/livox/lidar'], stamps, frames)
    check_stamps(ck, name, '/pose', data['/pose'], cloud_ns)
    check_poses(ck, name, data['/pose'], stamps, ts, qs)
    md5 = conns['/livox/lidar'].digest
    report(name, data, f'; {count_ros1_chunks(out / name)} BZ2 chunks; CustomMsg md5 {md5}')

    # C
    name = 'ros2_mcap'
    data, conns = read_all(out / name)
    ck(set(data) == {'/points', '/pose'}, f'{name} topics {sorted(data)}')
    check_stamps(ck, name, '/points', data['/points'], cloud_ns)
    check_clouds(ck, name, '/points', data['/points'], frames)
    m0 = data['/points'][0][2]
    ck(m0.height == ORGANIZED_ROWS and m0.width == math.ceil(len(frames[0]) / ORGANIZED_ROWS)
       and m0.point_step == 24 and m0.fields[0].datatype == PF_FLOAT64, f'{name}: organized f64 layout')
    check_stamps(ck, name, '/pose', data['/pose'], cloud_ns)
    check_poses(ck, name, data['/pose'], stamps, ts, qs)
    ck((out / name / 'ros2_mcap.mcap').exists() and (out / name / 'metadata.yaml').exists(), f'{name} files')
    report(name, data)

    # D
    name = 'ros2_sqlite3'
    data, conns = read_all(out / name)
    ck(set(data) == {'/livox/lidar', '/Odometry', '/tf_static'}, f'{name} topics {sorted(data)}')
    check_stamps(ck, name, '/livox/lidar', data['/livox/lidar'], cloud_ns)
    check_livox(ck, name, data['/livox/lidar'], stamps, frames)
    check_odometry(ck, name, data['/Odometry'], stamps, ts, qs)
    check_tf(ck, name, data['/tf_static'])
    ck((out / name / 'ros2_sqlite3.db3').exists(), f'{name} files')
    report(name, data)

    # Expected odometry file vs poses.txt
    est, ets, eqs = read_tum(out / 'expected_odometry_world_from_lidar.txt')
    ck(est == stamps, 'expected odometry stamps')
    dev = np.linalg.norm(ets - ts, axis=1)
    ck(dev[::2].max() < 1e-8, 'expected odometry == poses.txt at even frames')
    lines.append(f'expected_odometry_world_from_lidar.txt: |t - poses.txt| max {dev.max():.4f} m '
                 f'(even frames {dev[::2].max():.1e} m)')

    # E
    sst, sts, sqs = stamps[:SMALL_FRAMES], ts[:SMALL_FRAMES], qs[:SMALL_FRAMES]
    sfr = [f[:SMALL_POINTS] for f in frames[:SMALL_FRAMES]]
    s_ns = [abs_ns(s) for s in sst]
    for bag in ['bigendian.bag', 'no_z.bag', 'bad_row_step.bag', 'nan_pose.bag', 'no_overlap.bag', 'ros2.mcap']:
        name = f'small/{bag}'
        data, conns = read_all(out / name)
        ck(set(data) == {'/points', '/pose'}, f'{name} topics')
        clouds, poses = data['/points'], data['/pose']
        check_stamps(ck, name, '/points', clouds, s_ns)
        m0 = clouds[0][2]
        if bag == 'no_z.bag':
            check_clouds(ck, name, '/points', clouds, sfr, ncols=2)
            ck([f.name for f in m0.fields] == ['x', 'y'] and m0.point_step == 8, f'{name} fields')
        else:
            check_clouds(ck, name, '/points', clouds, sfr)
        if bag == 'bigendian.bag':
            ck(m0.is_bigendian, f'{name} is_bigendian')
            raw = np.asarray(m0.data, dtype=np.uint8).tobytes()
            ck(np.array_equal(np.frombuffer(raw, '>f4').reshape(-1, 3), sfr[0]), f'{name} BE bytes')
        if bag == 'bad_row_step.bag':
            ck(all(m.row_step * m.height != len(m.data) for _, _, m in clouds), f'{name} row_step')
        else:
            ck(all(m.row_step * m.height == len(m.data) for _, _, m in clouds), f'{name} row_step ok')
        if bag == 'no_overlap.bag':
            shift = sst[-1] - sst[0] + NO_OVERLAP_SHIFT_NS
            check_stamps(ck, name, '/pose', poses, [abs_ns(s + shift) for s in sst])
            ck(poses[0][0] - clouds[-1][0] == NO_OVERLAP_SHIFT_NS, f'{name} gap')
        else:
            check_stamps(ck, name, '/pose', poses, s_ns)
        check_poses(ck, name, poses, sst, sts, sqs, nan_index=1 if bag == 'nan_pose.bag' else None)
        report(name, data)

    for line in lines:
        print(line)
    print(f'verify: {ck.passed} passed, {len(ck.failures)} failed')
    return not ck.failures


def count_ros1_chunks(path: Path) -> int:
    from rosbags.rosbag1 import Reader

    with Reader(path) as r:
        return len(r.chunk_infos)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('source', type=Path, help='pssba dataset folder (frames/*.pcd, poses.txt)')
    ap.add_argument('out', type=Path, help='folder to write the fixtures into')
    ap.add_argument('--verify', action='store_true', help='only verify existing fixtures')
    ap.add_argument('--no-verify', action='store_true',
                    help='write without reading back (for large benchmark bags)')
    args = ap.parse_args()
    if not args.verify:
        generate(args.source, args.out)
        if args.no_verify:
            return 0
    return 0 if verify(args.source, args.out) else 1


if __name__ == '__main__':
    sys.exit(main())
