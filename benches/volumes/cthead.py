#!/usr/bin/env python3
"""Write the Stanford CT head at two grids for fidelity and cost checks on a second CT.

usage: cthead.py DATA_DIR THICK.raw THIN.raw

Reads DATA_DIR/volumes/stanford_cthead/CThead.1..113 (256 x 256 slices of big-endian u16,
voxel aspect 1:1:2), divides the values by 16 and rounds them to u8 (soft tissue lands at
about 60-80, bone at 110-190), and writes:

- THICK.raw: the head on its own grid, 256 x 256 x 113 u8, spacing 1 x 1 x 2 mm;
- THIN.raw: the same values interpolated trilinearly (numpy, one axis at a time, the first
  and last samples kept, as ../shared/data/make_large_ct.py does) onto 512 x 512 x 449 u8,
  spacing 0.499022 x 0.499022 x 0.5 mm: the same box.

Both x fastest, no header, orientation RAS at origin 0. Needs numpy; about 1.5 GB of memory.
"""
import os
import sys

import numpy as np


def resample(a, axis, n_out):
    """Linear interpolation of `a` along `axis` onto n_out samples spanning its first to last."""
    n_in = a.shape[axis]
    pos = np.linspace(0.0, n_in - 1.0, n_out, dtype=np.float64)
    i0 = np.floor(pos).astype(np.int64)
    i1 = np.minimum(i0 + 1, n_in - 1)
    w = (pos - i0).astype(np.float32)
    shape = [1] * a.ndim
    shape[axis] = n_out
    w = w.reshape(shape)
    return np.take(a, i0, axis=axis) * (1.0 - w) + np.take(a, i1, axis=axis) * w


def main():
    if len(sys.argv) != 4:
        sys.exit(__doc__)
    data, thick_out, thin_out = sys.argv[1:]
    stem = os.path.join(data, "volumes", "stanford_cthead", "CThead.")
    v = np.stack([np.fromfile(stem + str(i), dtype=">u2").reshape(256, 256) for i in range(1, 114)])
    u = np.clip(v.astype(np.float32) / 16.0, 0, 255)
    np.rint(u).astype(np.uint8).tofile(thick_out)
    t = resample(u, 2, 512)
    t = resample(t, 1, 512)
    t = resample(t, 0, 449)
    np.clip(np.rint(t), 0, 255).astype(np.uint8).tofile(thin_out)
    print(f"wrote {thick_out}: 256x256x113 u8, spacing 1,1,2")
    print(f"wrote {thin_out}: 512x512x449 u8, spacing 0.499022,0.499022,0.5")


if __name__ == "__main__":
    main()
