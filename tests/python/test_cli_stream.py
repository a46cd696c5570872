"""`avsplat fuse --memory-limit`: the out-of-core path gives the in-memory result, file for file.

Runs the built binary (as test_cli.py) on small simulated predictions with a memory limit far
below the inputs' size, so that the inputs are streamed into spill files, and compares with the
in-memory run / the Python operator. Also checks that no partial file is left behind.
"""
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


def ok(*args):
    p = run(*args)
    assert p.returncode == 0, f"avsplat {' '.join(map(str, args))} failed:\n{p.stdout}\n{p.stderr}"
    return p


@pytest.fixture(scope="module")
def preds():
    return avsplat.simulate_predictions(views=3, width=32, height=24, target_views=1, seed=5)


def test_streamed_raw_features_equal_fuse_voxels(tmp_path, preds):
    rng = np.random.default_rng(3)
    feats = rng.normal(size=(preds.views, preds.height, preds.width, 5)).astype(np.float32)
    inputs = []
    for s in range(preds.views):  # one file per view, fused as one sample set
        path = tmp_path / f"view{s}.npz"
        np.savez(path, points=preds.points[s:s + 1], confidence=preds.confidence[s:s + 1],
                 valid=preds.valid[s:s + 1], features=feats[s:s + 1])
        inputs.append(path)
    out, diag = tmp_path / "fused.npz", tmp_path / "diag.npz"
    p = ok("fuse", *inputs, "-o", out, "--voxel", "0.02", "--memory-limit", "8K", "--diagnostics", diag)
    assert "spilled" in p.stdout and "fusing out of core" in p.stdout
    v = np.asarray(preds.valid)
    ref = avsplat.fuse_voxels(np.asarray(preds.points)[v], feats[v], 0.02, confidence=np.asarray(preds.confidence)[v])
    got, d = np.load(out), np.load(diag)
    for name in ("positions", "features", "voxel_coords", "occupancy", "temperature", "variance", "reliability",
                 "kept", "entropy"):
        np.testing.assert_array_equal(got[name], np.asarray(getattr(ref, name)), err_msg=name)
    np.testing.assert_array_equal(d["occupancy"], ref.occupancy)
    assert sorted(os.listdir(tmp_path)) == sorted([f"view{s}.npz" for s in range(preds.views)] +
                                                  ["fused.npz", "diag.npz"])


def test_streamed_gaussians_equal_the_in_memory_run(tmp_path, preds):
    rng = np.random.default_rng(4)
    S, H, W = preds.views, preds.height, preds.width
    q = rng.normal(size=(S, H, W, 4))
    npz = tmp_path / "g.npz"
    np.savez(npz, points=np.array(preds.points), confidence=np.array(preds.confidence), valid=np.array(preds.valid),
             scales=rng.uniform(0.005, 0.05, size=(S, H, W, 3)).astype(np.float32),
             rotations=(q / np.linalg.norm(q, axis=-1, keepdims=True)).astype(np.float32),
             opacities=rng.uniform(0.05, 1.0, size=(S, H, W)).astype(np.float32),
             sh=rng.normal(scale=0.5, size=(S, H, W, 4, 3)).astype(np.float32))
    a, b = tmp_path / "memory.ply", tmp_path / "stream.ply"
    p = ok("fuse", npz, "-o", a, "--voxel", "0.03", "--shape", "moment")
    assert "spilled" not in p.stdout
    p = ok("fuse", npz, "-o", b, "--voxel", "0.03", "--shape", "moment", "--memory-limit", "4K")
    assert "spilled" in p.stdout
    assert a.read_bytes() == b.read_bytes()


def test_memory_limit_errors_and_no_partial_output(tmp_path, preds):
    npz = tmp_path / "maps.npz"
    np.savez(npz, points=preds.points, colors=preds.colors, confidence=preds.confidence, valid=preds.valid)
    p = run("fuse", npz, "-o", tmp_path / "x.ply", "--voxel", "0.03", "--memory-limit", "lots")
    assert p.returncode != 0 and "--memory-limit" in p.stderr
    # Gaussians cannot go to .npz: the streamed run fails after fusing and leaves no file.
    p = run("fuse", npz, "-o", tmp_path / "x.npz", "--voxel", "0.03", "--memory-limit", "1K")
    assert p.returncode != 0
    assert sorted(os.listdir(tmp_path)) == ["maps.npz"]


def test_scheduler_fuses_on_a_dask_cluster(tmp_path, preds):
    distributed = pytest.importorskip("distributed")
    import logging
    import sys

    rng = np.random.default_rng(8)
    feats = rng.normal(size=(preds.views, preds.height, preds.width, 3)).astype(np.float32)
    npz = tmp_path / "feats.npz"
    np.savez(npz, points=preds.points, confidence=preds.confidence, valid=preds.valid, features=feats)
    out = tmp_path / "fused.npz"
    env = dict(os.environ, AVSPLAT_PYTHON=sys.executable)
    # Workers in this process, but a TCP scheduler that the tool's Python can reach.
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=":0", silence_logs=logging.ERROR) as cluster:
        p = subprocess.run([BIN, "fuse", str(npz), "-o", str(out), "--voxel", "0.03", "--policy", "softmax",
                            "--trim-mass", "0.7", "--scheduler", cluster.scheduler_address],
                           capture_output=True, text=True, timeout=120, env=env)
    assert p.returncode == 0, p.stdout + p.stderr
    assert cluster.scheduler_address in p.stdout
    v = np.asarray(preds.valid)
    ref = avsplat.fuse_voxels(np.asarray(preds.points)[v], feats[v], 0.03, confidence=np.asarray(preds.confidence)[v],
                              policy="softmax", trim_mass=0.7)
    got = np.load(out)
    for name in ("positions", "features", "voxel_coords", "occupancy", "temperature", "variance", "reliability",
                 "kept", "entropy"):
        np.testing.assert_array_equal(got[name], np.asarray(getattr(ref, name)), err_msg=name)


def test_scheduler_fuses_gaussian_files(tmp_path, preds):
    distributed = pytest.importorskip("distributed")
    import logging
    import sys

    cloud = preds.gaussians()
    n = len(cloud)
    halves = [np.arange(0, n // 2), np.arange(n // 2, n)]
    inputs = []
    for k, rows in enumerate(halves):
        path = tmp_path / f"part{k}.ply"
        avsplat.write_ply(path, cloud.select(rows))
        inputs.append(path)
    whole = avsplat.read_ply(inputs[0])
    rest = avsplat.read_ply(inputs[1])
    ref = avsplat.fuse_gaussians(avsplat.concatenate([whole, rest]), 0.03, policy="occupancy", shape="moment")
    out = tmp_path / "fused.ply"
    env = dict(os.environ, AVSPLAT_PYTHON=sys.executable)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=":0", silence_logs=logging.ERROR) as cluster:
        p = subprocess.run([BIN, "fuse", *map(str, inputs), "-o", str(out), "--voxel", "0.03", "--shape", "moment",
                            "--scheduler", cluster.scheduler_address],
                           capture_output=True, text=True, timeout=180, env=env)
    assert p.returncode == 0, p.stdout + p.stderr
    ref_path = tmp_path / "ref.ply"
    avsplat.write_ply(ref_path, ref.cloud)
    assert out.read_bytes() == ref_path.read_bytes()
    assert sorted(os.listdir(tmp_path)) == ["fused.ply", "part0.ply", "part1.ply", "ref.ply"]


def test_streamed_ply_is_written_block_by_block(tmp_path, preds):
    # The streamed run writes the fused PLY as blocks are fused; the file is the in-memory one.
    cloud = preds.gaussians()
    src = tmp_path / "in.ply"
    avsplat.write_ply(src, cloud)
    a, b = tmp_path / "memory.ply", tmp_path / "stream.ply"
    ok("fuse", src, "-o", a, "--voxel", "0.02")
    p = ok("fuse", src, "-o", b, "--voxel", "0.02", "--memory-limit", "16K")
    assert "block by block" in p.stdout and "fusing blocks" not in p.stdout + p.stderr  # no bar in a pipe
    assert a.read_bytes() == b.read_bytes()
    assert sorted(os.listdir(tmp_path)) == ["in.ply", "memory.ply", "stream.ply"]


def test_the_decoded_size_decides_not_the_size_on_disk(tmp_path, preds):
    # A compressed .npz of constant features is tiny on disk and large decoded: the decoded size
    # is what must fit, so this input is fused out of core.
    feats = np.zeros((preds.views, preds.height, preds.width, 64), np.float32)
    npz = tmp_path / "feats.npz"
    np.savez_compressed(npz, points=preds.points, confidence=preds.confidence, valid=preds.valid, features=feats)
    decoded = feats.nbytes
    assert npz.stat().st_size < decoded // 10
    limit = npz.stat().st_size * 2
    assert limit < decoded
    p = ok("fuse", npz, "-o", tmp_path / "out.npz", "--voxel", "0.03", "--memory-limit", str(limit))
    assert "fusing out of core" in p.stdout and "spilled" in p.stdout
    v = np.asarray(preds.valid)
    ref = avsplat.fuse_voxels(np.asarray(preds.points)[v], feats[v], 0.03, confidence=np.asarray(preds.confidence)[v])
    np.testing.assert_array_equal(np.load(tmp_path / "out.npz")["positions"], ref.positions)
