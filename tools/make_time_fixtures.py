#!/usr/bin/env python3
"""Write small ROS bag fixtures with per-point time fields, with an independent writer.

Each bag stores the same moving-sensor frames with the point times in one of the
conventions real drivers use (field name, type, unit, origin), so pssba's point
time detection can be tested against files it did not write. The bags are
written with the PyPI package `rosbags` (pinned in tools/requirements-fixtures.txt).

Usage:
    python3 tools/make_time_fixtures.py SOURCE_DIR OUT_DIR           # write, then verify
    python3 tools/make_time_fixtures.py --verify SOURCE_DIR OUT_DIR  # verify only

SOURCE_DIR is a pssba dataset folder made by `pssba simulate` with motion within
frames: frames/NNNNNN.pcd (binary PCD, fields x y z time, all float32, time = s
after the frame's stamp) and poses.txt (world_from_lidar, TUM). OUT_DIR receives
(replacing only these names):

  ouster.bag          ROS 1  /os_cloud_node/points  t uint32, ns after the header stamp
  velodyne.bag        ROS 1  /velodyne_points       time float32, s after the header stamp
  hesai/              rosbag2 (MCAP) /lidar_points  timestamp float64, absolute s
  livox_driver2.bag   ROS 1  /livox/lidar           timestamp float64, absolute ns
  livox_custom/       rosbag2 (sqlite3) /livox/lidar livox_ros_driver2/msg/CustomMsg,
                      offset_time uint32, ns after timebase (= header stamp)
  bad_time_type.bag   ROS 1  /points  2 frames, time uint8 (an unsupported type)
  nan_time.bag        ROS 1  /velodyne_points  3 frames as velodyne.bag, frame 1 point 5
                      has time NaN

Every bag also has /pose geometry_msgs/PoseStamped (world_from_lidar from poses.txt,
frame_id world) at each cloud's stamp. All stamps (header and bag times) are
STAMP_OFFSET_S + the TUM stamp, computed in integer ns. No randomness: the same
rosbags version gives byte-identical files.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
from rosbags.rosbag1 import Writer as Writer1
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Writer2

sys.path.insert(0, str(Path(__file__).resolve().parent))
from make_bag_fixtures import (  # noqa: E402  (the sibling generator: types, TUM reader, checks)
    LIVOX_TAG,
    POSE,
    STAMP_OFFSET_NS,
    STAMP_OFFSET_S,
    Check,
    Msgs,
    read_all,
    read_tum,
    stamp_ns,
)

assert STAMP_OFFSET_NS == round(STAMP_OFFSET_S * 1e9)

PCL2 = 'sensor_msgs/msg/PointCloud2'
WORLD_FRAME = 'world'
CALLERID = '/make_time_fixtures'

# sensor_msgs/PointField datatypes
INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)
NP_TYPES = {INT8: 'i1', UINT8: 'u1', INT16: '<i2', UINT16: '<u2', INT32: '<i4',
            UINT32: '<u4', FLOAT32: '<f4', FLOAT64: '<f8'}

# Point layouts (name, offset, datatype), point_step, as the drivers publish them.
# ouster-ros (os_point.h, pcl::toROSMsg of an EIGEN_ALIGN16 struct): x y z + 4 padding
# bytes, then intensity, t, reflectivity, ring, ambient, 2 padding, range; 48 bytes.
OUSTER_FIELDS = [('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32),
                 ('intensity', 16, FLOAT32), ('t', 20, UINT32), ('reflectivity', 24, UINT16),
                 ('ring', 26, UINT16), ('ambient', 28, UINT16), ('range', 32, UINT32)]
OUSTER_STEP = 48
# velodyne_pointcloud PointcloudXYZIRT (setPointCloud2Fields, packed): 22 bytes.
VELODYNE_FIELDS = [('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32),
                   ('intensity', 12, FLOAT32), ('ring', 16, UINT16), ('time', 18, FLOAT32)]
VELODYNE_STEP = 22
# HesaiLidar_ROS_2.0 (addPointField, packed): 26 bytes.
HESAI_FIELDS = [('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32),
                ('intensity', 12, FLOAT32), ('ring', 16, UINT16), ('timestamp', 18, FLOAT64)]
HESAI_STEP = 26
# livox_ros_driver2 xfer_format 0 (LivoxPointXyzrtlt, pack(1)): 26 bytes.
LIVOX2_FIELDS = [('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32),
                 ('intensity', 12, FLOAT32), ('tag', 16, UINT8), ('line', 17, UINT8),
                 ('timestamp', 18, FLOAT64)]
LIVOX2_STEP = 26
# bad_time_type.bag: x y z, time uint8, 3 padding bytes.
BAD_FIELDS = [('x', 0, FLOAT32), ('y', 4, FLOAT32), ('z', 8, FLOAT32), ('time', 12, UINT8)]
BAD_STEP = 16

BAD_FRAMES = 2
NAN_FRAMES = 3
NAN_FRAME, NAN_POINT = 1, 5

# name -> (topic, cloud type, lidar frame id); the cloud topics of each output.
BAGS = {
    'ouster.bag': ('/os_cloud_node/points', PCL2, 'os_sensor'),
    'velodyne.bag': ('/velodyne_points', PCL2, 'velodyne'),
    'hesai': ('/lidar_points', PCL2, 'hesai_lidar'),
    'livox_driver2.bag': ('/livox/lidar', PCL2, 'livox_frame'),
    'livox_custom': ('/livox/lidar', 'livox_ros_driver2/msg/CustomMsg', 'livox_frame'),
    'bad_time_type.bag': ('/points', PCL2, 'lidar'),
    'nan_time.bag': ('/velodyne_points', PCL2, 'velodyne'),
}
OUTPUTS = list(BAGS)

# ---------------------------------------------------------------------------
# Input


def read_pcd_fields(path: Path) -> np.ndarray:
    """A binary PCD file as a numpy structured array (little-endian, COUNT 1 fields)."""
    raw = path.read_bytes()
    head: dict[str, list[str]] = {}
    pos = 0
    while 'DATA' not in head:
        end = raw.index(b'\n', pos)
        line = raw[pos:end].decode('ascii').strip()
        pos = end + 1
        if line and not line.startswith('#'):
            key, *vals = line.split()
            head[key.upper()] = vals
    if head['DATA'] != ['binary']:
        raise ValueError(f'{path}: only DATA binary is supported, got {head["DATA"]}')
    if any(c != '1' for c in head.get('COUNT', [])):
        raise ValueError(f'{path}: only COUNT 1 fields are supported')
    kinds = {'F': 'f', 'I': 'i', 'U': 'u'}
    dtype = np.dtype([(n, f'<{kinds[t]}{s}') for n, s, t in
                      zip(head['FIELDS'], head['SIZE'], head['TYPE'], strict=True)])
    return np.frombuffer(raw, dtype=dtype, count=int(head['POINTS'][0]), offset=pos)


def load_source(src: Path):
    """(xyz float32 (n, 3), time float32 (n,)) per frame, TUM stamps (ns), t, q."""
    frames = []
    for p in sorted((src / 'frames').glob('*.pcd')):
        arr = read_pcd_fields(p)
        for f in ('x', 'y', 'z', 'time'):
            if arr.dtype[f] != np.dtype('<f4'):
                raise ValueError(f'{p}: field {f} is {arr.dtype[f]}, expected float32')
        xyz = np.stack([arr['x'], arr['y'], arr['z']], axis=1)
        frames.append((xyz, arr['time'].copy()))
    stamps, ts, qs = read_tum(src / 'poses.txt')
    if len(stamps) != len(frames):
        raise ValueError(f'{len(frames)} frames but {len(stamps)} poses in poses.txt')
    return frames, stamps, ts, qs


def abs_ns(tum_ns: int) -> int:
    return STAMP_OFFSET_NS + tum_ns


# ---------------------------------------------------------------------------
# Point time encodings: source time (float32 s after the stamp) -> stored value


def ns_after(times: np.ndarray) -> np.ndarray:
    """uint32 ns after the stamp, rounded to nearest."""
    return np.array([round(float(t) * 1e9) for t in times], dtype=np.uint32)


def abs_seconds(stamp: int, times: np.ndarray) -> np.ndarray:
    """float64 absolute s: stamp + time, correctly rounded (exact rational sum)."""
    base = Fraction(stamp, 1_000_000_000)
    return np.array([float(base + Fraction(float(t))) for t in times], dtype=np.float64)


def abs_nanoseconds(stamp: int, times: np.ndarray) -> np.ndarray:
    """float64 absolute ns: the integer stamp ns + rounded ns offset, cast to f64 (as the
    Livox driver casts base_time + offset_time)."""
    return np.array([float(stamp + round(float(t) * 1e9)) for t in times], dtype=np.float64)


# ---------------------------------------------------------------------------
# Messages


def pack(fields, step: int, n: int, values: dict[str, np.ndarray]) -> bytes:
    """n points of the layout `fields`/`step` (little-endian); unset bytes are zero."""
    dt = np.dtype({'names': [f[0] for f in fields],
                   'formats': [NP_TYPES[f[2]] for f in fields],
                   'offsets': [f[1] for f in fields], 'itemsize': step})
    arr = np.zeros(n, dtype=dt)
    for name, v in values.items():
        arr[name] = v
    return arr.tobytes()


def cloud2(msgs: Msgs, stamp: int, seq: int, frame_id: str, fields, step: int, n: int,
           values: dict[str, np.ndarray]):
    T = msgs.T
    pf = T['sensor_msgs/msg/PointField']
    data = pack(fields, step, n, values)
    return T[PCL2](
        header=msgs.header(stamp, frame_id, seq), height=1, width=n,
        fields=[pf(name=name, offset=o, datatype=d, count=1) for name, o, d in fields],
        is_bigendian=False, point_step=step, row_step=step * n,
        data=np.frombuffer(data, dtype=np.uint8).copy(), is_dense=True,
    )


def common(xyz: np.ndarray) -> dict[str, np.ndarray]:
    n = len(xyz)
    return {'x': xyz[:, 0], 'y': xyz[:, 1], 'z': xyz[:, 2],
            'intensity': (np.arange(n) * 7 % 256).astype(np.float32)}


def ouster_cloud(msgs, stamp, seq, fid, xyz, times):
    n = len(xyz)
    v = common(xyz)
    v.update(t=ns_after(times), reflectivity=np.arange(n) % 256, ring=np.arange(n) % 64,
             ambient=np.full(n, 100),
             range=np.rint(np.linalg.norm(xyz.astype(np.float64), axis=1) * 1000))
    return cloud2(msgs, stamp, seq, fid, OUSTER_FIELDS, OUSTER_STEP, n, v)


def velodyne_cloud(msgs, stamp, seq, fid, xyz, times):
    v = common(xyz)
    v.update(ring=np.arange(len(xyz)) % 32, time=times)
    return cloud2(msgs, stamp, seq, fid, VELODYNE_FIELDS, VELODYNE_STEP, len(xyz), v)


def hesai_cloud(msgs, stamp, seq, fid, xyz, times):
    v = common(xyz)
    v.update(ring=np.arange(len(xyz)) % 32, timestamp=abs_seconds(stamp, times))
    return cloud2(msgs, stamp, seq, fid, HESAI_FIELDS, HESAI_STEP, len(xyz), v)


def livox2_cloud(msgs, stamp, seq, fid, xyz, times):
    v = common(xyz)
    v.update(tag=np.full(len(xyz), LIVOX_TAG), line=np.arange(len(xyz)) % 4,
             timestamp=abs_nanoseconds(stamp, times))
    return cloud2(msgs, stamp, seq, fid, LIVOX2_FIELDS, LIVOX2_STEP, len(xyz), v)


def bad_cloud(msgs, stamp, seq, fid, xyz, times):
    # Plausible values (ms after the stamp, 0..100) so only the type is wrong.
    v = {'x': xyz[:, 0], 'y': xyz[:, 1], 'z': xyz[:, 2],
         'time': np.rint(times.astype(np.float64) * 1000)}
    return cloud2(msgs, stamp, seq, fid, BAD_FIELDS, BAD_STEP, len(xyz), v)


def livox_custom(msgs, stamp, seq, fid, xyz, times):
    T = msgs.T
    cp = T[msgs.livox_point_type]
    off = ns_after(times)
    points = [cp(offset_time=int(off[i]), x=float(p[0]), y=float(p[1]), z=float(p[2]),
                 reflectivity=(i * 7) % 256, tag=LIVOX_TAG, line=i % 4)
              for i, p in enumerate(xyz)]
    return T[msgs.livox_type](
        header=msgs.header(stamp, fid, seq), timebase=stamp, point_num=len(points),
        lidar_id=0, rsvd=np.zeros(3, dtype=np.uint8), points=points,
    )


def pose_stamped(msgs: Msgs, stamp: int, t, q, seq: int):
    return msgs.T[POSE](header=msgs.header(stamp, WORLD_FRAME, seq), pose=msgs.pose(t, q))


# ---------------------------------------------------------------------------
# Writing


def messages(msgs: Msgs, name: str, build, frames, stamps, ts, qs):
    """[(abs stamp ns, topic, payload)] for the clouds and the /pose messages."""
    topic, typ, fid = BAGS[name]
    out = []
    for j, ((xyz, times), s) in enumerate(zip(frames, stamps, strict=True)):
        st = abs_ns(s)
        out.append((st, topic, msgs.serialize(build(msgs, st, j, fid, xyz, times), typ)))
        out.append((st, '/pose', msgs.serialize(pose_stamped(msgs, st, ts[j], qs[j], j), POSE)))
    return out


def write_ros1(path: Path, msgs: Msgs, name: str, items) -> None:
    topic, typ, _ = BAGS[name]
    with Writer1(path) as w:
        conns = {t: w.add_connection(t, ty, typestore=msgs.store, callerid=CALLERID)
                 for t, ty in [(topic, typ), ('/pose', POSE)]}
        for stamp, t, data in sorted(items, key=lambda m: m[0]):
            w.write(conns[t], stamp, data)


def write_ros2(path: Path, plugin, msgs: Msgs, name: str, items) -> None:
    topic, typ, _ = BAGS[name]
    with Writer2(path, version=Writer2.VERSION_LATEST, storage_plugin=plugin) as w:
        conns = {t: w.add_connection(t, ty, typestore=msgs.store, offered_qos_profiles=[])
                 for t, ty in [(topic, typ), ('/pose', POSE)]}
        for stamp, t, data in sorted(items, key=lambda m: m[0]):
            w.write(conns[t], stamp, data)


def with_nan_time(frames):
    out = [(xyz, times.copy()) for xyz, times in frames[:NAN_FRAMES]]
    out[NAN_FRAME][1][NAN_POINT] = np.nan
    return out


def generate(src: Path, out: Path) -> None:
    frames, stamps, ts, qs = load_source(src)
    out.mkdir(parents=True, exist_ok=True)
    for name in OUTPUTS:
        p = out / name
        if p.is_dir():
            shutil.rmtree(p)
        elif p.exists():
            p.unlink()
    r1, r2 = Msgs(ros1=True), Msgs(ros1=False)
    src_all = (frames, stamps, ts, qs)
    write_ros1(out / 'ouster.bag', r1, 'ouster.bag',
               messages(r1, 'ouster.bag', ouster_cloud, *src_all))
    write_ros1(out / 'velodyne.bag', r1, 'velodyne.bag',
               messages(r1, 'velodyne.bag', velodyne_cloud, *src_all))
    write_ros2(out / 'hesai', StoragePlugin.MCAP, r2, 'hesai',
               messages(r2, 'hesai', hesai_cloud, *src_all))
    write_ros1(out / 'livox_driver2.bag', r1, 'livox_driver2.bag',
               messages(r1, 'livox_driver2.bag', livox2_cloud, *src_all))
    write_ros2(out / 'livox_custom', StoragePlugin.SQLITE3, r2, 'livox_custom',
               messages(r2, 'livox_custom', livox_custom, *src_all))
    k = BAD_FRAMES
    write_ros1(out / 'bad_time_type.bag', r1, 'bad_time_type.bag',
               messages(r1, 'bad_time_type.bag', bad_cloud, frames[:k], stamps[:k], ts, qs))
    k = NAN_FRAMES
    write_ros1(out / 'nan_time.bag', r1, 'nan_time.bag',
               messages(r1, 'nan_time.bag', velodyne_cloud, with_nan_time(frames),
                        stamps[:k], ts, qs))


# ---------------------------------------------------------------------------
# Verification (reads everything back with rosbags' AnyReader)


def decode_fields(msg) -> dict[str, np.ndarray]:
    """Every field of a little-endian PointCloud2, by name, in its own type."""
    if msg.is_bigendian:
        raise ValueError('big-endian cloud')
    dt = np.dtype({'names': [f.name for f in msg.fields],
                   'formats': [NP_TYPES[f.datatype] for f in msg.fields],
                   'offsets': [f.offset for f in msg.fields], 'itemsize': msg.point_step})
    raw = np.asarray(msg.data, dtype=np.uint8).tobytes()
    arr = np.frombuffer(raw, dtype=dt, count=msg.width * msg.height)
    return {name: arr[name] for name in arr.dtype.names}


def layout(msg):
    return [(f.name, f.offset, f.datatype) for f in msg.fields], msg.point_step


def seconds_after(name: str, msg, st: int):
    """The decoded point times of a cloud as s after its header stamp (float64), the
    raw field, and the tolerance of its representation (s)."""
    if name == 'livox_custom':
        off = np.array([p.offset_time for p in msg.points], dtype=np.int64)
        return (off + (msg.timebase - st)) * 1e-9, off, 0.5e-9
    f = decode_fields(msg)
    if name == 'ouster.bag':
        return f['t'].astype(np.float64) * 1e-9, f['t'], 0.5e-9
    if name in ('velodyne.bag', 'nan_time.bag'):
        return f['time'].astype(np.float64), f['time'], 0.0
    if name == 'hesai':
        return f['timestamp'] - st / 1e9, f['timestamp'], 1e-6
    if name == 'livox_driver2.bag':
        ns = np.array([int(v) - st for v in f['timestamp']], dtype=np.int64)
        return ns * 1e-9, f['timestamp'], 1e-6
    raise KeyError(name)


def xyz_of(name: str, msg) -> np.ndarray:
    if name == 'livox_custom':
        return np.array([[p.x, p.y, p.z] for p in msg.points], dtype=np.float32)
    f = decode_fields(msg)
    return np.stack([f['x'], f['y'], f['z']], axis=1)


EXPECTED_LAYOUT = {
    'ouster.bag': (OUSTER_FIELDS, OUSTER_STEP),
    'velodyne.bag': (VELODYNE_FIELDS, VELODYNE_STEP),
    'hesai': (HESAI_FIELDS, HESAI_STEP),
    'livox_driver2.bag': (LIVOX2_FIELDS, LIVOX2_STEP),
    'bad_time_type.bag': (BAD_FIELDS, BAD_STEP),
    'nan_time.bag': (VELODYNE_FIELDS, VELODYNE_STEP),
}


def verify(src: Path, out: Path) -> bool:
    frames, stamps, ts, qs = load_source(src)
    ck = Check()
    lines = []
    for name in OUTPUTS:
        path = out / name
        topic, typ, fid = BAGS[name]
        nframes = {'bad_time_type.bag': BAD_FRAMES, 'nan_time.bag': NAN_FRAMES}.get(name, len(frames))
        src_frames = with_nan_time(frames) if name == 'nan_time.bag' else frames[:nframes]
        exp_ns = [abs_ns(s) for s in stamps[:nframes]]
        if not path.exists():
            ck(False, f'{name}: missing')
            continue
        data, conns = read_all(path)
        ck(set(data) == {topic, '/pose'}, f'{name}: topics {sorted(data)}')
        clouds, poses = data.get(topic, []), data.get('/pose', [])
        ck(conns[topic].msgtype == typ and conns['/pose'].msgtype == POSE, f'{name}: types')
        for what, items in ((topic, clouds), ('/pose', poses)):
            ck(len(items) == nframes, f'{name} {what}: {len(items)} messages, expected {nframes}')
            ck([t for t, _, _ in items] == exp_ns, f'{name} {what}: bag times != stamps')
            ck(all(stamp_ns(m.header) == t for t, _, m in items),
               f'{name} {what}: header stamps != bag times')
        ok = all(np.array_equal([m.pose.position.x, m.pose.position.y, m.pose.position.z], ts[j])
                 and np.array_equal([m.pose.orientation.x, m.pose.orientation.y,
                                     m.pose.orientation.z, m.pose.orientation.w], qs[j])
                 and m.header.frame_id == WORLD_FRAME for j, (_, _, m) in enumerate(poses))
        ck(ok, f'{name} /pose: values or frame_id != poses.txt / {WORLD_FRAME}')

        ok_xyz, ok_layout, max_err, worst_tol, n_pts = True, True, 0.0, 0.0, 0
        ok_time = True
        for j, (t, _, m) in enumerate(clouds):
            xyz_src, times_src = src_frames[j]
            ok_xyz &= m.header.frame_id == fid
            xyz = xyz_of(name, m)
            ok_xyz &= xyz.dtype == np.float32 and xyz.shape == xyz_src.shape
            ok_xyz &= xyz.tobytes() == xyz_src.tobytes()  # bit for bit
            n_pts += len(xyz)
            if name == 'livox_custom':
                ok_layout &= m.timebase == t and m.point_num == len(xyz_src)
                ok_layout &= all(p.tag == LIVOX_TAG for p in m.points)
            else:
                fields, step = EXPECTED_LAYOUT[name]
                ok_layout &= layout(m) == (fields, step) and m.height == 1
                ok_layout &= m.row_step == step * m.width and len(m.data) == m.row_step
                ok_layout &= not m.is_bigendian
            if name == 'bad_time_type.bag':
                continue
            sec, _raw, tol = seconds_after(name, m, t)
            ref = times_src.astype(np.float64)
            nan_src = np.isnan(ref)
            ok_time &= np.array_equal(np.isnan(sec), nan_src)
            err = np.abs(sec[~nan_src] - ref[~nan_src])
            # 1e-15 s: float64 rounding of the conversion itself
            ok_time &= bool((err <= tol + 1e-15).all())
            if tol == 0.0:
                ok_time &= np.array_equal(np.asarray(_raw)[~nan_src], times_src[~nan_src])
            max_err = max(max_err, float(err.max()))
            worst_tol = tol
        ck(ok_xyz, f'{name} {topic}: x y z or frame_id != source')
        ck(ok_layout, f'{name} {topic}: field layout / point_step / row_step')
        if name == 'bad_time_type.bag':
            kinds = {f.name: f.datatype for f in clouds[0][2].fields}
            ck(kinds.get('time') == UINT8, f'{name}: time is not uint8')
            lines.append(f'{name}: {topic} {len(clouds)} + /pose {len(poses)}, {n_pts} points, '
                         f'time uint8')
            continue
        ck(ok_time, f'{name} {topic}: times != source within {worst_tol:g} s (max {max_err:.3g})')
        extra = ''
        if name == 'nan_time.bag':
            nan_at = [(j, int(i)) for j, (t, _, m) in enumerate(clouds)
                      for i in np.flatnonzero(np.isnan(seconds_after(name, m, t)[0]))]
            ck(nan_at == [(NAN_FRAME, NAN_POINT)], f'{name}: NaN times at {nan_at}')
            extra = f', NaN time at (frame, point) {nan_at}'
        lines.append(f'{name}: {topic} {len(clouds)} + /pose {len(poses)}, {n_pts} points, '
                     f'time max |err| {max_err:.3g} s (tol {worst_tol:g}){extra}')
    for line in lines:
        print(line)
    print(f'verify: {ck.passed} passed, {len(ck.failures)} failed')
    return not ck.failures


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('source', type=Path, help='pssba dataset folder (frames/*.pcd with time, poses.txt)')
    ap.add_argument('out', type=Path, help='folder to write the fixtures into')
    ap.add_argument('--verify', action='store_true', help='only verify existing fixtures')
    args = ap.parse_args()
    if not args.verify:
        generate(args.source, args.out)
    return 0 if verify(args.source, args.out) else 1


if __name__ == '__main__':
    sys.exit(main())
