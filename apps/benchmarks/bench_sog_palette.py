"""The SOG writer's SH palette: the grouped search (default above 3e10 multiply-adds per pass)
against the exhaustive one (`exact_palette=True`), measured in the same run (not a test).

Scenes: `trained_like_cloud(n, seed=2)` of the reduction report (SH degree 3, bands with
magnitudes 0.15 / 0.08 / 0.04 drawn independently per Gaussian: noise-like, the hard case for any
palette search). For each n and search: wall time of `write_sog` (default palette size and 10
iterations) and the SH-rest error of the file: the mean over Gaussians of the squared distance
between the decoded and the original 45 SH-rest coefficients (palette and its 256 levels
together). Decoded Gaussians are matched to the originals by their means (SOG stores Morton
order; positions are 16-bit, so the nearest original mean is the Gaussian's own but for a few
pairs of originals closer than that).

Usage: PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/bench_sog_palette.py
       [--n 50000 300000] [--exact-up-to 300000]   (exhaustive only up to that n: 8 min at 300k)
"""
import argparse
import json
import os
import subprocess
import tempfile
import time
import zipfile

import numpy as np

import avsplat
from avsplat.eval.reduction import trained_like_cloud


def machine():
    model = next((l.split(":", 1)[1].strip() for l in subprocess.run(
        ["lscpu"], capture_output=True, text=True).stdout.splitlines() if l.startswith("Model name")), "?")
    return f"{model}, {os.cpu_count()} cores, OMP threads {os.environ.get('OMP_NUM_THREADS', 'all')}, " \
           f"load average {os.getloadavg()[0]:.1f}"


def match(original: np.ndarray, decoded: np.ndarray, window: int = 64) -> np.ndarray:
    """Index of the original mean nearest to each decoded one, among the `window` nearest in x."""
    order = np.argsort(original[:, 0], kind="stable")
    xs = original[order, 0]
    at = np.searchsorted(xs, decoded[:, 0])
    start = np.clip(at - window // 2, 0, max(len(xs) - window, 0))
    cand = order[np.minimum(start[:, None] + np.arange(window)[None, :], len(xs) - 1)]
    d2 = ((original[cand] - decoded[:, None, :].astype(np.float64)) ** 2).sum(-1)
    m = cand[np.arange(len(decoded)), d2.argmin(1)]
    # Originals closer than the position quantisation (1e-4) are ambiguous: a few pairs in
    # 300,000 (8 on the large scene), which move the error by less than the digits printed.
    if len(original) - len(np.unique(m)) > len(original) // 1000:
        raise RuntimeError("decoded Gaussians do not match the originals one to one")
    return m


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, nargs="+", default=[50000, 300000])
    ap.add_argument("--exact-up-to", type=int, default=300000)
    args = ap.parse_args()
    print(f"machine: {machine()}\n")
    print("| Gaussians | palette | search | write s | SH-rest error / Gaussian | default / exhaustive error |")
    print("|---|---|---|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.n:
            cloud = trained_like_cloud(n, seed=2)
            errors = {}
            for exact in ([False, True] if n <= args.exact_up_to else [False]):
                path = os.path.join(tmp, "p.sog")
                t = time.perf_counter()
                avsplat.write_sog(path, cloud, exact_palette=exact)
                seconds = time.perf_counter() - t
                decoded = avsplat.read_sog(path)
                m = match(cloud.means, decoded.means)
                err = float(((decoded.sh[:, 1:].astype(np.float64) - cloud.sh[m, 1:]) ** 2).sum()) / n
                errors[exact] = err
                with zipfile.ZipFile(path) as z:
                    palette = json.loads(z.read("meta.json"))["shN"]["count"]
                search = "exhaustive" if exact else ("grouped" if n * palette * 45 > 3e10 else "exhaustive (default)")
                ratio = f"{errors[False] / err:.4f}" if exact else ""
                print(f"| {n:,} | {palette:,} | {search} | {seconds:.1f} | {err:.5f} | {ratio} |", flush=True)


if __name__ == "__main__":
    main()
