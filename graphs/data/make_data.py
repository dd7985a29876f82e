#!/usr/bin/env python3
"""Writes the example graphs' data: bacon.png (a wavy strip mask, BaconDrop) and rope.ply
(a 40-link chain whose first point has mass 0, an immovable anchor)."""
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
