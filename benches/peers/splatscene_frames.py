#!/usr/bin/env python3
"""Frame times of splatscene on a raw volume, with the camera and ramp of `vtk_raycast.py
--raw`, so that the two can be run in turn on the same picture.

Draws the volume through the Python module (`pip install ./python`), which composites as
`splatscene render` does (the CPU tile compositor where the GPU adapter is itself a CPU).
Frame 0 is a warm-up and is not timed (it classifies the volume); frame i turns the camera
by i times `--turn` degrees about the scene's up (the patient's superior axis) through the
target. A timed frame is one `Scene.render` call: ordering, compositing and the conversion of
the picture to 8-bit RGBA. Prints a JSON object on stdout: the median and minimum frame, and
the median of each stage the renderer reports.
"""

import argparse
import json
import statistics
import sys
import time


def triple(text, kind=float):
    parts = tuple(kind(v) for v in text.split(","))
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"{text!r}: three comma-separated numbers")
    return parts


def pair(text):
    parts = tuple(float(v) for v in text.split(","))
    if len(parts) != 2:
        raise argparse.ArgumentTypeError(f"{text!r}: two comma-separated numbers")
    return parts


def size(text):
    w, _, h = text.partition("x")
    return int(w), int(h)


def parse_args(argv):
    # Values that start with a minus sign (an eye at x < 0) are joined to their option, as
    # argparse would otherwise take them for options.
    joined = []
    for arg in argv:
        if joined and joined[-1] in ("--eye", "--target", "--origin") and arg.startswith("-"):
            joined[-1] = f"{joined[-1]}={arg}"
        else:
            joined.append(arg)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--raw", required=True)
    p.add_argument("--dims", type=lambda t: triple(t, int), required=True)
    p.add_argument("--scalar", default="u8")
    p.add_argument("--spacing", type=triple, default=[1.0, 1.0, 1.0])
    p.add_argument("--origin", type=triple)
    p.add_argument("--orientation", default="RAS")
    p.add_argument("--window", type=pair, required=True)
    p.add_argument("--eye", type=triple, required=True)
    p.add_argument("--target", type=triple, required=True)
    p.add_argument("--fov", type=float, default=35.0)
    p.add_argument("--size", type=size, default=(512, 512))
    p.add_argument("--frames", type=int, default=9)
    p.add_argument("--turn", type=float, default=7.0)
    p.add_argument("--lod", choices=["on", "off"], default="on")
    return p.parse_args(joined)


def main():
    args = parse_args(sys.argv[1:])
    try:
        import splatscene
    except ImportError as e:
        sys.exit(f"splatscene_frames: the Python module is not installed ({e}): pip install ./python")
    options = dict(dims=args.dims, scalar=args.scalar, spacing=args.spacing, orientation=args.orientation)
    if args.origin:
        options["origin"] = args.origin
    volume = splatscene.load_volume(args.raw, **options)
    scene = splatscene.Scene([volume], window=tuple(args.window))
    camera = dict(eye=args.eye, target=args.target, fov=args.fov, lod=args.lod == "on")
    times, reports = [], []
    for i in range(args.frames + 1):
        started = time.perf_counter()
        scene.render(args.size, orbit=(i * args.turn, 0.0), **camera)
        elapsed = time.perf_counter() - started
        if i > 0:
            times.append(elapsed * 1e3)
            reports.append(scene.report)
    stages = {}
    for key in ("order_ms",):
        stages[key] = statistics.median(r[key] for r in reports)
    for key in ("project_ms", "bin_ms", "tiles_ms"):
        values = [r["tiles"][key] for r in reports if r.get("tiles")]
        if values:
            stages[key] = statistics.median(values)
    print(
        json.dumps(
            {
                "volume": args.raw,
                "size": list(args.size),
                "frames": args.frames,
                "splats": reports[-1]["splats"] if reports else 0,
                "level": reports[-1]["level"] if reports else 0,
                "frames_ms": [round(t, 1) for t in times],
                "levels": [r.get("levels") for r in reports],
                "levels_ms": [r.get("levels_ms") for r in reports],
                "texels_ms": [r.get("texels_ms") for r in reports],
                "splats_per_frame": [r["splats"] for r in reports],
                "median_ms": statistics.median(times) if times else None,
                "min_ms": min(times) if times else None,
                "stages_median_ms": stages,
            }
        )
    )


if __name__ == "__main__":
    main()
