"""The public API as a typed user script: pytest runs it, and scripts/stubs.sh has mypy check it
against the package's stubs (bindings/avsplat/_avsplat.pyi), so a stub that disagrees with how
the API is called fails one or the other."""
from __future__ import annotations

import pathlib

import numpy as np
import numpy.typing as npt

import avsplat
import avsplat.fusion
import avsplat.io
import avsplat.metrics
import avsplat.reduce
import avsplat.render
import avsplat.sim


def test_typed_workflow(tmp_path: pathlib.Path) -> None:
    pred: avsplat.sim.Predictions = avsplat.sim.simulate_predictions(views=8, width=48, height=36, seed=1)
    samples: avsplat.GaussianCloud = pred.gaussians()
    fused: avsplat.fusion.GaussianFusionResult = avsplat.fusion.fuse_gaussians(samples, 0.05, policy="mean",
                                                                              trim_mass=None)
    cloud = fused.cloud
    half: avsplat.GaussianCloud = cloud[: len(cloud) // 2]
    camera: avsplat.Camera = pred.target_cameras[0]
    image: avsplat.render.RenderResult = avsplat.render.render(cloud, camera)
    color: npt.NDArray[np.float32] = image.color
    truth = avsplat.sim.ground_truth(camera)
    score: float = avsplat.metrics.psnr(color, truth.color)
    assert 5.0 < score < 60.0
    path = tmp_path / "fused.ply"
    avsplat.io.write_ply(path, cloud)
    back: avsplat.GaussianCloud = avsplat.io.read_gaussians(str(path))
    assert len(back) == len(cloud) and len(half) == len(cloud) // 2
    reduced = avsplat.reduce.simplify(cloud, ratio=0.5)
    assert len(reduced.cloud) == round(len(cloud) * 0.5)
    knobs: list[dict[str, object]] = avsplat.fusion.fusion_knobs()
    assert knobs[0]["name"] == "policy"
    try:
        avsplat.io.read_ply(tmp_path / "missing.ply")
    except avsplat.FileError as error:
        assert "missing.ply" in str(error)
    else:
        raise AssertionError("no FileError")
