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

    # A bad feature stops the stream at the add() of its chunk, named by its global index;
    # finish() after it still removes the work folder.
    stream = avsplat.FusionStream(0.1, memory_limit=16 << 10, work_dir=tmp_path)
    f2 = f.copy()
    f2[1500, 3] = np.nan
    with pytest.raises(ValueError, match=r"features\[1500, 3\]"):
        for rows in np.array_split(np.arange(len(p)), 6):
            stream.add(p[rows], f2[rows], conf[rows])
    assert stream.num_blocks > 0
    stream.finish()
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(RuntimeError):
        stream.finish()
    with pytest.raises(ValueError, match="voxel_size"):
        avsplat.FusionStream(0.0)
    writer = avsplat.GaussianPlyWriter(tmp_path / "empty.ply")
    writer.commit()
    assert len(avsplat.read_ply(tmp_path / "empty.ply")) == 0 and repr(writer).endswith("size=0)")
    with pytest.raises(RuntimeError):
        writer.commit()
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


def error_of(call):
    with pytest.raises(ValueError) as e:
        call()
    return str(e.value)


@pytest.mark.parametrize("defect", ["confidence", "position_nan", "position_overflow", "feature", "mixed"])
def test_stream_raises_the_operators_error_with_the_global_index(defect):
    # The first chunks are clean, so the in-memory operator on the concatenated input meets the
    # same first error (its checks go category by category: confidence, non-finite positions,
    # keys that overflow, features); the stream must raise exactly its message.
    # (Chunks of 600 samples: every defect below lies in the last chunk, 2400..2999.)
    p, f, conf = scene(n=3000, seed=12)
    if defect in ("confidence", "mixed"):
        conf[2600] = np.nan
    if defect in ("position_nan", "mixed"):
        p[2500, 1] = np.inf
    if defect == "position_overflow":
        p[2500, 2] = 1e30
    if defect in ("feature", "mixed"):
        f[2450, 4] = np.nan
    ref = error_of(lambda: avsplat.fuse_voxels(p, f, 0.1, conf))
    stream = avsplat.FusionStream(0.1, memory_limit=32 << 10)
    got = error_of(lambda: [stream.add(p[r], f[r], conf[r]) for r in np.array_split(np.arange(len(p)), 5)])
    assert got == ref
    assert "[2" in got


def test_stream_raises_at_the_first_chunk_holding_an_invalid_sample():
    # Across chunks the stream stops at the first bad chunk (fail fast: nothing more is spilled),
    # even where the in-memory operator, checking confidence before features, names a later one.
    p, f, conf = scene(n=3000, seed=12)
    f[700, 1] = np.nan
    conf[2600] = np.nan
    stream = avsplat.FusionStream(0.1, memory_limit=32 << 10)
    got = error_of(lambda: [stream.add(p[r], f[r], conf[r]) for r in np.array_split(np.arange(len(p)), 5)])
    assert got.startswith("features[700, 1]")
    assert stream.num_samples == 600
    assert error_of(lambda: avsplat.fuse_voxels(p, f, 0.1, conf)).startswith("confidence[2600]")


@pytest.mark.parametrize("defect", ["scale", "confidence", "overflow"])
def test_stream_gaussians_raise_the_operators_error(defect):
    cloud = gaussian_scene(n=3000, seed=13)
    if defect == "scale":
        cloud.scales[2700, 1] = -1.0
    elif defect == "confidence":
        cloud.confidence[2800] = np.nan
    else:
        cloud.means[2900, 0] = 3e30
    ref = error_of(lambda: avsplat.fuse_gaussians(cloud, 0.1))
    stream = avsplat.FusionStream(0.1, memory_limit=32 << 10)
    got = error_of(lambda: [stream.add_gaussians(cloud.select(r)) for r in np.array_split(np.arange(len(cloud)), 4)])
    assert got == ref


def test_one_dense_slab_is_split_by_the_other_key_components():
    # Every sample in one kx slab: blocks must cut it along ky and kz, and the result is still
    # the in-memory one. (The stream used to cut along kx only and fused such a slab whole.)
    rng = np.random.default_rng(14)
    n = 6000
    p = rng.uniform(-2, 2, size=(n, 3)).astype(np.float32)
    p[:, 0] = 0.01
    f = rng.normal(size=(n, 3)).astype(np.float32)
    conf = rng.normal(size=n).astype(np.float32)
    ref = avsplat.fuse_voxels(p, f, 0.1, conf)
    stream = avsplat.FusionStream(0.1, memory_limit=32 << 10)
    for rows in random_chunks(n, rng, parts=12):
        stream.add(p[rows], f[rows], conf[rows])
    got = stream.finish()
    assert stream.num_blocks > 8
    assert_identical(got, ref, ("features",))


def test_sink_and_ply_writer_give_the_in_memory_file(tmp_path):
    cloud = gaussian_scene(n=5000, seed=21)
    ref = avsplat.fuse_gaussians(cloud, 0.1)
    avsplat.write_ply(tmp_path / "ref.ply", ref.cloud)
    stream = avsplat.FusionStream(0.1, memory_limit=32 << 10)
    for rows in random_chunks(len(cloud), np.random.default_rng(22), parts=7):
        stream.add_gaussians(cloud.select(rows))
    seen = []
    stream.set_progress(lambda done, total: seen.append((done, total)))
    with avsplat.GaussianPlyWriter(tmp_path / "parts.ply") as out:
        summary = stream.finish_gaussians(sink=lambda block: out.append(block.cloud))
    assert len(out) == len(ref.cloud) and len(summary.cloud) == 0
    np.testing.assert_array_equal(summary.sample_voxel, ref.sample_voxel)
    assert (tmp_path / "parts.ply").read_bytes() == (tmp_path / "ref.ply").read_bytes()
    assert seen[0][0] == 0 and seen[-1] == (len(cloud), len(cloud)) and len(seen) > 2
    assert [d for d, _ in seen] == sorted(d for d, _ in seen)


def test_ply_writer_keeps_the_old_file_on_error(tmp_path):
    path = tmp_path / "keep.ply"
    path.write_bytes(b"old")
    cloud = gaussian_scene(n=100, seed=23)
    with pytest.raises(ZeroDivisionError):
        with avsplat.GaussianPlyWriter(path) as out:
            out.append(cloud)
            1 / 0
    del out
    import gc
    gc.collect()
    assert path.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.ply"]


def test_feature_sink_concatenates_to_finish():
    p, f, conf = scene(n=4000, seed=24)
    ref = avsplat.fuse_voxels(p, f, 0.1, conf)
    stream = avsplat.FusionStream(0.1, memory_limit=24 << 10)
    for rows in random_chunks(len(p), np.random.default_rng(25), parts=5):
        stream.add(p[rows], f[rows], conf[rows])
    blocks = []
    summary = stream.finish(sink=blocks.append)
    assert len(blocks) > 1
    np.testing.assert_array_equal(np.concatenate([b.features for b in blocks]), ref.features)
    np.testing.assert_array_equal(np.concatenate([b.voxel_coords for b in blocks]), ref.voxel_coords)
    np.testing.assert_array_equal(summary.sample_voxel, ref.sample_voxel)


def test_four_threads_adding_at_once_never_crash_or_miscount():
    """add() releases the GIL: concurrent calls are refused with RuntimeError, never raced (child
    process: a race crashed with 'double free or corruption' when spilling)."""
    import subprocess
    import sys
    code = r'''
import sys, threading, numpy as np, avsplat
rng = np.random.default_rng(0)
p = rng.normal(size=(400000, 3)).astype(np.float32)
f = rng.normal(size=(400000, 4)).astype(np.float32)
s = avsplat.FusionStream(0.05, memory_limit=int(sys.argv[1]))
accepted = [0] * 4
refused = [0] * 4
def feed(t):
    for at in range(t * 10000, len(p), 40000):
        try:
            s.add(p[at:at + 10000], f[at:at + 10000])
            accepted[t] += 10000
        except RuntimeError as e:
            assert "another call on it runs" in str(e), e
            refused[t] += 10000
threads = [threading.Thread(target=feed, args=(t,)) for t in range(4)]
[t.start() for t in threads]
[t.join() for t in threads]
assert sum(accepted) + sum(refused) == len(p)
assert s.num_samples == sum(accepted), (s.num_samples, sum(accepted))
r = s.finish()
assert len(r.sample_voxel) == sum(accepted)
assert np.all(np.isfinite(r.positions))
print(sum(refused))
'''
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    for limit in (64 << 20, 1 << 30):  # spilling, and not
        run = subprocess.run([sys.executable, "-c", code, str(limit)], env=env, capture_output=True, text=True,
                             timeout=600)
        assert run.returncode == 0, (limit, run.returncode, run.stderr[-2000:])


def test_add_after_an_add_that_failed_to_spill_says_the_stream_is_closed(tmp_path):
    import shutil
    work = tmp_path / "work"
    work.mkdir()
    p, f, conf = scene(20000, 2)
    s = avsplat.FusionStream(0.1, memory_limit=64 << 10, work_dir=str(work))
    shutil.rmtree(work)  # the work folder vanishes before the first spill
    with pytest.raises(OSError, match="work folder"):
        s.add(p, f, conf)
    with pytest.raises(RuntimeError, match="closed because an earlier add failed"):
        s.add(p[:10], f[:10], conf[:10])
    with pytest.raises(RuntimeError, match="closed"):
        s.finish()
