"""SOG encoding speed and round-trip quality: avsplat.write_sog against splat-transform 3.7.0
(`-g cpu`) on the same clouds, in the same run (not a test).

Clouds: `avsplat.eval.reduction.trained_like_cloud(n, seed=0)` (the statistics of trained 3DGS
scenes, SH degree 3), cut to the SH degree asked. For each size and degree: the wall time of each
writer (splat-transform's from the PLY it reads, Node's start-up included), bytes per Gaussian,
and the PSNR of renders of each decoded cloud (both decoded by avsplat.read_sog) against renders
of the original at 4 orbit cameras around the scene (256 x 256).

Usage: PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_sog_speed.py
       [--sizes 100000 500000 1000000] [--degrees 3] [--peer-timeout 1800]
"""
import argparse
import os
import subprocess
import tempfile
import time

import numpy as np

import avsplat
from avsplat.eval.reduction import trained_like_cloud
from bench_sog import machine  # the same machine line as the SOG benchmark beside it

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def with_degree(cloud, degree):
    k = (degree + 1) ** 2
    return avsplat.GaussianCloud(cloud.means, cloud.scales, cloud.rotations, cloud.opacities,
                                 np.ascontiguousarray(cloud.sh[:, :k]))


def psnrs(cloud, cams, refs):
    return [avsplat.psnr(avsplat.render(cloud, c).color, r) for c, r in zip(cams, refs)]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", type=int, nargs="+", default=[100_000, 500_000, 1_000_000])
    ap.add_argument("--degrees", type=int, nargs="+", default=[3], choices=[1, 2, 3])
    ap.add_argument("--peer-timeout", type=float, default=1800)
    args = ap.parse_args()
    exe = subprocess.run(["bash", os.path.join(ROOT, "scripts", "splat_transform.sh")],
                         capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
    print(f"machine: {machine()}\n")
    print("| Gaussians | SH | writer | write s | bytes / Gaussian | PSNR dB (4 views, min..max) | speed-up |")
    print("|---:|---:|---|---:|---:|---|---:|")
    for n in args.sizes:
        base = trained_like_cloud(n, seed=0)
        for degree in args.degrees:
            cloud = with_degree(base, degree)
            cams = avsplat.orbit_cameras(cloud, 4, width=256, height=256)
            refs = [avsplat.render(cloud, c).color for c in cams]
            with tempfile.TemporaryDirectory() as tmp:
                ply = os.path.join(tmp, "scene.ply")
                avsplat.write_ply(ply, cloud)
                ours, theirs = os.path.join(tmp, "ours.sog"), os.path.join(tmp, "theirs.sog")
                t = time.perf_counter()
                avsplat.write_sog(ours, cloud)
                t_ours = time.perf_counter() - t
                t = time.perf_counter()
                try:
                    subprocess.run([exe, "-q", "-w", "-g", "cpu", ply, theirs], check=True, timeout=args.peer_timeout)
                    t_theirs = time.perf_counter() - t
                except subprocess.TimeoutExpired:
                    t_theirs = None
                rows = [("avsplat.write_sog", ours, t_ours)]
                if t_theirs is not None:
                    rows.append(("splat-transform 3.7.0", theirs, t_theirs))
                for name, path, secs in rows:
                    p = psnrs(avsplat.read_sog(path), cams, refs)
                    ratio = f"{t_theirs / t_ours:.1f}x" if name.startswith("avsplat") and t_theirs else ""
                    print(f"| {n:,} | {degree} | {name} | {secs:.1f} | {os.path.getsize(path) / n:.2f} | "
                          f"{np.mean(p):.2f} ({min(p):.2f}..{max(p):.2f}) | {ratio} |", flush=True)
                if t_theirs is None:
                    print(f"| {n:,} | {degree} | splat-transform 3.7.0 | > {args.peer_timeout:.0f} (stopped) | | | |",
                          flush=True)
    print(f"\nload average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
