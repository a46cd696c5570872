"""avsplat.dask on a LocalCluster of 2 workers: bit-identical to the in-memory operators.

Inputs are dask arrays with irregular random chunks; the scene is a dense object in a sparse
background with samples exactly on voxel boundaries, so voxels straddle chunk boundaries and the
blocks are far from equal-width slabs. Every output array must equal the in-memory one.
"""
import logging
import os
import signal

import numpy as np
import pytest

import avsplat

da = pytest.importorskip("dask.array")
distributed = pytest.importorskip("distributed")
ad = pytest.importorskip("avsplat.dask")

FIELDS = ("positions", "voxel_coords", "sample_voxel", "occupancy", "temperature", "variance", "reliability",
          "kept", "entropy")


@pytest.fixture(scope="module")
def client():
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, dashboard_address=":0",
                                  silence_logs=logging.ERROR) as cluster, distributed.Client(cluster) as c:
        yield c


def scene(n=8000, c=4, seed=0):
    rng = np.random.default_rng(seed)
    dense = rng.normal(0, 0.2, size=(n * 3 // 4, 3))
    sparse = rng.uniform(-5, 5, size=(n - len(dense), 3))
    p = np.concatenate([dense, sparse]).astype(np.float32)[rng.permutation(n)]
    p[:40, 0] = (np.arange(40) - 20 + 0.5).astype(np.float32) * np.float32(0.1)
    return p, rng.normal(size=(n, c)).astype(np.float32), rng.normal(0, 2, size=n).astype(np.float32)


def random_chunks(n, seed, parts=7):
    rng = np.random.default_rng(seed)
    cuts = np.sort(rng.choice(np.arange(1, n), size=parts - 1, replace=False))
    return tuple(np.diff(np.concatenate([[0], cuts, [n]])).tolist())


def chunked(a, chunks):
    return da.from_array(a, chunks=(chunks,) + a.shape[1:])


def assert_identical(got, ref, extra=()):
    for name in FIELDS + tuple(extra):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref, name), err_msg=name)
    assert int(got.dropped) == ref.dropped


@pytest.mark.parametrize("policy,knobs", [("mean", {}), ("softmax", {}), ("occupancy", {}),
                                          ("occupancy", {"weights": "sparsemax", "precision": "float64"})])
def test_dask_fuse_voxels_identical(client, policy, knobs):
    p, f, conf = scene(seed=1)
    ref = avsplat.fuse_voxels(p, f, 0.1, conf, policy=policy, **knobs)
    ch = random_chunks(len(p), 2)
    r = ad.fuse_voxels(chunked(p, ch), chunked(f, ch), 0.1, chunked(conf, ch), policy=policy, blocks=6, **knobs)
    got = r.compute()
    assert len(got.block_samples) == 6 and got.block_samples.sum() == len(p)
    assert_identical(got, ref, ("features",))


def test_dask_fuse_voxels_drop_and_no_confidence(client):
    p, f, conf = scene(n=3000, seed=3)
    p[[5, 2000], 2] = np.nan
    f[17, 1] = np.inf
    ref = avsplat.fuse_voxels(p, f, 0.1, on_invalid="drop")
    assert ref.dropped == 3
    ch = random_chunks(len(p), 4, parts=4)
    got = ad.fuse_voxels(chunked(p, ch), chunked(f, ch), 0.1, on_invalid="drop", blocks=3).compute()
    assert_identical(got, ref, ("features",))
    with pytest.raises(ValueError, match=r"positions\[2000, 2\]"):
        p[5, 2] = 0
        ad.fuse_voxels(chunked(p, ch), chunked(f, ch), 0.1, blocks=3).compute()
    p[2000, 2] = 0
    with pytest.raises(ValueError, match=r"features\[17, 1\]"):  # the global index, not the block's
        ad.fuse_voxels(chunked(p, ch), chunked(f, ch), 0.1, blocks=3).compute(scheduler="sync")
    with pytest.raises(TypeError, match="'wrong'"):
        ad.fuse_voxels(chunked(p, ch), chunked(f, ch), 0.1, wrong=1)


@pytest.mark.parametrize("shape", ["average", "moment"])
@pytest.mark.parametrize("policy", ["mean", "softmax", "occupancy"])
def test_dask_fuse_gaussians_identical(client, shape, policy):
    rng = np.random.default_rng(5)
    p, _, conf = scene(n=4000, c=1, seed=5)
    n = len(p)
    cloud = avsplat.GaussianCloud(means=p, scales=rng.uniform(0.01, 0.1, size=(n, 3)),
                                  rotations=rng.normal(size=(n, 4)), opacities=rng.uniform(0, 1, size=n),
                                  sh=rng.normal(size=(n, 4, 3)), confidence=conf)
    extra = rng.normal(size=n).astype(np.float32)
    cloud.set_extra("f_extra", extra)
    ref = avsplat.fuse_gaussians(cloud, 0.1, policy=policy, shape=shape)
    ch = random_chunks(n, 6, parts=5)
    r = ad.fuse_gaussians(chunked(cloud.means, ch), chunked(cloud.scales, ch), chunked(cloud.rotations, ch),
                          chunked(cloud.opacities, ch), chunked(cloud.sh, ch), 0.1,
                          confidence=chunked(cloud.confidence, ch), extras={"f_extra": chunked(extra, ch)},
                          policy=policy, shape=shape, blocks=5)
    got = r.compute()
    assert_identical(got, ref)
    for name in ("means", "scales", "rotations", "opacities", "sh", "confidence"):
        np.testing.assert_array_equal(getattr(got, name), getattr(ref.cloud, name), err_msg=name)
    np.testing.assert_array_equal(got.extras["f_extra"], ref.cloud.extras["f_extra"])


def test_blocks_are_balanced_for_a_dense_object_in_a_sparse_background(client):
    rng = np.random.default_rng(7)
    n = 60000
    p = np.concatenate([rng.normal(0, 0.1, size=(n * 9 // 10, 3)),
                        rng.uniform(-20, 20, size=(n // 10, 3))]).astype(np.float32)
    keys = ad.voxel_keys(p, 0.05)
    # Equal-width kx slabs would be far from balanced on this scene...
    slabs = np.histogram(keys[:, 0], bins=8)[0]
    assert slabs.max() > 4 * slabs.mean()
    # ...the key-quantile blocks are within the documented 1.25x of the mean.
    r = ad.fuse_voxels(da.from_array(p, chunks=(7000, 3)), np.zeros((n, 0), np.float32), 0.05, blocks=8)
    counts = r.block_samples.compute()
    assert len(counts) == 8 and counts.sum() == n
    assert counts.max() <= 1.25 * counts.mean(), counts


def test_voxel_keys_round_half_away_from_zero():
    x = np.array([[0.5, -0.5, 1.5], [2.5, -2.5, 0.49999997]], np.float32)
    np.testing.assert_array_equal(ad.voxel_keys(x, 1.0), [[1, -1, 2], [3, -3, 0]])
    grid = avsplat.SparseVoxelGrid(x, 1.0)
    np.testing.assert_array_equal(np.unique(ad.voxel_keys(x, 1.0), axis=0), grid.voxel_coords)


def test_worker_killed_during_the_run_is_recovered():
    # The result is persisted on the workers, one of them is killed with SIGKILL (its nanny
    # starts a new one), and the keys it held are recomputed by Dask from the graph.
    p, f, conf = scene(n=6000, seed=9)
    ref = avsplat.fuse_voxels(p, f, 0.1, conf)
    ch = random_chunks(len(p), 10, parts=6)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=logging.CRITICAL) as cluster, distributed.Client(cluster) as c:
        r = ad.fuse_voxels(chunked(p, ch), chunked(f, ch), 0.1, chunked(conf, ch), blocks=6)
        arrays = dict(vars(r))
        persisted = dict(zip(arrays, c.persist(list(arrays.values()))))
        distributed.wait([persisted[k] for k in arrays])
        held = c.has_what()
        victim = max(held, key=lambda w: len(held[w]))
        assert held[victim], "the victim holds part of the result"
        pid = c.run(os.getpid, workers=[victim])[victim]
        os.kill(pid, signal.SIGKILL)
        got = dict(zip(arrays, c.compute(list(persisted.values()), sync=True)))
    for name in FIELDS + ("features",):
        np.testing.assert_array_equal(got[name], getattr(ref, name), err_msg=name)


def test_worker_killed_while_blocks_are_being_fused_is_recovered():
    # SIGKILL lands on a worker while the scheduler shows it running fusion tasks; whatever it was
    # running or holding is recomputed elsewhere, and the result is still the in-memory one.
    import time

    p, f, conf = scene(n=400000, seed=10)
    ref = avsplat.fuse_voxels(p, f, 0.02, conf)
    ch = random_chunks(len(p), 11, parts=8)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  silence_logs=logging.CRITICAL) as cluster, distributed.Client(cluster) as c:
        r = ad.fuse_voxels(chunked(p, ch), chunked(f, ch), 0.02, chunked(conf, ch), blocks=16)
        arrays = dict(vars(r))
        futures = c.compute(list(arrays.values()))
        victim, running = None, []
        deadline = time.monotonic() + 60
        while victim is None and time.monotonic() < deadline:
            for worker, keys in c.processing().items():
                fusing = [k for k in keys if "fuse_block" in str(k)]
                if fusing:
                    victim, running = worker, fusing
                    break
            time.sleep(0.005)
        assert victim is not None, "no fusion task was seen running"
        pid = c.run(os.getpid, workers=[victim])[victim]
        os.kill(pid, signal.SIGKILL)
        got = dict(zip(arrays, c.gather(futures)))
    assert running
    for name in FIELDS + ("features",):
        np.testing.assert_array_equal(got[name], getattr(ref, name), err_msg=name)


def test_keys_at_the_ends_of_int32_are_kept_as_in_memory():
    """round(p / voxel) = -2^31 fits int32 and is a voxel of the in-memory operator; 2^31 does not."""
    p = np.array([[-2.0**31, 0, 0], [0, 2.0**31 - 128, 0], [1, 2, 3], [0, 0, -2.0**31]], np.float32)
    f = np.arange(8, dtype=np.float32).reshape(4, 2)
    ref = avsplat.fuse_voxels(p, f, 1.0)
    for on_invalid in ("raise", "drop"):
        got = ad.fuse_voxels(da.from_array(p, chunks=(2, 3)), da.from_array(f, chunks=(2, 2)), 1.0,
                             on_invalid=on_invalid, blocks=2).compute(scheduler="sync")
        np.testing.assert_array_equal(got.voxel_coords, ref.voxel_coords)
        np.testing.assert_array_equal(got.sample_voxel, ref.sample_voxel)
        assert int(got.dropped) == 0


def test_a_key_beyond_int32_is_reported_on_its_own_axis():
    p = np.array([[0, 0, 0], [1, 2.0**31, 3]], np.float32)
    f = np.zeros((2, 1), np.float32)
    with pytest.raises(ValueError, match=r"positions\[1, 1\]"):
        ad.fuse_voxels(da.from_array(p, chunks=(1, 3)), da.from_array(f, chunks=(1, 1)), 1.0,
                       blocks=1).compute(scheduler="sync")
