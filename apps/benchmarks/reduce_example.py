"""prune and reduce_sh on the embedded scene: counts, bytes saved and the largest pixel change.

    PYTHONPATH=build/python /usr/bin/python3 apps/benchmarks/reduce_example.py

The scene is the README demo's: 32 simulated views (192 x 144) of the embedded scene, fused with
`occupancy` at voxel 0.02. prune is given the 4 held-out target cameras, and its result is
rendered from them (where the guarantee holds) and from the 32 input cameras (where it does
not). The fused scene has SH degree 0, so for reduce_sh it is given degree-3 bands of Gaussian
noise (standard deviation 0.0005 per coefficient, as a model whose higher bands carry nothing);
reduce_sh with max_error 1/255 then chooses the degree. Bytes are 3DGS PLY file sizes.
"""
import os
import tempfile

import numpy as np

import avsplat


def max_change(a, b, cameras):
    return max(float(np.abs(avsplat.render(a, c).color - avsplat.render(b, c).color).max()) for c in cameras)


def ply_bytes(cloud, folder, name):
    path = os.path.join(folder, name)
    avsplat.write_ply(path, cloud)
    return os.path.getsize(path)


def main():
    pred = avsplat.simulate_predictions(views=32, width=192, height=144, seed=0)
    fused = avsplat.fuse_gaussians(pred.gaussians(), 0.02, policy="occupancy").cloud
    targets, inputs = list(pred.target_cameras), list(pred.cameras)
    with tempfile.TemporaryDirectory() as tmp:
        print(f"fused: {len(fused)} Gaussians, {ply_bytes(fused, tmp, 'fused.ply')} bytes (PLY)")
        for min_contribution in (None, 1 / 255):
            r = avsplat.prune(fused, targets, min_contribution=min_contribution)
            print(f"prune(min_contribution={min_contribution}): {r.summary()}; "
                  f"{ply_bytes(r.cloud, tmp, 'pruned.ply')} bytes; max pixel change "
                  f"{max_change(fused, r.cloud, targets):.3g} at the 4 target cameras, "
                  f"{max_change(fused, r.cloud, inputs):.3g} at the 32 input cameras")
        rng = np.random.default_rng(0)
        sh = np.zeros((len(fused), 16, 3), np.float32)
        sh[:, 0] = np.asarray(fused.sh)[:, 0]
        sh[:, 1:] = rng.normal(0.0, 0.0005, (len(fused), 15, 3))
        deg3 = avsplat.GaussianCloud(fused.means, fused.scales, fused.rotations, fused.opacities, sh)
        r = avsplat.reduce_sh(deg3)
        print(f"reduce_sh(1/255): {r.summary()}; PLY {ply_bytes(deg3, tmp, 'deg3.ply')} -> "
              f"{ply_bytes(r.cloud, tmp, 'reduced.ply')} bytes; max pixel change "
              f"{max_change(deg3, r.cloud, targets + inputs):.3g} at all 36 cameras")


if __name__ == "__main__":
    main()
