"""SPZ on the embedded scene: bytes per Gaussian and the image error of a round trip, ours and
PlayCanvas's splat-transform 3.7 (when scripts/splat_transform.sh has installed it).

    PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/spz_round_trip.py

The scene is the demo's: 32 simulated views of 192 x 144, fused with `occupancy` at voxel 0.02.
Each file is read back, rendered from the four held-out cameras and compared (PSNR) with the
render of the cloud before writing and with the ray-cast ground truth. Sizes and PSNR do not
depend on the machine. Timings (best of 3, wall clock) are printed with the CPU, the thread count
and the load average: ours are the library calls, splat-transform's are its whole command (Node
start-up included, so the ratio flatters us for small scenes).
"""
import os
import pathlib
import subprocess
import tempfile
import time

import numpy as np

import avsplat

ROOT = pathlib.Path(__file__).resolve().parents[2]
PEER = ROOT / "build-node" / "node_modules" / ".bin" / "splat-transform"


def best_of_3(fn):
    times = []
    for _ in range(3):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def cpu_model():
    for line in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines():
        if line.startswith("Model name:"):
            return line.split(":", 1)[1].strip()
    return "unknown CPU"


def main():
    print(f"{cpu_model()}, {os.cpu_count()} cores; load average {os.getloadavg()[0]:.1f} "
          f"(a shared machine: timings are indicative)")
    pred = avsplat.simulate_predictions(views=32, width=192, height=144, seed=0)
    cloud = avsplat.fuse_gaussians(pred.gaussians(), 0.02, policy="occupancy").cloud
    n = len(cloud)
    cams = pred.target_cameras
    before = [avsplat.render(cloud, c).color for c in cams]
    truth = [avsplat.ground_truth(c).color for c in cams]
    print(f"embedded scene: {n} Gaussians, SH degree {cloud.sh_degree}; PSNR of the cloud against the "
          f"ground truth {np.mean([avsplat.psnr(b, t) for b, t in zip(before, truth)]):.2f} dB")
    work = pathlib.Path(tempfile.mkdtemp())
    ply = work / "scene.ply"
    avsplat.write_ply(ply, cloud)
    print(f"{'file':34s} {'bytes/Gaussian':>14s} {'PSNR vs before':>15s} {'(min)':>7s} {'PSNR vs truth':>14s}")
    print(f"{'3DGS PLY (float32)':34s} {os.path.getsize(ply) / n:14.2f}")

    def report(label, path, back):
        after = [avsplat.render(back, c).color for c in cams]
        vs_before = [avsplat.psnr(a, b) for a, b in zip(after, before)]
        vs_truth = [avsplat.psnr(a, t) for a, t in zip(after, truth)]
        print(f"{label:34s} {os.path.getsize(path) / n:14.2f} {np.mean(vs_before):15.2f} "
              f"{np.min(vs_before):7.2f} {np.mean(vs_truth):14.2f}")

    timings = []
    for version in (4, 3):
        path = work / f"ours_v{version}.spz"
        t_write, _ = best_of_3(lambda: avsplat.write_spz(path, cloud, version=version))
        t_read, back = best_of_3(lambda: avsplat.read_spz(path))
        report(f"avsplat write_spz v{version}", path, back)
        timings.append((f"avsplat v{version}: write_spz / read_spz", t_write, t_read))
    if PEER.exists():
        for version in (4, 3):
            path = work / f"theirs_v{version}.spz"
            cmd = [str(PEER), "-q", "-w", "-g", "cpu", "--spz-version", str(version), str(ply), str(path)]
            t_write, _ = best_of_3(lambda: subprocess.run(cmd, check=True))
            t_read, _ = best_of_3(lambda: subprocess.run(
                [str(PEER), "-q", "-w", "-g", "cpu", str(path), str(work / "back.ply")], check=True))
            # splat-transform stores PLY's axes (RDF) without conversion.
            report(f"splat-transform 3.7 v{version}", path, avsplat.read_spz(path, coordinate_system="rdf"))
            timings.append((f"splat-transform v{version}: ply->spz / spz->ply", t_write, t_read))
    else:
        print("splat-transform not installed (bash scripts/splat_transform.sh): peer rows skipped")
    print(f"\ntimes for {n} Gaussians, best of 3 (load average now {os.getloadavg()[0]:.1f}):")
    for label, w, r in timings:
        print(f"  {label:48s} {w * 1e3:8.1f} ms / {r * 1e3:8.1f} ms")


if __name__ == "__main__":
    main()
