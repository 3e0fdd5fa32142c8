#!/usr/bin/env python3
"""Writes the hand-made seeds of the fuzz corpora (corpus/<target>/seed_*): small valid files of
every encoding each reader takes. The test fixtures are added by make_seeds.sh."""
import math
import struct
import sys
from pathlib import Path

root = Path(sys.argv[1] if len(sys.argv) > 1 else "corpus")
points = [(0.1 * k, math.sin(k), 2.0 - 0.05 * k) for k in range(12)]


def put(target, name, data):
    d = root / target
    d.mkdir(parents=True, exist_ok=True)
    (d / name).write_bytes(data if isinstance(data, bytes) else data.encode())


def pcd_header(data, fields="x y z", size="4 4 4", types="F F F", count="1 1 1", n=len(points)):
    return (f"# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {types}\n"
            f"COUNT {count}\nWIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\n"
            f"DATA {data}\n").encode()


put("pcd", "seed_ascii.pcd", pcd_header("ascii") + "".join(f"{x} {y} {z}\n" for x, y, z in points).encode())
put("pcd", "seed_binary.pcd", pcd_header("binary") + b"".join(struct.pack("<3f", *p) for p in points))
put("pcd", "seed_binary_xyzi_f64.pcd",
    pcd_header("binary", "x y z intensity", "8 8 8 4", "F F F F", "1 1 1 1")
    + b"".join(struct.pack("<3df", *p, 1.0) for p in points))
# binary_compressed: fields stored one after the other (SoA), LZF-compressed; literal runs only
# (a valid LZF stream: a control byte < 32 = run length - 1, then the bytes).
soa = b"".join(struct.pack(f"<{len(points)}f", *[p[i] for p in points]) for i in range(3))
lzf = b"".join(bytes([len(soa[i:i + 32]) - 1]) + soa[i:i + 32] for i in range(0, len(soa), 32))
put("pcd", "seed_compressed.pcd", pcd_header("binary_compressed") + struct.pack("<II", len(lzf), len(soa)) + lzf)

tum = "".join(f"{1700000000 + 0.1 * k:.6f} {x} {y} {z} 0 0 {math.sin(0.01 * k):.9f} {math.cos(0.01 * k):.9f}\n"
              for k, (x, y, z) in enumerate(points))
put("tum", "seed_poses.txt", "# timestamp tx ty tz qx qy qz qw\n" + tum)

ply_head = "ply\nformat {fmt} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\nproperty float z\nend_header\n"
put("ply", "seed_ascii.ply", ply_head.format(fmt="ascii", n=len(points)) + "".join(f"{x} {y} {z}\n" for x, y, z in points))
put("ply", "seed_binary.ply", ply_head.format(fmt="binary_little_endian", n=len(points)).encode()
    + b"".join(struct.pack("<3f", *p) for p in points))

tri = [((0, 0, 1), (0, 0, 0), (1, 0, 0), (0, 1, 0)), ((0, 0, 1), (1, 0, 0), (1, 1, 0), (0, 1, 0))]
put("stl", "seed_binary.stl", b"pssba fuzz seed".ljust(80, b" ") + struct.pack("<I", len(tri))
    + b"".join(struct.pack("<12fH", *[c for v in t for c in v], 0) for t in tri))
put("stl", "seed_ascii.stl", "solid seed\n" + "".join(
    f" facet normal {t[0][0]} {t[0][1]} {t[0][2]}\n  outer loop\n"
    + "".join(f"   vertex {v[0]} {v[1]} {v[2]}\n" for v in t[1:]) + "  endloop\n endfacet\n" for t in tri)
    + "endsolid seed\n")
print(f"seeds written under {root}")
