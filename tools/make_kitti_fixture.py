#!/usr/bin/env python3
"""Write a dataset folder (frames/*.pcd, poses.txt, gt.txt) as a KITTI odometry sequence.

An independent writer for the KITTI source's tests (standard library only): it reads the
binary PCD frames and TUM poses itself and writes what KITTI and kiss-icp write:
  velodyne/NNNNNN.bin   float32 x y z intensity per point (intensity 0)
  calib.txt             P0..P3 (unused here) and Tr = cam0_from_velo, 3x4 row by row
  times.txt             one time per scan (s)
  poses.txt             KITTI poses, one 3x4 per line: P_k = Tr T_k Tr^-1 (camera convention)
  gt.txt                ground truth in the same format (if the dataset has gt.txt)

Usage: make_kitti_fixture.py DATASET OUT [--rebase] [--poses-name NAME] [--no-times]
  --rebase       express poses relative to scan 0 (as KITTI's files do); the default keeps the
                 dataset's world frame, so the sequence carries exactly the same poses
  --poses-name   file name of the initial poses (default poses.txt)
"""
import argparse
import math
import os
import struct
import sys

# KITTI sequence 00's Tr (cam0 from velodyne): x right/y down/z forward from x forward/y left/z up.
TR = [
    [4.276802385584e-04, -9.999672484946e-01, -8.084491683471e-03, -1.198459927713e-02],
    [-7.210626507497e-03, 8.081198471645e-03, -9.999413164504e-01, -5.403984729748e-02],
    [9.999738645903e-01, 4.859485810390e-04, -7.206933692422e-03, -2.921968648686e-01],
]


def fail(message):
    sys.exit(f"make_kitti_fixture: {message}")


def read_pcd_xyz(path):
    """x, y, z of a binary PCD with float32 x y z fields."""
    with open(path, "rb") as f:
        data = f.read()
    header = {}
    offset = 0
    while True:
        end = data.index(b"\n", offset)
        line = data[offset:end].decode("ascii").strip()
        offset = end + 1
        if not line or line.startswith("#"):
            continue
        key, _, value = line.partition(" ")
        header[key] = value.split()
        if key == "DATA":
            break
    if header["DATA"] != ["binary"] or header["FIELDS"][:3] != ["x", "y", "z"]:
        fail(f"{path}: expected a binary PCD starting with float32 x y z")
    sizes = [int(s) for s in header["SIZE"]]
    if sizes[:3] != [4, 4, 4] or header["TYPE"][:3] != ["F", "F", "F"]:
        fail(f"{path}: expected float32 x y z")
    stride = sum(int(s) * int(c) for s, c in zip(sizes, header["COUNT"]))
    count = int(header["POINTS"][0])
    return [struct.unpack_from("<3f", data, offset + i * stride) for i in range(count)]


def read_tum(path):
    poses = []
    with open(path) as f:
        for line in f:
            words = line.split()
            if not words or words[0].startswith("#"):
                continue
            poses.append([float(w) for w in words])
    return poses


def matrix_from_tum(p):
    """4x4 world_from_lidar from a TUM line."""
    _, tx, ty, tz, qx, qy, qz, qw = p
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)
    x, y, z, w = qx / n, qy / n, qz / n, qw / n
    return [
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w), tx],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w), ty],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y), tz],
        [0.0, 0.0, 0.0, 1.0],
    ]


def mul(a, b):
    return [[sum(a[i][k] * b[k][j] for k in range(4)) for j in range(4)] for i in range(4)]


def inverse(m):
    """Inverse of a rigid 4x4 (rotation block transposed)."""
    r = [[m[j][i] for j in range(3)] for i in range(3)]
    t = [-sum(r[i][k] * m[k][3] for k in range(3)) for i in range(3)]
    return [r[0] + [t[0]], r[1] + [t[1]], r[2] + [t[2]], [0.0, 0.0, 0.0, 1.0]]


def orthonormal_tr():
    """KITTI's Tr has 6-digit rounding; make its rotation exact (Gram-Schmidt on the rows)."""
    rows = [row[:3] for row in TR]
    out = []
    for row in rows:
        v = row[:]
        for u in out:
            d = sum(a * b for a, b in zip(v, u))
            v = [a - d * b for a, b in zip(v, u)]
        n = math.sqrt(sum(a * a for a in v))
        out.append([a / n for a in v])
    return [out[i] + [TR[i][3]] for i in range(3)] + [[0.0, 0.0, 0.0, 1.0]]


def kitti_lines(poses, tr, rebase):
    tr_inv = inverse(tr)
    base = inverse(matrix_from_tum(poses[0])) if rebase else None
    lines = []
    for p in poses:
        world_from_lidar = matrix_from_tum(p)
        if base is not None:
            world_from_lidar = mul(base, world_from_lidar)
        cam = mul(mul(tr, world_from_lidar), tr_inv)
        lines.append(" ".join(f"{cam[i][j]:.12e}" for i in range(3) for j in range(4)))
    return lines


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dataset")
    parser.add_argument("out")
    parser.add_argument("--rebase", action="store_true")
    parser.add_argument("--poses-name", default="poses.txt")
    parser.add_argument("--no-times", action="store_true")
    args = parser.parse_args()
    frames_dir = os.path.join(args.dataset, "frames")
    names = sorted(n for n in os.listdir(frames_dir) if n.endswith(".pcd"))
    poses = read_tum(os.path.join(args.dataset, "poses.txt"))
    if len(poses) != len(names):
        fail(f"{len(poses)} poses for {len(names)} frames")
    velodyne = os.path.join(args.out, "velodyne")
    os.makedirs(velodyne)
    for k, name in enumerate(names):
        points = read_pcd_xyz(os.path.join(frames_dir, name))
        with open(os.path.join(velodyne, f"{k:06d}.bin"), "wb") as f:
            for x, y, z in points:
                f.write(struct.pack("<4f", x, y, z, 0.0))
    tr = orthonormal_tr()
    with open(os.path.join(args.out, "calib.txt"), "w") as f:
        projection = "7.188560000000e+02 0 6.071928000000e+02 0 0 7.188560000000e+02 1.852157000000e+02 0 0 0 1 0"
        for i in range(4):
            f.write(f"P{i}: {projection}\n")
        f.write("Tr: " + " ".join(f"{tr[i][j]:.12e}" for i in range(3) for j in range(4)) + "\n")
    if not args.no_times:
        with open(os.path.join(args.out, "times.txt"), "w") as f:
            for p in poses:
                f.write(f"{p[0]:.6e}\n")
    with open(os.path.join(args.out, args.poses_name), "w") as f:
        f.write("\n".join(kitti_lines(poses, tr, args.rebase)) + "\n")
    gt_path = os.path.join(args.dataset, "gt.txt")
    if os.path.exists(gt_path):
        with open(os.path.join(args.out, "gt.txt"), "w") as f:
            f.write("\n".join(kitti_lines(read_tum(gt_path), tr, args.rebase)) + "\n")
    print(f"wrote {len(names)} scans to {args.out}")


if __name__ == "__main__":
    main()
