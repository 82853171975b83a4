#!/usr/bin/env python3
"""Views per second of one `splatscene batch` process against one `splatscene render` process
per view, on the built-in scene and on LIDC2 (examples/scenes/lidc2-shoulders.toml), the two
sides alternating round by round so that the machine's drift falls on both.

    cargo build --release
    python3 benches/batch/views_per_second.py [--rounds 5] [--size 512x384]

Prints a Markdown table: per scene, the median wall time of each side over the rounds, views
per second, and the ratio. Needs the shared data for LIDC2 (SPLATSCENE_DATA, default
../shared/data).
"""
import argparse
import os
import shutil
import statistics
import subprocess
import tempfile
import time

VIEWS = ["anterior", "posterior", "left", "right", "superior", "inferior"]
ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BINARY = os.path.join(ROOT, "target", "release", "splatscene")
SCENES = {
    "built-in shoulder scene": os.path.join(ROOT, "examples", "scenes", "shoulder.toml"),
    "LIDC2 shoulders": os.path.join(ROOT, "examples", "scenes", "lidc2-shoulders.toml"),
}


def run(args):
    env = dict(os.environ, NODEVICE_SELECT="1")
    subprocess.run(args, check=True, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def batch_once(scene, size, work):
    out = os.path.join(work, "batch")
    shutil.rmtree(out, ignore_errors=True)
    manifest = os.path.join(work, "manifest.toml")
    w, h = size.split("x")
    with open(manifest, "w") as f:
        f.write(f'[[job]]\nname = "case"\nscene = "{scene}"\n')
        f.write("views = [" + ", ".join(f'"{v}"' for v in VIEWS) + "]\n")
        f.write(f"sizes = [[{w}, {h}]]\n")
    start = time.perf_counter()
    run([BINARY, "batch", manifest, "--out", out])
    return time.perf_counter() - start


def renders_once(scene, size, work):
    start = time.perf_counter()
    for view in VIEWS:
        run([BINARY, "render", scene, "--view", view, "--size", size,
             "--out", os.path.join(work, f"render-{view}.png")])
    return time.perf_counter() - start


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=5)
    parser.add_argument("--size", default="512x384")
    args = parser.parse_args()
    print(f"| scene | {len(VIEWS)} views, {args.size} | one batch process | "
          f"one render process per view | batch speedup |")
    print("|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as work:
        for name, scene in SCENES.items():
            batch, renders = [], []
            for _ in range(args.rounds):
                batch.append(batch_once(scene, args.size, work))
                renders.append(renders_once(scene, args.size, work))
            b, r = statistics.median(batch), statistics.median(renders)
            n = len(VIEWS)
            print(f"| {name} | median of {args.rounds} | {b:.2f} s ({n / b:.1f} views/s) | "
                  f"{r:.2f} s ({n / r:.1f} views/s) | {r / b:.1f}x |")


if __name__ == "__main__":
    main()
