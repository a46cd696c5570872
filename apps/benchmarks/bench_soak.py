"""Soak benchmark through the Python bindings (not a test): the loop of bench_soak.cpp, fuse and
render many times in one process, plus what only the bindings do (numpy arrays in and out, views
of results kept and dropped, exceptions raised and caught). Prints resident memory (VmRSS) and open
file descriptors after a warm-up and every 10% of the calls, the least-squares growth per call,
the CPU model, cores, threads and load average.

    PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_soak.py [--calls 10000]
"""

import argparse
import os
import tempfile
import time

import numpy as np

import avsplat


def rss_kib():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    return -1


def open_fds():
    return len(os.listdir("/proc/self/fd")) - 1  # the listing's own descriptor


def cpu_model():
    with open("/proc/cpuinfo") as f:
        for line in f:
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    return "unknown"


def load_average():
    with open("/proc/loadavg") as f:
        return " ".join(f.read().split()[:3])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--calls", type=int, default=10000)
    ap.add_argument("--views", type=int, default=4)
    ap.add_argument("--width", type=int, default=48)
    ap.add_argument("--height", type=int, default=36)
    ap.add_argument("--io-every", type=int, default=10)
    a = ap.parse_args()

    pred = avsplat.simulate_predictions(views=a.views, width=a.width, height=a.height, seed=0, target_views=1)
    samples = pred.gaussians()
    camera = pred.target_cameras[0]
    # The same samples as plain numpy arrays, rebuilt into a cloud every call (the binding's
    # array conversion path).
    arrays = dict(means=np.array(samples.means), scales=np.array(samples.scales),
                  rotations=np.array(samples.rotations), opacities=np.array(samples.opacities),
                  sh=np.array(samples.sh), confidence=np.array(samples.confidence))
    bad_scales = arrays["scales"].copy()
    bad_scales[0, 0] = np.nan
    work = tempfile.mkdtemp(prefix="avsplat_soak_")
    ply = os.path.join(work, "fused.ply")

    print(f"bench_soak.py: {a.calls} calls of GaussianCloud(numpy) + fuse_gaussians + render "
          f"({len(samples)} samples, {camera.width} x {camera.height} image), I/O every {a.io_every}")
    print(f"CPU: {cpu_model()}; {os.cpu_count()} cores; OMP_NUM_THREADS={os.environ.get('OMP_NUM_THREADS', 'unset')}; "
          f"load average before: {load_average()}")
    warm, step = max(50, a.calls // 100), max(1, a.calls // 10)
    at, rss, fds = [], [], []
    kept = None
    t0 = time.perf_counter()
    print(f"{'call':>10} {'VmRSS KiB':>12} {'open fds':>10} {'s':>10}")
    for call in range(1, a.calls + 1):
        cloud = avsplat.GaussianCloud(arrays["means"], arrays["scales"], arrays["rotations"], arrays["opacities"],
                                      arrays["sh"], confidence=arrays["confidence"])
        fused = avsplat.fuse_gaussians(cloud, 0.02, policy="occupancy")
        image = avsplat.render(fused.cloud, camera)
        color = image.color  # a view that outlives the result object for one iteration
        kept = (color, fused.temperature)
        try:
            avsplat.GaussianCloud(arrays["means"], bad_scales, arrays["rotations"], arrays["opacities"],
                                  arrays["sh"]).validate()
        except ValueError:
            pass
        if call % a.io_every == 0:
            avsplat.write_ply(ply, fused.cloud)
            avsplat.read_ply(ply)
        if call == warm or (call > warm and (call - warm) % step == 0) or call == a.calls:
            at.append(call)
            rss.append(rss_kib())
            fds.append(open_fds())
            print(f"{call:>10} {rss[-1]:>12} {fds[-1]:>10} {time.perf_counter() - t0:>10.1f}", flush=True)
    seconds = time.perf_counter() - t0
    del kept
    if os.path.exists(ply):
        os.remove(ply)
    os.rmdir(work)
    growth = np.polyfit(np.array(at, float), np.array(rss, float), 1)[0] * 1024 if len(at) > 1 else 0.0
    print(f"time: {1e3 * seconds / a.calls:.2f} ms per call ({seconds:.1f} s in all)")
    print(f"VmRSS after warm-up (call {warm}): {rss[0]} KiB; at the end: {rss[-1]} KiB; growth {rss[-1] - rss[0]} KiB")
    print(f"RSS growth per call (least-squares slope after warm-up): {growth:.2f} bytes")
    print(f"open file descriptors: {fds[0]} after warm-up, {fds[-1]} at the end")
    print(f"load average after: {load_average()}")


if __name__ == "__main__":
    main()
