"""Benchmark of voxel fusion against Open3D and the memory-bandwidth floor (not a test).

Workload: N = 2,000,000 samples uniformly on a unit sphere shell (radius uniform in
[0.996, 1.004]), C = 56 float32 feature channels, a confidence logit ~ N(0, 1) per sample, voxel
0.01 (about 225k occupied voxels). The samples are in random order by default, the worst case
for the scattered reads of grouping; --order scan sorts them along latitude rows, as per-view
pixel predictions arrive.

Timed in the same run: after one warm-up call of each, --repeats rounds each time every method
once, in turn (each round starting one method later), so that the machine's state (other
processes, memory traffic, what the previous call left in the caches) weighs on all alike; the
table gives each method's median and the median of the per-round ratios (round r's ratio uses
the times of round r):
  avsplat occupancy   avsplat.fuse_voxels(p, f, voxel, conf)                (AVSplat, Algorithm 2)
  avsplat softmax     avsplat.fuse_voxels(p, f, voxel, conf, policy="softmax")      (AnySplat)
  avsplat mean        avsplat.fuse_voxels(p, f, voxel)                (plain average, no conf)
  Open3D              open3d.t.geometry.PointCloud.voxel_down_sample(voxel) with the 56
                      channels as one attribute "features" (Open3D averages every attribute)
  memcpy              np.copyto of the input bytes (positions, features, confidence) into
                      buffers touched beforehand: the bandwidth floor

Open3D gets its tensors through Tensor.from_numpy (no copy) outside the timed call. Both
libraries run with the same number of OpenMP threads: --threads 1,2 (the default) measures each
count in its own interpreter (OMP_NUM_THREADS is read at start-up), one after the other, and
ends with a summary; numpy's memcpy is one thread either way. Prints, per thread count, the
machine line, a markdown table and whether the targets are met (occupancy
>= 5x faster than Open3D and <= 4x the memcpy time, with one and with two threads).

Usage: PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_fusion.py [--samples 2000000]
       [--channels 56] [--voxel 0.01] [--repeats 3] [--order random|scan] [--threads 1,2]
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import time

import numpy as np

import avsplat
from avsplat.eval._report import machine


def workload(n, channels, order="random", seed=0):
    rng = np.random.default_rng(seed)
    d = rng.standard_normal((n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    if order == "scan":
        # Spatially coherent order, as per-view pixel predictions arrive: rows of latitude, each
        # swept in longitude (bands of about two voxels).
        lat = np.floor((np.arcsin(np.clip(d[:, 2], -1, 1)) + np.pi / 2) / 0.02)
        lon = np.arctan2(d[:, 1], d[:, 0])
        d = d[np.lexsort((lon, lat))]
    r = rng.uniform(0.996, 1.004, size=(n, 1))
    positions = (d * r).astype(np.float32)
    features = rng.uniform(-1, 1, size=(n, channels)).astype(np.float32)
    confidence = rng.standard_normal(n).astype(np.float32)
    return positions, features, confidence


def interleaved_times(methods, repeats):
    """Seconds of each of `methods` (name -> callable) in each of `repeats` rounds, after one
    warm-up call each (first touch of pages, lazy initialisation). Each round calls every
    method once, in turn, starting one method later than the round before, so that no method
    always follows the same one (a memcpy leaves dirty cache lines and cold caches behind,
    Open3D its threads and freed memory); the result of a call is released before the next
    starts."""
    for fn in methods.values():
        fn()
    names = list(methods)
    times = {name: [] for name in names}
    for r in range(repeats):
        for k in range(len(names)):
            name = names[(r + k) % len(names)]
            t0 = time.perf_counter()
            methods[name]()
            times[name].append(time.perf_counter() - t0)
    return {name: np.array(t) for name, t in times.items()}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--samples", type=int, default=2_000_000)
    ap.add_argument("--channels", type=int, default=56)
    ap.add_argument("--voxel", type=float, default=0.01)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--order", choices=("random", "scan"), default="random",
                    help="sample order: random (the worst case for memory access, default) or scan "
                         "(spatially coherent, like per-view pixel predictions)")
    ap.add_argument("--threads", default="1,2",
                    help="comma-separated OpenMP thread counts, each measured in its own interpreter "
                         "(default 1,2); 'env' measures in this process with OMP_NUM_THREADS as set")
    args = ap.parse_args()
    if args.threads != "env":
        run_thread_counts(args)
        return

    import open3d as o3d

    p, f, conf = workload(args.samples, args.channels, args.order)
    n, c, voxel = args.samples, args.channels, args.voxel
    print(f"bench_fusion: {n:,} samples on a unit sphere shell ({args.order} order), {c} channels, "
          f"voxel {voxel}, median of {args.repeats}")
    print(f"machine: {machine()}; numpy {np.__version__}, open3d {o3d.__version__}")

    occ = avsplat.fuse_voxels(p, f, voxel, conf)
    pcd = o3d.t.geometry.PointCloud(o3d.core.Tensor.from_numpy(p))
    pcd.point["features"] = o3d.core.Tensor.from_numpy(f)
    down = pcd.voxel_down_sample(voxel)
    dst = [np.ones_like(a) for a in (p, f, conf)]

    def copy():
        for s, d in zip((p, f, conf), dst):
            np.copyto(d, s)

    names = {
        "occupancy": "avsplat occupancy",
        "softmax": "avsplat softmax",
        "mean": "avsplat mean (no confidence)",
        "open3d": "Open3D t.PointCloud.voxel_down_sample",
        "memcpy": "memcpy of the input bytes",
    }
    times = interleaved_times({
        "occupancy": lambda: avsplat.fuse_voxels(p, f, voxel, conf),
        "softmax": lambda: avsplat.fuse_voxels(p, f, voxel, conf, policy="softmax"),
        "mean": lambda: avsplat.fuse_voxels(p, f, voxel, policy="mean"),
        "open3d": lambda: pcd.voxel_down_sample(voxel),
        "memcpy": copy,
    }, args.repeats)
    voxels = {"occupancy": len(occ), "softmax": len(occ), "mean": len(occ),
              "open3d": down.point.positions.shape[0], "memcpy": None}
    input_mib = (p.nbytes + f.nbytes + conf.nbytes) / 2**20
    t_copy, t_o3d = times["memcpy"], times["open3d"]

    print()
    print("| method | seconds (median) | / memcpy | Open3D / method | voxels |")
    print("|---|---:|---:|---:|---:|")
    for key, name in names.items():
        t = times[key]
        m = voxels[key]
        print(f"| {name} | {np.median(t):.4f} | {np.median(t / t_copy):.2f} | {np.median(t_o3d / t):.2f} | "
              f"{'' if m is None else f'{m:,}'} |")
    print()
    print(f"ratios are medians over {args.repeats} rounds of the ratio within a round; input {input_mib:.0f} MiB; "
          f"peak RSS of this process {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB")
    speedup, floor = np.median(t_o3d / times["occupancy"]), np.median(times["occupancy"] / t_copy)
    print(f"target: occupancy >= 5x faster than Open3D: {speedup:.2f}x -> {'met' if speedup >= 5 else 'NOT met'}")
    print(f"target: occupancy within 4x of memcpy: {floor:.2f}x -> {'met' if floor <= 4 else 'NOT met'}")
    print("SUMMARY " + json.dumps({
        "threads": os.environ.get("OMP_NUM_THREADS", str(os.cpu_count())),
        "occupancy": float(np.median(times["occupancy"])), "open3d": float(np.median(t_o3d)),
        "memcpy": float(np.median(t_copy)), "speedup": float(speedup), "floor": float(floor),
        "load": os.getloadavg()[0]}))


def run_thread_counts(args):
    """Runs this benchmark once per thread count of --threads, each in its own interpreter with
    OMP_NUM_THREADS set, prints their output and a summary table."""
    rows = []
    for t in args.threads.split(","):
        t = t.strip()
        cmd = [sys.executable, os.path.abspath(__file__), "--samples", str(args.samples), "--channels",
               str(args.channels), "--voxel", str(args.voxel), "--repeats", str(args.repeats),
               "--order", args.order, "--threads", "env"]
        done = subprocess.run(cmd, env=dict(os.environ, OMP_NUM_THREADS=t), capture_output=True, text=True)
        sys.stdout.write(done.stdout)
        sys.stderr.write(done.stderr)
        if done.returncode != 0:
            raise SystemExit(f"bench_fusion with OMP_NUM_THREADS={t} failed ({done.returncode})")
        rows += [json.loads(line[len("SUMMARY "):]) for line in done.stdout.splitlines() if line.startswith("SUMMARY ")]
        print()
    print("| threads | occupancy s | Open3D s | memcpy s | Open3D / occupancy (target >= 5) | "
          "occupancy / memcpy (target <= 4) | load |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['threads']} | {r['occupancy']:.4f} | {r['open3d']:.4f} | {r['memcpy']:.4f} | "
              f"{r['speedup']:.2f} ({'met' if r['speedup'] >= 5 else 'NOT met'}) | "
              f"{r['floor']:.2f} ({'met' if r['floor'] <= 4 else 'NOT met'}) | {r['load']:.1f} |")


if __name__ == "__main__":
    main()
