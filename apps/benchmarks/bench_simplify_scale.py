"""simplify(method="merge") against splat-transform 3.7.0's `-d` (`-g cpu`) on trained-like clouds
larger than the reduction report's (50-80k): whether the speed-up holds with the scene's size.
Ours: the best of `--repeats` calls (wall time, OpenMP's threads). The peer: the best of as many
runs of the whole process, and "net" minus a plain `splat-transform IN.ply OUT.ply` copy in the
same run (its start-up, read and write), as in the report. Quality is not measured here (the report does).
Usage: OMP_WAIT_POLICY=passive PYTHONPATH=build/python /usr/bin/python3 \\
           apps/benchmarks/bench_simplify_scale.py [--n 300000 ...] [--ratios 0.5 0.0625]
"""
import argparse
import os
import tempfile
import time

import avsplat
from avsplat.eval._report import machine
from avsplat.eval.reduction import _run_peer_best, splat_transform_executable, trained_like_cloud


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, nargs="+", default=[300_000])
    ap.add_argument("--ratios", type=float, nargs="+", default=[1 / 2, 1 / 16])
    ap.add_argument("--repeats", type=int, default=2)
    args = ap.parse_args()
    exe = splat_transform_executable()
    print(machine())
    if not exe:
        print("splat-transform not installed (bash scripts/splat_transform.sh): ours only")
    print(f"{'n':>9s} {'kept':>5s} {'ours s':>8s} {'-d s':>8s} {'-d net s':>9s} {'net ratio':>10s} {'whole ratio':>12s}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.n:
            cloud = trained_like_cloud(n, seed=2)
            src, dst = os.path.join(tmp, "in.ply"), os.path.join(tmp, "out.ply")
            copy = None
            if exe:
                avsplat.write_ply(src, cloud)
                copy = _run_peer_best([exe, "-q", "-w", "-g", "cpu", src, dst], max(2, args.repeats))[0]
            for ratio in args.ratios:
                target = max(1, round(ratio * n))
                ours = float("inf")
                for _ in range(max(1, args.repeats)):
                    t0 = time.perf_counter()
                    avsplat.simplify(cloud, target_count=target, method="merge")
                    ours = min(ours, time.perf_counter() - t0)
                if exe:
                    whole = _run_peer_best([exe, "-q", "-w", "-g", "cpu", src, "-d", str(target), dst], args.repeats)[0]
                    net = max(whole - copy, 0.0)
                    print(f"{n:9d} 1/{round(1 / ratio):<3d} {ours:8.3f} {whole:8.2f} {net:9.2f} "
                          f"{net / ours:9.1f}x {whole / ours:11.1f}x", flush=True)
                else:
                    print(f"{n:9d} 1/{round(1 / ratio):<3d} {ours:8.3f}", flush=True)
            if copy is not None:
                print(f"{'':9s} peer copy run (start-up, read, write): {copy:.2f} s")
    print(f"load average after the run: {os.getloadavg()[0]:.1f} (shared machine)")


if __name__ == "__main__":
    main()
