#!/usr/bin/env python3
"""Makes the README's picture, docs/images/demo_fused_vs_truth.png, with the library itself.

    PYTHONPATH=build/python /usr/bin/python3 scripts/readme_figure.py [DEMO_DIR]

Runs `build/apps/avsplat demo -o DEMO_DIR` (default settings: 32 views of 192 x 144, occupancy
fusion at voxel 0.02) unless DEMO_DIR already holds its output, then puts the four held-out
renders of the occupancy-fused scene (top row) over their ray-cast ground truth (bottom row),
with a 4-pixel white border, and writes the PNG with avsplat.write_color_png.
"""
import os
import subprocess
import sys
import tempfile

import matplotlib.image
import numpy as np

import avsplat

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
OUT = os.path.join(ROOT, "docs", "images", "demo_fused_vs_truth.png")
GAP = 4


def main():
    demo = sys.argv[1] if len(sys.argv) > 1 else tempfile.mkdtemp(prefix="avsplat-demo-")
    if not os.path.exists(os.path.join(demo, "summary.json")):
        subprocess.run([os.path.join(ROOT, "build", "apps", "avsplat"), "demo", "-o", demo], check=True)
    rows = []
    for kind in ("occupancy", "truth"):
        tiles = [matplotlib.image.imread(os.path.join(demo, f"target{t}_{kind}.png"))[..., :3] for t in range(4)]
        h = tiles[0].shape[0]
        gap = np.ones((h, GAP, 3), np.float32)
        row = [gap]
        for tile in tiles:
            row += [tile.astype(np.float32), gap]
        rows.append(np.concatenate(row, axis=1))
    w = rows[0].shape[1]
    band = np.ones((GAP, w, 3), np.float32)
    image = np.concatenate([band, rows[0], band, rows[1], band], axis=0)
    avsplat.write_color_png(OUT, np.ascontiguousarray(image))
    print("wrote", OUT, image.shape)


if __name__ == "__main__":
    main()
