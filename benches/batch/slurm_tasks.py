#!/usr/bin/env python3
"""Wall time of one batch split over 1, 2 and 4 Slurm array tasks, on a throwaway single-node
cluster (examples/slurm/local-cluster.sh; needs root and Debian's slurm-wlm and munge), from
submission until the last task ends, each task given one CPU (--cpus-per-task=1). The task
counts alternate round by round.

    cargo build --release
    python3 benches/batch/slurm_tasks.py [--rounds 3] [--jobs 8]

The manifest: JOBS cases of the built-in shoulder scene and LIDC2 (examples/scenes), each in
four views at 512x384. Prints a Markdown table: per task count, the median wall time and the
speedup over one task, and the same batch run as one process without Slurm.
"""
import argparse
import os
import shutil
import statistics
import subprocess
import tempfile
import time

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
BINARY = os.path.join(ROOT, "target", "release", "splatscene")
CLUSTER = os.path.join(ROOT, "examples", "slurm", "local-cluster.sh")
SCRIPT = os.path.join(ROOT, "examples", "slurm", "planning-report.sbatch")
SCENES = ["shoulder.toml", "lidc2-shoulders.toml"]


def write_manifest(path, jobs):
    with open(path, "w") as f:
        f.write('[defaults]\nviews = ["anterior", "posterior", "right", "superior"]\n')
        f.write("sizes = [[512, 384]]\n")
        for i in range(jobs):
            scene = os.path.join(ROOT, "examples", "scenes", SCENES[i % len(SCENES)])
            f.write(f'\n[[job]]\nname = "case-{i + 1}"\nscene = "{scene}"\n')


def run_array(env, manifest, out, tasks, work):
    shutil.rmtree(out, ignore_errors=True)
    start = time.perf_counter()
    job = subprocess.run(
        ["sbatch", "--parsable", f"--array=1-{tasks}", "--cpus-per-task=1",
         f"--output={work}/log-%A_%a.txt", SCRIPT, manifest, out],
        check=True, env=env, cwd=work, capture_output=True, text=True).stdout.strip()
    job = job.split(";")[0]
    # sbatch --wait polls every few seconds; squeue every 50 ms resolves the end far better.
    while subprocess.run(["squeue", "--noheader", f"--jobs={job}"], env=env,
                         capture_output=True, text=True).stdout.strip():
        time.sleep(0.05)
    elapsed = time.perf_counter() - start
    for k in range(1, tasks + 1):
        index = os.path.join(out, f"index-{k}-of-{tasks}.json")
        with open(index) as f:
            if '"failed": 0' not in f.read():
                raise SystemExit(f"{index}: a job failed")
    return elapsed


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--jobs", type=int, default=8)
    args = parser.parse_args()
    counts = [1, 2, 4]
    with tempfile.TemporaryDirectory() as work:
        cluster = os.path.join(work, "cluster")
        subprocess.run([CLUSTER, "start", cluster], check=True, stdout=subprocess.DEVNULL)
        try:
            # The tasks run in the scratch folder: the data folder must be absolute.
            data = os.environ.get("SPLATSCENE_DATA") or os.path.join(ROOT, "..", "shared", "data")
            env = dict(os.environ, SLURM_CONF=os.path.join(cluster, "slurm.conf"),
                       SPLATSCENE=BINARY, NODEVICE_SELECT="1",
                       SPLATSCENE_DATA=os.path.abspath(data))
            manifest = os.path.join(work, "manifest.toml")
            write_manifest(manifest, args.jobs)
            times = {n: [] for n in counts}
            direct = []
            for _ in range(args.rounds):
                out = os.path.join(work, "direct")
                shutil.rmtree(out, ignore_errors=True)
                start = time.perf_counter()
                subprocess.run([BINARY, "batch", manifest, "--out", out], check=True, env=env,
                               stderr=subprocess.DEVNULL)
                direct.append(time.perf_counter() - start)
                for n in counts:
                    times[n].append(run_array(env, manifest, os.path.join(work, "out"), n, work))
        finally:
            subprocess.run([CLUSTER, "stop", cluster], check=True)
    cpus = os.cpu_count()
    print(f"| array tasks ({cpus} CPUs, {args.jobs} cases x 4 views) | median wall time "
          f"of {args.rounds} | speedup over 1 task |")
    print("|---|---|---|")
    one = statistics.median(times[1])
    print(f"| none: one process without Slurm | {statistics.median(direct):.1f} s | "
          f"{one / statistics.median(direct):.2f}x |")
    for n in counts:
        t = statistics.median(times[n])
        print(f"| {n} | {t:.1f} s | {one / t:.2f}x |")


if __name__ == "__main__":
    main()
