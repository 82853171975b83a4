#!/usr/bin/env python3
"""How far apart a volume's voxels fall on the screen, brick by brick, across the lines of
sight: what a level of detail chosen per 16^3 brick could halve in one view.

usage: brick_spacing.py RAW --dims X,Y,Z --scalar u8|u16 --spacing SX,SY,SZ
           --orientation LAI --above V --eye X,Y,Z --target X,Y,Z [--fov 35] [--size WxH]

The volume's index (0, 0, 0) sits at the world origin, each index axis running toward the
patient direction its letter names (RAS world: +x the patient's right), as `splatscene render --orientation` places a
raw volume. A voxel counts as a splat where its value is above `--above` (the transfer
function's window starts there; the renderer's classification, which needs some opacity, is
not redone). For each brick holding splats, and for each axis, the part of a voxel's edge
that lies across the sight line from the eye to the brick's centre is taken in pixels at the
brick's distance; the brick's spacing is the largest over its axes. Prints the share of splats
in bricks whose spacing is at most 0.5, 0.75 and 1 pixel (the renderer halves an axis where
its voxels fall at most half a pixel apart across the view), and the spacing's range. Needs
numpy.
"""
import argparse
import math

import numpy as np

BRICK = 16
TOWARD = {"R": (0, 1), "L": (0, -1), "A": (1, 1), "P": (1, -1), "S": (2, 1), "I": (2, -1)}


def numbers(text, kind=float):
    return tuple(kind(v) for v in text.split(","))


def main():
    # Values that start with a minus sign are joined to their option.
    import sys

    argv = []
    for arg in sys.argv[1:]:
        if argv and argv[-1] in ("--eye", "--target") and arg.startswith("-"):
            argv[-1] = f"{argv[-1]}={arg}"
        else:
            argv.append(arg)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("raw")
    p.add_argument("--dims", type=lambda t: numbers(t, int), required=True)
    p.add_argument("--scalar", choices=["u8", "u16"], default="u8")
    p.add_argument("--spacing", type=numbers, default=(1.0, 1.0, 1.0))
    p.add_argument("--orientation", default="RAS")
    p.add_argument("--above", type=float, required=True)
    p.add_argument("--eye", type=numbers, required=True)
    p.add_argument("--target", type=numbers, required=True)
    p.add_argument("--fov", type=float, default=35.0)
    p.add_argument("--size", default="512x512")
    a = p.parse_args(argv)
    nx, ny, nz = a.dims
    dtype = np.uint8 if a.scalar == "u8" else np.uint16
    values = np.memmap(a.raw, dtype=dtype, mode="r", shape=(nz, ny, nx))
    bz, by, bx = nz // BRICK, ny // BRICK, nx // BRICK
    counts = np.zeros((bz, by, bx), dtype=np.int64)
    for k in range(bz):
        slab = values[k * BRICK : (k + 1) * BRICK, : by * BRICK, : bx * BRICK] > a.above
        counts[k] = slab.reshape(BRICK, by, BRICK, bx, BRICK).sum(axis=(0, 2, 4))
    # Index to world: column `i` is index axis i's step in RAS millimetres.
    m = np.zeros((3, 3))
    for i, letter in enumerate(a.orientation):
        axis, sign = TOWARD[letter]
        m[axis, i] = sign * a.spacing[i]
    eye, target = np.array(a.eye), np.array(a.target)
    forward = (target - eye) / np.linalg.norm(target - eye)
    h = int(a.size.split("x")[1])
    focal = 0.5 * h / math.tan(math.radians(a.fov) / 2)
    kz, ky, kx = np.meshgrid(np.arange(bz), np.arange(by), np.arange(bx), indexing="ij")
    centres = (np.stack([kx, ky, kz], -1).reshape(-1, 3) + 0.5) * BRICK
    d = centres @ m.T - eye
    distance = np.linalg.norm(d, axis=1)
    sight = d / distance[:, None]
    spacing = np.zeros(len(d))
    for i in range(3):
        axis = m[:, i] / a.spacing[i]
        across = a.spacing[i] * np.sqrt(np.maximum(0.0, 1.0 - (sight @ axis) ** 2))
        spacing = np.maximum(spacing, focal * across / distance)
    c = counts.reshape(-1)
    seen = (c > 0) & (d @ forward > 0)
    total = c[seen].sum()
    for limit in (0.5, 0.75, 1.0):
        share = c[seen & (spacing <= limit)].sum() / max(total, 1)
        print(f"splats in bricks at most {limit} px apart across the view: {share:.1%}")
    print(
        f"spacing over the bricks holding splats: {spacing[seen].min():.2f} to "
        f"{spacing[seen].max():.2f} px, median by splat {np.median(np.repeat(spacing[seen], c[seen])):.2f}"
    )


if __name__ == "__main__":
    main()
