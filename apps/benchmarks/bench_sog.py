"""SOG (PlayCanvas) on the embedded scene: size, round-trip image error and time, avsplat against
splat-transform 3.7.0 in the same run (not a test).

Scene: the demo's (simulate_predictions(views=32, width=192, height=144, seed=0), fused with
the occupancy policy at voxel 0.02; SH degree 0). With --sh-degree 3 the SH bands 1..3 are filled
with N(0, 0.05) noise (synthetic: the simulator predicts degree 0 only) to time the palette
k-means. For each writer: bytes per Gaussian of the .sog, wall time of the write (splat-transform's
includes Node's start-up, about 0.5 s; it runs with -g cpu), and PSNR of the decoded cloud's
renders against the original's at the four held-out target cameras (both decoded by avsplat).

Usage: PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_sog.py [--sh-degree 0|3]
       [--max-gaussians N]  (every k-th Gaussian of the scene, at most N)
"""
import argparse
import os
import subprocess
import tempfile
import time

import numpy as np

import avsplat

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def machine():
    model = next((l.split(":", 1)[1].strip() for l in subprocess.run(
        ["lscpu"], capture_output=True, text=True).stdout.splitlines() if l.startswith("Model name")), "?")
    return f"{model}, {os.cpu_count()} cores, OMP threads {os.environ.get('OMP_NUM_THREADS', 'all')}, " \
           f"load average {os.getloadavg()[0]:.1f} (shared machine)"


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sh-degree", type=int, default=0, choices=[0, 3])
    ap.add_argument("--peer-timeout", type=float, default=600, help="seconds splat-transform may take")
    ap.add_argument("--max-gaussians", type=int, default=0, help="keep every k-th Gaussian, at most this many")
    args = ap.parse_args()
    pred = avsplat.simulate_predictions(views=32, width=192, height=144, seed=0)
    cloud = avsplat.fuse_gaussians(pred.gaussians(), 0.02, policy="occupancy").cloud
    if args.max_gaussians and len(cloud) > args.max_gaussians:
        step = -(-len(cloud) // args.max_gaussians)
        cloud = avsplat.GaussianCloud(cloud.means[::step], cloud.scales[::step], cloud.rotations[::step],
                                      cloud.opacities[::step], cloud.sh[::step])
    if args.sh_degree == 3:
        n = len(cloud)
        sh = np.zeros((n, 16, 3), np.float32)
        sh[:, 0] = cloud.sh[:, 0]
        sh[:, 1:] = np.random.default_rng(0).normal(0, 0.05, (n, 15, 3))
        cloud = avsplat.GaussianCloud(cloud.means, cloud.scales, cloud.rotations, cloud.opacities, sh)
    exe = subprocess.run(["bash", os.path.join(ROOT, "scripts", "splat_transform.sh")],
                         capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
    cams = pred.target_cameras
    refs = [avsplat.render(cloud, c).color for c in cams]
    print(f"machine: {machine()}")
    print(f"scene: {len(cloud)} Gaussians, SH degree {cloud.sh_degree}\n")
    print("| writer | bytes / Gaussian | write s | PSNR dB (4 views, min..max) |")
    print("|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        ply = os.path.join(tmp, "scene.ply")
        avsplat.write_ply(ply, cloud)
        rows = []
        ours = os.path.join(tmp, "ours.sog")
        t = time.perf_counter()
        avsplat.write_sog(ours, cloud)
        rows.append(("avsplat.write_sog", ours, time.perf_counter() - t))
        theirs = os.path.join(tmp, "theirs.sog")
        t = time.perf_counter()
        try:
            subprocess.run([exe, "-q", "-w", "-g", "cpu", ply, theirs], check=True, timeout=args.peer_timeout)
            rows.append(("splat-transform 3.7.0", theirs, time.perf_counter() - t))
        except subprocess.TimeoutExpired:
            print(f"| splat-transform 3.7.0 | - | > {args.peer_timeout:.0f} (stopped) | - |")
        for name, path, secs in rows:
            back = avsplat.read_sog(path)
            psnr = [avsplat.psnr(avsplat.render(back, c).color, r) for c, r in zip(cams, refs)]
            print(f"| {name} | {os.path.getsize(path) / len(cloud):.2f} | {secs:.2f} | "
                  f"{np.mean(psnr):.2f} ({min(psnr):.2f}..{max(psnr):.2f}) |")
        t = time.perf_counter()
        avsplat.read_sog(ours)
        print(f"\navsplat.read_sog of its file: {time.perf_counter() - t:.2f} s; "
              f"3DGS PLY: {os.path.getsize(ply) / len(cloud):.0f} bytes / Gaussian")
    print(f"load average after: {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
