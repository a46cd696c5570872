"""Executes every notebook in notebooks/ with the Debian Python kernel and checks what it computed.

Each notebook ends by printing one line "AVSPLAT_RESULTS {json}"; the assertions below are on
those numbers, so a notebook that runs but computes nonsense fails.
"""
import json
import os
import pathlib

import nbformat
import pytest
from nbclient import NotebookClient

ROOT = pathlib.Path(__file__).resolve().parents[2]
NOTEBOOKS = sorted((ROOT / "notebooks").glob("*.ipynb"))


def execute(path, workdir):
    import avsplat

    nb = nbformat.read(path, as_version=4)
    for cell in nb.cells:
        if cell.cell_type == "code":
            assert not cell.outputs, f"{path.name} is stored with outputs; clear them"
    # The kernel is a subprocess: it finds the package under test through PYTHONPATH.
    package_root = str(pathlib.Path(avsplat.__file__).resolve().parents[1])
    os.environ["PYTHONPATH"] = os.pathsep.join(filter(None, [package_root, os.environ.get("PYTHONPATH")]))
    os.environ.setdefault("MPLBACKEND", "Agg")
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(workdir)}}).execute()
    for cell in nb.cells:
        for out in cell.get("outputs", []):
            text = out.get("text", "")
            for line in text.splitlines():
                if line.startswith("AVSPLAT_RESULTS "):
                    return json.loads(line[len("AVSPLAT_RESULTS "):])
    raise AssertionError(f"{path.name} printed no AVSPLAT_RESULTS line")


def test_there_are_notebooks():
    assert NOTEBOOKS, "no notebooks found"


@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebook_runs_and_computes_sensible_results(path, tmp_path):
    results = execute(path, tmp_path)
    if path.stem == "fusion_walkthrough":
        assert results["spearman"] > 0.3, "confidence must rank samples by their true error"
        scores = results["scores"]
        assert set(scores) == {"mean", "softmax", "occupancy"}
        # The same voxel grid for every policy: the same number of fused Gaussians.
        assert len({s["gaussians"] for s in scores.values()}) == 1
        for policy, s in scores.items():
            assert 12.0 < s["psnr"] < 60.0, (policy, s)
            assert 0.2 < s["ssim"] <= 1.0, (policy, s)
        assert (tmp_path / "notebook_output" / "fused_occupancy.ply").stat().st_size > 0
