#!/usr/bin/env python3
"""Writes tests/data/mask_half.png: a 40 x 20 RGBA image, opaque white in the left half (columns
0-19), fully transparent in the right half. At separation 0.1 over size 1.9 x 0.9 each grain
covers a 2 x 2 pixel block, so the `image` source makes a 10 x 10 sheet (tests/nodes/grains/
test_constraints.cpp)."""
import os
import struct
import zlib

W, H = 40, 20
rows = b""
for y in range(H):
    rows += b"\x00" + b"".join(
        (b"\xff\xff\xff\xff" if x < W // 2 else b"\x00\x00\x00\x00") for x in range(W))


def chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


png = (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", W, H, 8, 6, 0, 0, 0)) +
       chunk(b"IDAT", zlib.compress(rows)) + chunk(b"IEND", b""))
with open(os.path.join(os.path.dirname(os.path.abspath(__file__)), "mask_half.png"), "wb") as f:
    f.write(png)
