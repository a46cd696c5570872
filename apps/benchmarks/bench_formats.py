"""What each Gaussian file format keeps: bytes per Gaussian and the image error of a round trip
(write, read back, render) on the embedded default scene, against the render of the cloud in
memory. Formats this build cannot write are listed as such. Quality figures are deterministic.
With --timing N: seconds to write and read a compressed PLY, avsplat against splat-transform.

    PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_formats.py [--views 16] [--voxel 0.01]
    PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_formats.py --timing 1000000
"""

import argparse
import os
import tempfile

import numpy as np

import avsplat

FORMATS = [("3DGS PLY", "scene.ply"), ("compressed PLY", "scene.compressed.ply"), (".splat", "scene.splat"),
           ("SPZ", "scene.spz"), ("SOG", "scene.sog")]


def with_sh3(cloud, seed=0):
    """The scene with view-dependent colour: bands 1..3 filled with small random coefficients,
    so that the formats' SH handling shows in the images."""
    rng = np.random.default_rng(seed)
    sh = np.zeros((len(cloud), 16, 3), np.float32)
    sh[:, 0, :] = cloud.sh[:, 0, :]
    sh[:, 1:, :] = rng.normal(size=(len(cloud), 15, 3)) * 0.15
    return avsplat.GaussianCloud(cloud.means, cloud.scales, cloud.rotations, cloud.opacities, sh)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--views", type=int, default=16)
    ap.add_argument("--voxel", type=float, default=0.01)
    ap.add_argument("--timing", type=int, default=0, metavar="N",
                    help="instead: time compressed PLY writing and reading of N Gaussians against splat-transform")
    args = ap.parse_args()
    if args.timing:
        timing(args.timing, 3)
        return
    pred = avsplat.simulate_predictions(views=args.views, width=160, height=120, seed=0)
    base = avsplat.fuse_gaussians(pred.gaussians(), args.voxel).cloud
    cams = pred.target_cameras
    print(f"embedded scene: {args.views} views 160x120, fused at voxel {args.voxel}: {len(base)} Gaussians; "
          f"{len(cams)} held-out views 160x120")
    print("| scene | format | bytes per Gaussian | max abs colour error | PSNR vs in-memory render (dB) |")
    print("|---|---|---:|---:|---:|")
    for label, cloud in (("SH 0", base), ("SH 3", with_sh3(base))):
        refs = [avsplat.render(cloud, c).color for c in cams]
        with tempfile.TemporaryDirectory() as tmp:
            for name, file in FORMATS:
                path = os.path.join(tmp, file)
                try:
                    avsplat.write_gaussians(path, cloud)
                except OSError as e:
                    if "cannot be written by this build" not in str(e):
                        raise
                    print(f"| {label} | {name} | (not in this build) | | |")
                    continue
                size = os.path.getsize(path) if os.path.isfile(path) else sum(
                    os.path.getsize(os.path.join(path, f)) for f in os.listdir(path))
                back = avsplat.read_gaussians(path)
                err, psnrs = 0.0, []
                for c, ref in zip(cams, refs):
                    img = avsplat.render(back, c).color
                    err = max(err, float(np.abs(img - ref).max()))
                    psnrs.append(avsplat.psnr(img, ref) if err > 0 else float("inf"))
                print(f"| {label} | {name} | {size / len(cloud):.1f} | {err:.2e} | {np.mean(psnrs):.1f} |")


def timing(n, repeats):
    """Seconds to write and read a compressed PLY of n Gaussians (SH 3) with avsplat and with
    splat-transform (node, its CLI: process start included), medians of `repeats`."""
    import platform
    import subprocess
    import time
    exe = subprocess.run(["bash", os.path.join(os.path.dirname(__file__), "..", "..", "scripts", "splat_transform.sh")],
                         capture_output=True, text=True).stdout.strip().splitlines()[-1]
    cpu = [ln.split(":", 1)[1].strip() for ln in subprocess.run(["lscpu"], capture_output=True, text=True).stdout.splitlines()
           if ln.startswith("Model name")]
    print(f"machine: {cpu[0] if cpu else platform.processor()}, {os.cpu_count()} cores, OMP_NUM_THREADS="
          f"{os.environ.get('OMP_NUM_THREADS', 'unset')}, load average {os.getloadavg()[0]:.1f} (shared machine)")
    rng = np.random.default_rng(0)
    cloud = avsplat.GaussianCloud(rng.normal(size=(n, 3)), np.exp(rng.uniform(-6, 0, (n, 3))), rng.normal(size=(n, 4)),
                                  rng.uniform(0, 1, n), rng.normal(size=(n, 16, 3)) * 0.3)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        ply = os.path.join(tmp, "in.ply")
        avsplat.write_ply(ply, cloud)
        ours, st = os.path.join(tmp, "ours.compressed.ply"), os.path.join(tmp, "st.compressed.ply")

        def clock(fn):
            times = []
            for _ in range(repeats):
                t = time.perf_counter()
                fn()
                times.append(time.perf_counter() - t)
            return float(np.median(times))

        rows["write (PLY in memory -> compressed PLY)"] = (
            clock(lambda: avsplat.write_compressed_ply(ours, cloud)), None)
        rows["convert PLY file -> compressed PLY file"] = (
            clock(lambda: avsplat.write_compressed_ply(ours, avsplat.read_ply(ply))),
            clock(lambda: subprocess.run([exe, "-q", "-w", ply, st], check=True)))
        rows["read compressed PLY"] = (
            clock(lambda: avsplat.read_compressed_ply(st)),
            clock(lambda: subprocess.run([exe, "-q", "-w", st, "null"], check=True)))
    print(f"| {n} Gaussians, SH 3 (median of {repeats}) | avsplat s | splat-transform s | ratio |")
    print("|---|---:|---:|---:|")
    for name, (a, b) in rows.items():
        print(f"| {name} | {a:.3f} | {'' if b is None else f'{b:.3f}'} | {'' if b is None else f'{b / a:.1f}x'} |")


if __name__ == "__main__":
    main()
