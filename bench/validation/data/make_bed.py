#!/usr/bin/env python3
"""Writes rough_bed.ply for bench/validation/angle_of_repose.json and column_collapse.json: a disc of radius 1.2 m of
fixed grains (mass 0, so nothing moves them) on a square lattice of spacing 0.02 m, resting on
y = 0 (centres at y = 0.01, pscale 0.01). Poured grains stand on it as on the rough base of fixed
spheres that DEM angle-of-repose studies use, so the colliders can stay frictionless."""
import os

here = os.path.dirname(os.path.abspath(__file__))
d, radius = 0.02, 1.2
n = int(radius / d)
points = []
for i in range(-n, n + 1):
    for k in range(-n, n + 1):
        x, z = i * d, k * d
        if x * x + z * z <= radius * radius:
            points.append((x, z))
with open(os.path.join(here, "rough_bed.ply"), "w") as f:
    f.write("ply\nformat ascii 1.0\ncomment written by make_bed.py\nelement vertex %d\n"
            "property float x\nproperty float y\nproperty float z\nproperty float pscale\n"
            "property float mass\nend_header\n" % len(points))
    for x, z in points:
        f.write("%g %g %g %g 0\n" % (x, d / 2, z, d / 2))
