"""simplify(method="merge") to 1/16 on degenerate clouds, where every distance or cost ties
(identical Gaussians, a few positions with many copies, a line, a grid), beside a random cloud of
the same size: the time should scale with n on all of them (not a test). splat-transform 3.7.0's
-d on the identical cloud in the same run, when it is installed (scripts/splat_transform.sh; its
wall time includes Node's start-up, about 0.5 s): it refuses that cloud ("decimation stalled"),
so there is no peer ratio to give.

avsplat's figures are CPU time (process_time: every thread's) and wall time of the call.

Usage: PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_simplify_degenerate.py [--n N ...]
       (OMP_NUM_THREADS=1 for one thread)
"""
import argparse
import os
import subprocess
import tempfile
import time

import numpy as np

import avsplat
from avsplat.eval._report import machine

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
PEER = os.path.join(ROOT, "build-node", "node_modules", ".bin", "splat-transform")


def clouds(n, rng):
    """(name, means, scales, opacities) of each shape with n Gaussians."""
    same = np.tile([0.3, -0.2, 1.0], (n, 1))
    scales = np.tile([0.01, 0.02, 0.03], (n, 1))
    yield "identical", same, scales, np.full(n, 0.4)
    yield "same mean, random scales and opacities", same, rng.uniform(0.005, 0.03, (n, 3)), rng.uniform(0.05, 0.95, n)
    yield "100 positions, n/100 copies each", rng.uniform(-1, 1, (100, 3))[np.arange(n) % 100], scales, np.full(n, 0.4)
    yield "line, equal spacing", np.c_[np.arange(n) * 0.01, np.zeros(n), np.zeros(n)], scales, np.full(n, 0.4)
    yield "grid of 0.02", np.round(rng.uniform(-1, 1, (n, 3)) / 0.02) * 0.02, scales, np.full(n, 0.4)
    yield "random (reference)", rng.uniform(-1, 1, (n, 3)), scales, np.full(n, 0.4)


def make(means, scales, opacities):
    n = len(means)
    return avsplat.GaussianCloud(means.astype(np.float32), scales.astype(np.float32),
                                 np.tile(np.float32([1, 0, 0, 0]), (n, 1)), opacities.astype(np.float32),
                                 np.zeros((n, 1, 3), np.float32))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, nargs="+", default=[10_000, 100_000])
    args = ap.parse_args()
    print(machine())
    for n in args.n:
        rng = np.random.default_rng(0)
        print(f"\nn = {n}, ratio 1/16 (target {round(n / 16)})")
        print(f"  {'cloud':40s} {'CPU s':>8s} {'wall s':>8s} {'CPU us/Gaussian':>16s} {'out':>8s} {'rounds':>6s}")
        for name, means, scales, opacities in clouds(n, rng):
            c = make(means, scales, opacities)
            c0, w0 = time.process_time(), time.perf_counter()
            r = avsplat.simplify(c, ratio=1 / 16, method="merge")
            cpu, wall = time.process_time() - c0, time.perf_counter() - w0
            print(f"  {name:40s} {cpu:8.3f} {wall:8.3f} {1e6 * cpu / n:16.2f} {r.output_count:8d} {r.iterations:6d}")
        if os.access(PEER, os.X_OK):
            with tempfile.TemporaryDirectory() as tmp:
                src, dst = os.path.join(tmp, "in.ply"), os.path.join(tmp, "out.ply")
                avsplat.write_ply(src, make(*next(clouds(n, rng))[1:]))
                w0 = time.perf_counter()
                p = subprocess.run([PEER, "-q", "-w", "-g", "cpu", src, "-d", str(round(n / 16)), dst],
                                   capture_output=True, text=True)
                wall = time.perf_counter() - w0
                if p.returncode == 0:
                    got = f"out {len(avsplat.read_gaussians(dst))}"
                else:
                    got = "failed: " + next((l.strip() for l in (p.stderr + p.stdout).splitlines() if l.strip()), "?")
                print(f"  peer splat-transform -d on identical: wall {wall:.3f} s, {got}")
        else:
            print("  peer: splat-transform not installed (bash scripts/splat_transform.sh)")
    print(f"\nload average after the run: {os.getloadavg()[0]:.1f} (shared machine)")


if __name__ == "__main__":
    main()
