#!/usr/bin/env python3
"""Write a dense benchmark volume: a textured ball filling an N^3 grid of u16.

usage: ball.py N OUT.raw

Inside a ball of radius 0.48 N about the grid's centre the value is
1000 * (0.5 + 0.5 * sin(s x) sin(s y) sin(s z)) with s = 512 / (10 N) per voxel (the same
pattern at any N); outside it is 0. x is fastest, no header. Written one z-slice at a time, so
that a 1024^3 volume (2 GiB) needs a few MB of memory. Prints the share of voxels at or above a
few values, to choose a window with the share of significant voxels wanted (600 gives about
11%). Needs numpy.
"""
import sys

import numpy as np

n, out = int(sys.argv[1]), sys.argv[2]
c = (n - 1) / 2.0
r = 0.48 * n
s = 512.0 / (10.0 * n)
y, x = np.mgrid[0:n, 0:n].astype(np.float32)
sx, sy = np.sin(x * s), np.sin(y * s)
inside_xy = (x - c) ** 2 + (y - c) ** 2
hist = np.zeros(1001, np.int64)
with open(out, "wb") as f:
    for z in range(n):
        inside = inside_xy + (z - c) ** 2 <= r * r
        v = 1000.0 * (0.5 + 0.5 * sx * sy * np.sin(z * s))
        slab = np.where(inside, v, 0).astype(np.uint16)
        hist += np.bincount(slab.ravel(), minlength=1001)[:1001]
        f.write(slab.tobytes())
share = np.cumsum(hist[::-1])[::-1] / hist.sum()
for t in (550, 600, 650, 700):
    print(f"share of voxels >= {t}: {share[t]:.3f}")
