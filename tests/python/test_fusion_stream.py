"""FusionStream against the in-memory operators: bit-identical on randomly chunked input.

Each test fuses the same samples with fuse_voxels / fuse_gaussians (the reference) and through a
FusionStream fed in random chunks under a memory_limit small enough that the input is spilled
to many block files and blocks are split again in finish(); every output array (diagnostics and
sample_voxel included) must be equal, not close.
"""
import os

import numpy as np
import pytest

import avsplat

FIELDS = ("positions", "voxel_coords", "sample_voxel", "occupancy", "temperature", "variance", "reliability",
          "kept", "entropy")


def scene(n=6000, c=5, seed=0):
    """A dense object (most samples, many per voxel) in a sparse background, in random order."""
    rng = np.random.default_rng(seed)
    dense = rng.normal(0, 0.15, size=(n * 3 // 4, 3))
    sparse = rng.uniform(-4, 4, size=(n - len(dense), 3))
    p = np.concatenate([dense, sparse]).astype(np.float32)
    p = p[rng.permutation(n)]
    # A few samples exactly on voxel boundaries (x = (k + 0.5) * voxel) straddle the rounding.
    p[:50, 0] = (np.arange(50) - 25 + 0.5).astype(np.float32) * np.float32(0.1)
    f = rng.normal(size=(n, c)).astype(np.float32)
    conf = rng.normal(0, 2, size=n).astype(np.float32)
    return p, f, conf


def random_chunks(n, rng, parts=23):
    cuts = np.sort(rng.choice(np.arange(1, n), size=parts - 1, replace=False))
    return np.split(np.arange(n), cuts)


def assert_identical(got, ref, extra=()):
    assert len(got) == len(ref)
    for name in FIELDS + tuple(extra):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    assert got.dropped == ref.dropped


@pytest.mark.parametrize("policy,knobs", [
    ("mean", {}),
    ("softmax", {}),
    ("occupancy", {}),
    ("occupancy", {"weights": "sparsemax", "trim_mass": 0.5}),
    ("occupancy", {"precision": "float64", "confidence_mapping": "positive"}),
])
def test_stream_features_identical_to_fuse_voxels(policy, knobs, tmp_path):
    p, f, conf = scene(seed=1)
    if knobs.get("confidence_mapping") == "positive":
        conf = np.abs(conf) + 0.1
    ref = avsplat.fuse_voxels(p, f, 0.1, conf, policy=policy, **knobs)
    rng = np.random.default_rng(2)
    stream = avsplat.FusionStream(0.1, policy=policy, memory_limit=64 << 10, work_dir=tmp_path, **knobs)
    for rows in random_chunks(len(p), rng):
        stream.add(p[rows], f[rows], conf[rows])
    assert stream.num_samples == len(p)
    assert stream.num_blocks > 8 and stream.spilled_bytes > p.nbytes  # it really spilled
    assert os.path.isdir(stream.work_folder)
    folder = stream.work_folder
    got = stream.finish()
    assert_identical(got, ref, ("features",))
    assert not os.path.exists(folder) and list(tmp_path.iterdir()) == []


def test_stream_without_confidence_and_in_memory_path():
    p, f, _ = scene(n=3000, c=0, seed=3)
    ref = avsplat.fuse_voxels(p, f, 0.2)
    for limit in (None, 16 << 10):  # None: 1 GiB, nothing spilled
        stream = avsplat.FusionStream(0.2, memory_limit=limit)
        for rows in random_chunks(len(p), np.random.default_rng(4), parts=5):
            stream.add(p[rows], f[rows])
        assert (stream.num_blocks == 0) == (limit is None)
        assert_identical(stream.finish(), ref, ("features",))


def test_blocks_that_grow_after_the_first_spill_are_split_again():
    # Sorted by x, the first spill sees only the lowest slabs, so its last block receives all
    # the rest and finish() must split it (by its own key quantiles) to respect the limit.
    p, f, conf = scene(n=5000, seed=11)
    order = np.argsort(p[:, 0], kind="stable")
    p, f, conf = p[order], f[order], conf[order]
    ref = avsplat.fuse_voxels(p, f, 0.1, conf)
    stream = avsplat.FusionStream(0.1, memory_limit=48 << 10)
    for rows in np.array_split(np.arange(len(p)), 50):
        stream.add(p[rows], f[rows], conf[rows])
    before = stream.num_blocks
    assert_identical(stream.finish(), ref, ("features",))
    assert stream.num_blocks > before


def test_stream_drops_invalid_samples_with_global_indices():
    p, f, conf = scene(n=4000, seed=5)
    p[[7, 3001], 1] = np.nan
    f[[11, 2500], 2] = np.inf
    conf[1999] = np.nan
    ref = avsplat.fuse_voxels(p, f, 0.1, conf, on_invalid="drop")
    assert ref.dropped == 5
    stream = avsplat.FusionStream(0.1, memory_limit=32 << 10, on_invalid="drop")
    for rows in random_chunks(len(p), np.random.default_rng(6), parts=9):
        stream.add(p[rows], f[rows], conf[rows])
    assert_identical(stream.finish(), ref, ("features",))


def test_stream_errors_name_field_and_global_index(tmp_path):
    p, f, conf = scene(n=2000, seed=7)
    stream = avsplat.FusionStream(0.1, memory_limit=16 << 10, work_dir=tmp_path)
    stream.add(p[:1000], f[:1000], conf[:1000])
    bad = p[1000:].copy()
    bad[234, 2] = np.nan
    with pytest.raises(ValueError, match=r"positions\[1234, 2\]"):
        stream.add(bad, f[1000:], conf[1000:])
    with pytest.raises(ValueError, match="channels"):
        stream.add(p[:10], f[:10, :2], conf[:10])
    with pytest.raises(ValueError, match="confidence"):
        stream.add(p[:10], f[:10])
    with pytest.raises(ValueError, match="Gaussians|features"):
        stream.add_gaussians(gaussian_scene(n=100))

    # A bad feature is found in finish(), named by its global index; the work folder goes.
    stream = avsplat.FusionStream(0.1, memory_limit=16 << 10, work_dir=tmp_path)
    f2 = f.copy()
    f2[1500, 3] = np.nan
    for rows in random_chunks(len(p), np.random.default_rng(8), parts=6):
        stream.add(p[rows], f2[rows], conf[rows])
    assert stream.num_blocks > 0
    with pytest.raises(ValueError, match=r"features\[1500, 3\]"):
        stream.finish()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(RuntimeError):
        stream.finish()
    with pytest.raises(ValueError, match="voxel_size"):
        avsplat.FusionStream(0.0)
    with pytest.raises(TypeError, match="'wrong'"):
        avsplat.FusionStream(0.1, wrong=1)
    with pytest.raises(OSError, match="no-such-folder"):
        avsplat.FusionStream(0.1, work_dir=tmp_path / "no-such-folder")


def gaussian_scene(n=4000, seed=9):
    rng = np.random.default_rng(seed)
    p, _, conf = scene(n=n, c=1, seed=seed)
    cloud = avsplat.GaussianCloud(
        means=p, scales=rng.uniform(0.01, 0.1, size=(n, 3)), rotations=rng.normal(size=(n, 4)),
        opacities=rng.uniform(0, 1, size=n), sh=rng.normal(size=(n, 4, 3)), confidence=conf)
    cloud.set_extra("f_extra", rng.normal(size=n).astype(np.float32))
    return cloud


@pytest.mark.parametrize("shape", ["average", "moment"])
@pytest.mark.parametrize("policy", ["mean", "softmax", "occupancy"])
def test_stream_gaussians_identical_to_fuse_gaussians(shape, policy):
    cloud = gaussian_scene()
    ref = avsplat.fuse_gaussians(cloud, 0.1, policy=policy, shape=shape)
    stream = avsplat.FusionStream(0.1, policy=policy, shape=shape, memory_limit=64 << 10)
    for rows in random_chunks(len(cloud), np.random.default_rng(10)):
        stream.add_gaussians(cloud.select(rows))
    assert stream.num_blocks > 8
    got = stream.finish()
    assert isinstance(got, avsplat.GaussianFusionResult)
    assert_identical(got, ref)
    for name in ("means", "scales", "rotations", "opacities", "sh", "confidence"):
        np.testing.assert_array_equal(getattr(got.cloud, name), getattr(ref.cloud, name), err_msg=name)
    np.testing.assert_array_equal(got.cloud.extras["f_extra"], ref.cloud.extras["f_extra"])


def test_empty_streams():
    r = avsplat.FusionStream(0.1).finish()
    assert len(r) == 0 and len(r.sample_voxel) == 0
    g = avsplat.FusionStream(0.1).finish_gaussians()
    assert len(g) == 0 and isinstance(g, avsplat.GaussianFusionResult)
    assert repr(avsplat.FusionStream(0.1)).startswith("FusionStream(samples=0")
