#!/usr/bin/env python3
"""Writes the example graphs' data: bacon.png (a wavy strip mask, BaconDrop), rope.ply
(a 40-link chain whose first point has mass 0, an immovable anchor) and bowl.obj (a
hemispherical bowl, an open shell, for mesh_bowl)."""
import math
import os
import struct
import zlib

here = os.path.dirname(os.path.abspath(__file__))

# bacon.png: 64 x 16 RGBA, opaque inside a strip whose edges wave along x
W, H = 64, 16
rows = b""
for y in range(H):
    row = b"\x00"
    for x in range(W):
        top = 2 + 1.5 * math.sin(x * 0.45)
        bottom = 13 + 1.5 * math.sin(x * 0.45 + 1.3)
        inside = top <= y <= bottom and 1 <= x <= W - 2
        row += b"\xc8\x50\x50\xff" if inside else b"\x00\x00\x00\x00"
    rows += row


def chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 6, 0, 0, 0)) +
       chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))
open(os.path.join(here, "bacon.png"), "wb").write(png)

# rope.ply: ascii, 40 links of 2.5 cm along +x from (0, 1, 0); point 0 anchored (mass 0)
n, link = 41, 0.025
with open(os.path.join(here, "rope.ply"), "w") as f:
    f.write("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
            "property float z\nproperty float pscale\nproperty float mass\n" % n)
    f.write("element edge %d\nproperty int vertex1\nproperty int vertex2\nproperty float restlength\n"
            "end_header\n" % (n - 1))
    for k in range(n):
        f.write("%g 1 0 %g %g\n" % (k * link, 0.011, 0.0 if k == 0 else 0.01))
    for k in range(n - 1):
        f.write("%d %d %g\n" % (k, k + 1, link))

# bowl.obj: the lower half of a sphere of radius 0.3 m whose lowest point is the origin, rim at
# y = 0.3; 32 segments around, 12 rings from the bottom pole to the rim; open (no lid)
R, seg, rings = 0.3, 32, 12
with open(os.path.join(here, "bowl.obj"), "w") as f:
    f.write("# a hemispherical bowl: radius 0.3 m, bottom at the origin, rim at y = 0.3 (make_data.py)\n")
    f.write("v 0 0 0\n")
    for i in range(1, rings + 1):
        t = 0.5 * math.pi * i / rings
        for j in range(seg):
            p = 2 * math.pi * j / seg
            f.write("v %.6f %.6f %.6f\n" % (R * math.sin(t) * math.cos(p), R - R * math.cos(t),
                                           R * math.sin(t) * math.sin(p)))
    ring = lambda i, j: 2 + (i - 1) * seg + j % seg  # 1-based index of ring i's vertex j
    for j in range(seg):  # the fan at the bottom, facing up into the bowl
        f.write("f 1 %d %d\n" % (ring(1, j + 1), ring(1, j)))
    for i in range(1, rings):
        for j in range(seg):
            a, b, c, d = ring(i, j), ring(i, j + 1), ring(i + 1, j + 1), ring(i + 1, j)
            f.write("f %d %d %d\nf %d %d %d\n" % (a, b, c, a, c, d))

# rock.obj: a lumpy closed stone about 0.24 m across: an icosahedron subdivided once, each vertex
# pushed out or in by a fixed pseudo-random factor (0.75 to 1.25 of 0.12 m); wound outward
t = (1 + math.sqrt(5)) / 2
ico_v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t),
         (0, 1, -t), (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
ico_f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4),
         (11, 10, 2), (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9),
         (4, 9, 5), (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
unit = lambda p: tuple(c / math.sqrt(sum(q * q for q in p)) for c in p)
verts = [unit(p) for p in ico_v]
mid = {}
def middle(a, b):
    key = (min(a, b), max(a, b))
    if key not in mid:
        verts.append(unit(tuple((verts[a][k] + verts[b][k]) / 2 for k in range(3))))
        mid[key] = len(verts) - 1
    return mid[key]
faces = []
for a, b, c in ico_f:
    ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
    faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
with open(os.path.join(here, "rock.obj"), "w") as f:
    f.write("# a lumpy stone about 0.24 m across (make_data.py)\n")
    for k, p in enumerate(verts):
        s = 0.12 * (1 + 0.25 * math.sin(12.9898 * k + 78.233 * (k % 7)))
        f.write("v %.6f %.6f %.6f\n" % tuple(s * c for c in p))
    for a, b, c in faces:
        f.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))
