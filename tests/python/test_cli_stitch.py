"""`avsplat stitch`: chunk .npz files written by numpy, stitched by the CLI, compared with
avsplat.stitch on the same files (through the same PLY encoding); errors are one line naming the
chunk."""

import json
import os
import subprocess

import numpy as np
import pytest

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")

pytestmark = pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")


def run(*args):
    return subprocess.run([BIN, *map(str, args)], capture_output=True, text=True, timeout=120)


@pytest.fixture(scope="module")
def chunk_files(tmp_path_factory):
    folder = tmp_path_factory.mktemp("chunks")
    capture = avsplat.simulate_chunked_capture(frames=26, window=10, overlap=4, width=32, height=24, seed=2)
    paths = []
    for i, c in enumerate(capture.chunks):
        p = c.predictions
        path = folder / f"chunk{i}.npz"
        np.savez(path, points=p.points, colors=p.colors, valid=p.valid, confidence=p.confidence,
                 frame_ids=c.frame_ids)
        paths.append(path)
    return folder, paths


def test_stitch_writes_the_scene_and_the_transforms_as_the_python_api_does(chunk_files):
    folder, paths = chunk_files
    out = folder / "scene.ply"
    p = run("stitch", *paths, "-o", out, "--voxel", 0.05)
    assert p.returncode == 0, p.stderr
    chunks = [avsplat.read_prediction_chunk(x) for x in paths]
    ref = avsplat.stitch(chunks, 0.05)
    got = avsplat.read_ply(out)
    assert len(got) == len(ref.cloud)
    np.testing.assert_array_equal(got.means, ref.cloud.means)
    info = json.loads((folder / "scene.transforms.json").read_text())
    assert len(info["chunks"]) == len(paths)
    for c, t in zip(info["chunks"], ref.alignment.transforms):
        np.testing.assert_allclose(c["rotation"], t.rotation, atol=1e-12)
        assert c["scale"] == pytest.approx(t.scale, rel=1e-12)
    assert [(q["a"], q["b"]) for q in info["pairs"]] == [(q.a, q.b) for q in ref.alignment.pairs]
    # Streamed through a FusionStream: the same scene.
    out2 = folder / "streamed.ply"
    p = run("stitch", *paths, "-o", out2, "--voxel", 0.05, "--memory-limit", "1M")
    assert p.returncode == 0, p.stderr
    np.testing.assert_array_equal(avsplat.read_ply(out2).means, got.means)


def test_stitch_errors_name_the_chunk(chunk_files):
    folder, paths = chunk_files
    p = run("stitch", paths[0], paths[2], "-o", folder / "x.ply", "--voxel", 0.05)
    assert p.returncode == 3 and len(p.stderr.strip().splitlines()) == 1
    assert f"chunk 1 ('{paths[2]}') shares no frames" in p.stderr
    bad = folder / "bad.npz"
    np.savez(bad, points=np.zeros((2, 4, 4, 3), np.float32))
    p = run("stitch", paths[0], bad, "-o", folder / "x.ply", "--voxel", 0.05)
    assert p.returncode == 3 and "frame_ids" in p.stderr and str(bad) in p.stderr
    p = run("stitch", paths[0], "-o", folder / "x.ply", "--voxel", 0.05)
    assert p.returncode == 3 and "at least two chunks" in p.stderr
