#!/usr/bin/env python3
"""Writes tube.obj for bench/validation/column_collapse.json: an open cylinder (no caps) of
radius 1 from y = 0 to y = 20, 96 facets round. The collapse scene scales it to the column's
radius (plus half a grain) as a mesh collider, a two-sided shell the column settles in; at the
release the scale jumps a hundredfold, the tube's wall moving away from the grains along its
normal, as a tube lifted off a column leaves it standing (Lube et al. 2004)."""
import math
import os

here = os.path.dirname(os.path.abspath(__file__))
segments, height = 96, 20.0
with open(os.path.join(here, "tube.obj"), "w") as f:
    f.write("# written by make_tube.py: open cylinder, radius 1, y 0..%g\n" % height)
    for y in (0.0, height):
        for k in range(segments):
            a = 2 * math.pi * k / segments
            f.write("v %.9f %g %.9f\n" % (math.cos(a), y, math.sin(a)))
    for k in range(segments):
        a, b = 1 + k, 1 + (k + 1) % segments
        c, d = a + segments, b + segments
        f.write("f %d %d %d\nf %d %d %d\n" % (a, b, d, a, d, c))
