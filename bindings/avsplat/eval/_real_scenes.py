"""Real trained scenes for the reports: where they are, how to read them, and a scene of any size
made from one (subsampled or tiled)."""

from __future__ import annotations

import os
import subprocess
from typing import TYPE_CHECKING

import numpy as np

import avsplat

if TYPE_CHECKING:
    from ..core import GaussianCloud

# Report name -> file or folder in the real-scene folder (its SOURCES.md says where each is from).
REAL_SCENES: dict[str, str] = {
    "guitar": "guitar.compressed.ply",
    "biker": "biker.compressed.ply",
    "logo": "playcanvas-logo-sogv1",
}


def real_data_dir() -> str | None:
    """The folder of real scenes: $AVSPLAT_REAL_DATA, else ``../shared/data/real`` from the root of
    the repository this package was built from (or from the working directory and its parents);
    None when there is none (reports then leave the real scenes out)."""
    env = os.environ.get("AVSPLAT_REAL_DATA")
    if env:
        return env if os.path.isdir(env) else None
    here = os.path.dirname(os.path.abspath(__file__))
    for start in (here, os.getcwd()):
        d = start
        for _ in range(8):
            cand = os.path.join(d, "..", "shared", "data", "real")
            if os.path.isdir(cand):
                return os.path.normpath(cand)
            d = os.path.dirname(d)
    return None


def read_real_scene(path: str, splat_transform: str | None, tmp: str) -> GaussianCloud:
    """Reads the scene at `path` with avsplat.read_gaussians; a file or folder it cannot read
    (a SOG version 1 folder, before avsplat reads that format) is converted to a PLY in `tmp` by
    splat-transform first. Raises ValueError naming the path when neither can read it."""
    try:
        return avsplat.read_gaussians(path)
    except (ValueError, OSError, RuntimeError) as err:
        first = err
    src = os.path.join(path, "meta.json") if os.path.isdir(path) else path
    if splat_transform is None or not os.path.exists(src):
        raise ValueError(f"{path}: avsplat cannot read it ({first}) and splat-transform is not installed")
    dst = os.path.join(tmp, os.path.basename(os.path.normpath(path)) + ".converted.ply")
    done = subprocess.run([splat_transform, "-q", "-w", src, dst], capture_output=True, text=True, timeout=600)
    if done.returncode != 0:
        raise ValueError(f"{path}: avsplat cannot read it ({first}); splat-transform failed: "
                         f"{(done.stderr or done.stdout).strip()[-300:]}")
    return avsplat.read_gaussians(dst)


def resize_scene(cloud: GaussianCloud, count: int, seed: int = 0) -> GaussianCloud:
    """A scene of exactly `count` Gaussians made from `cloud`: a random subset (fixed seed) when
    count <= len(cloud); else ceil(count / N) copies of it side by side on a square grid in the
    horizontal (x, z) plane (avsplat's axes are y-down), each shifted by 1.1 times the scene's
    robust extent (2nd-98th percentile of the means) on each axis, of which a random subset of
    `count` is kept. Rows keep the order of the copies (the subset is sorted)."""
    n = len(cloud)
    if count < 1:
        raise ValueError(f"resize_scene: count must be >= 1, got {count}")
    rng = np.random.default_rng(seed)
    if count <= n:
        return cloud.select(np.sort(rng.choice(n, size=count, replace=False)))
    copies = -(-count // n)
    side = int(np.ceil(np.sqrt(copies)))
    means = np.asarray(cloud.means, dtype=np.float64)
    lo, hi = np.percentile(means, 2, axis=0), np.percentile(means, 98, axis=0)
    step = 1.1 * (hi - lo)
    tiles = []
    for c in range(copies):
        t = cloud.copy()
        shift = np.array([(c % side) * step[0], 0.0, (c // side) * step[2]], dtype=np.float32)
        t.means = np.asarray(t.means) + shift
        tiles.append(t)
    big = avsplat.concatenate(tiles)
    return big.select(np.sort(rng.choice(len(big), size=count, replace=False)))
