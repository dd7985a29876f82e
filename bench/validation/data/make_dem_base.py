#!/usr/bin/env python3
"""Writes dem_base.ply for bench/validation/dem_pile.json: the rough base of the LIGGGHTS pile
scene (../shared/reference/dem/scene_pile.in): one layer of fixed grains (mass 0) of diameter
0.01 m on a simple cubic lattice of spacing 0.01 m, offset by half a spacing, inside a disc of
radius 0.2 m, centres at y = 0.005 (the DEM's z = 0.005, y up here): 1,264 grains."""
import os

here = os.path.dirname(os.path.abspath(__file__))
d, radius = 0.01, 0.2
n = int(radius / d) + 1
points = []
for i in range(-n, n):
    for k in range(-n, n):
        x, z = (i + 0.5) * d, (k + 0.5) * d
        if x * x + z * z <= radius * radius:
            points.append((x, z))
with open(os.path.join(here, "dem_base.ply"), "w") as f:
    f.write("ply\nformat ascii 1.0\ncomment written by make_dem_base.py\nelement vertex %d\n"
            "property float x\nproperty float y\nproperty float z\nproperty float pscale\n"
            "property float mass\nend_header\n" % len(points))
    for x, z in points:
        f.write("%g %g %g %g 0\n" % (x, d / 2, z, d / 2))
print(len(points), "grains")
