"""avsplat.fuse_voxels / fuse_gaussians / SparseVoxelGrid against a float64 numpy reference of
AVSplat's Algorithm 2 written here, plus shapes, dtypes, error paths and knobs."""
import threading

import numpy as np
import pytest

import avsplat

FLT_MAX = float(np.finfo(np.float32).max)

DEFAULTS = dict(tau0=0.7, alpha=0.5, n_ref=8.0, tau_min=0.15, tau_max=2.0, b_conf=1.0, b_geo=2.0,
                k_rel=1.0, eps=1e-6, trim_mass=0.8, weights="softmax", confidence_mapping="logit")


# --------------------------------------------------------------------------------------------
# The reference (float64, numpy, one voxel at a time)

def ref_keys(p, voxel):
    q = p.astype(np.float64) / voxel
    return (np.sign(q) * np.floor(np.abs(q) + 0.5)).astype(np.int64)  # half away from zero


def ref_map(c, mapping):
    c = c.astype(np.float64)
    with np.errstate(divide="ignore"):
        if mapping == "probability":
            logit, prob = np.log(c) - np.log1p(-c), c
        elif mapping == "positive":
            logit, prob = np.log(c), c / (1 + c)
        else:
            logit, prob = c, 1 / (1 + np.exp(-c))
    return np.clip(logit, -FLT_MAX, FLT_MAX), prob


def ref_softmax(z):
    e = np.exp(z - z.max())
    return e / e.sum()


def ref_sparsemax(z):
    z = z - z.max()
    s = np.sort(z)[::-1]
    k = np.arange(1, len(z) + 1)
    cum = np.cumsum(s)
    support = k[1 + k * s > cum].max()
    tau = (cum[support - 1] - 1) / support
    return np.maximum(z - tau, 0)


def ref_trim(w, m):
    if not 0 < m < 1:
        return w
    s = np.sort(w)[::-1]
    cum = np.cumsum(s)
    idx = np.nonzero(cum >= m)[0]
    cut = s[idx[0]] if len(idx) else s[s > 0][-1]
    w = np.where(w >= cut, w, 0.0)
    return w / w.sum()


def reference(p, f, voxel, conf=None, policy="occupancy", **knobs):
    k = {**DEFAULTS, **knobs}
    keys = ref_keys(p, voxel)
    uniq, inverse = np.unique(keys, axis=0, return_inverse=True)  # lexicographic, like avsplat
    inverse = inverse.reshape(-1)
    out = dict(voxel_coords=uniq, positions=[], features=[], occupancy=[], temperature=[],
               variance=[], reliability=[], kept=[], entropy=[], weights=[], members=[])
    groups = np.split(np.argsort(inverse, kind="stable"), np.cumsum(np.bincount(inverse))[:-1])
    for ids in groups:
        n = len(ids)
        pv = p[ids].astype(np.float64)
        var = ((pv - pv.mean(0)) ** 2).sum(1).mean()
        g = 1 / (1 + var / (voxel ** 2 + k["eps"]))
        if conf is None:
            logit, prob, raw = np.zeros(n), np.full(n, 0.5), np.zeros(n)
        else:
            logit, prob = ref_map(conf[ids], k["confidence_mapping"])
            raw = conf[ids].astype(np.float64)
        r = np.clip((k["b_conf"] * prob.mean() + k["b_geo"] * g) / (k["b_conf"] + k["b_geo"] + k["eps"]), 0, 1)
        if policy == "mean":
            w, tau = np.full(n, 1 / n), np.inf
        elif policy == "softmax":
            w, tau = ref_softmax(raw), 1.0
        else:
            tau = k["tau0"] * max(n / k["n_ref"], k["eps"]) ** (-k["alpha"]) / (1 + k["k_rel"] * (1 - r))
            tau = min(max(tau, k["tau_min"]), k["tau_max"])
            z = logit / tau
            w = ref_sparsemax(z) if k["weights"] == "sparsemax" else ref_softmax(z)
            w = ref_trim(w, k["trim_mass"] or 0.0)
        out["positions"].append(w @ pv / w.sum())
        out["features"].append(w @ f[ids].astype(np.float64) / w.sum())
        out["occupancy"].append(n)
        out["temperature"].append(tau)
        out["variance"].append(var)
        out["reliability"].append(r)
        out["kept"].append(int((w > 0).sum()))
        nz = w[w > 0]
        out["entropy"].append(float(-(nz * np.log(nz)).sum()))
        out["weights"].append(w)
        out["members"].append(ids)
    for key in ("positions", "features", "occupancy", "temperature", "variance", "reliability", "kept", "entropy"):
        out[key] = np.array(out[key])
    return out


def scene(n=4000, c=6, seed=0, extent=1.0, mapping="logit"):
    rng = np.random.default_rng(seed)
    p = rng.uniform(-extent, extent, size=(n, 3)).astype(np.float32)
    f = rng.uniform(-3, 3, size=(n, c)).astype(np.float32)
    if mapping == "probability":
        conf = rng.uniform(0, 1, size=n)
    elif mapping == "positive":
        conf = 1 + np.exp(rng.normal(0, 2, size=n))
    else:
        conf = rng.normal(0, 2, size=n)
    return p, f, conf.astype(np.float32)


def assert_matches(got, ref, p, f, tol=1e-5):
    np.testing.assert_array_equal(got.voxel_coords, ref["voxel_coords"])
    np.testing.assert_array_equal(got.occupancy, ref["occupancy"])
    # Tolerance relative to the magnitude of each voxel's inputs (the scale of a weighted mean).
    for v, ids in enumerate(ref["members"]):
        scale_p = np.abs(p[ids]).max(0)
        scale_f = np.abs(f[ids]).max(0) if f.shape[1] else np.zeros(0)
        assert np.all(np.abs(got.positions[v] - ref["positions"][v]) <= tol * scale_p), v
        assert np.all(np.abs(got.features[v] - ref["features"][v]) <= tol * scale_f), v
    np.testing.assert_array_equal(got.kept, ref["kept"])
    np.testing.assert_allclose(got.temperature, ref["temperature"], rtol=1e-5)
    np.testing.assert_allclose(got.variance, ref["variance"], rtol=1e-4, atol=1e-12)
    np.testing.assert_allclose(got.reliability, ref["reliability"], rtol=1e-5)
    np.testing.assert_allclose(got.entropy, ref["entropy"], atol=1e-5)


# --------------------------------------------------------------------------------------------
# Against the reference

@pytest.mark.parametrize("mapping", ["logit", "probability", "positive"])
@pytest.mark.parametrize("policy,knobs", [
    ("mean", {}),
    ("softmax", {}),
    ("occupancy", {}),
    ("occupancy", dict(trim_mass=None)),
    ("occupancy", dict(weights="sparsemax")),
    ("occupancy", dict(weights="sparsemax", trim_mass=0.6, tau0=0.4, alpha=0.3, n_ref=4, k_rel=2.0,
                       b_conf=0.5, b_geo=3.0)),
])
def test_matches_numpy_reference(mapping, policy, knobs):
    p, f, conf = scene(mapping=mapping, seed=len(mapping))
    got = avsplat.fuse_voxels(p, f, 0.15, conf, policy=policy, confidence_mapping=mapping, **knobs)
    ref = reference(p, f, 0.15, conf, policy=policy, confidence_mapping=mapping, **knobs)
    if policy == "softmax" and mapping == "positive":
        # Raw confidences up to ~e^8 underflow some float32 weights that float64 keeps: compare
        # the values, and the kept count only where no reference weight is that small.
        tiny = np.array([((w > 0) & (w < 1e-36)).any() for w in ref["weights"]])
        ref["kept"] = np.where(tiny, got.kept, ref["kept"])
    assert_matches(got, ref, p, f)


def test_float64_precision_matches_reference_and_float32_is_close():
    p, f, conf = scene(n=6000, seed=3)
    a = avsplat.fuse_voxels(p, f, 0.12, conf, precision="float32")
    b = avsplat.fuse_voxels(p, f, 0.12, conf, precision="float64")
    assert_matches(b, reference(p, f, 0.12, conf), p, f)
    assert np.abs(a.features - b.features).max() <= 1e-5 * 3


def test_without_confidence_every_policy_is_the_mean():
    p, f, _ = scene(seed=5)
    mean = avsplat.fuse_voxels(p, f, 0.2, policy="mean")
    ref = reference(p, f, 0.2, policy="mean")
    assert_matches(mean, ref, p, f)
    for policy in ("softmax", "occupancy"):
        got = avsplat.fuse_voxels(p, f, 0.2, policy=policy)
        np.testing.assert_array_equal(got.features, mean.features)
        np.testing.assert_array_equal(got.positions, mean.positions)
        np.testing.assert_array_equal(got.kept, got.occupancy)


def test_occupancy_reduces_to_softmax():
    p, f, conf = scene(seed=7)
    a = avsplat.fuse_voxels(p, f, 0.1, conf, trim_mass=0, alpha=0, k_rel=0, tau0=1)
    b = avsplat.fuse_voxels(p, f, 0.1, conf, policy="softmax")
    np.testing.assert_array_equal(a.features, b.features)
    np.testing.assert_array_equal(a.positions, b.positions)


def test_permutation_and_translation_invariance():
    p, f, conf = scene(n=8000, seed=9)
    perm = np.random.default_rng(1).permutation(len(p))
    a = avsplat.fuse_voxels(p, f, 0.1, conf)
    b = avsplat.fuse_voxels(p[perm], f[perm], 0.1, conf[perm])
    for name in ("positions", "features", "voxel_coords", "temperature", "variance", "reliability", "kept",
                 "entropy"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    np.testing.assert_array_equal(b.sample_voxel, a.sample_voxel[perm])
    # Whole-voxel translation on an exact lattice.
    q = (np.round(p * 64) / 64 + 1 / 256).astype(np.float32)
    shift = np.array([2, -5, 9])
    c = avsplat.fuse_voxels(q, f, 0.25, conf)
    d = avsplat.fuse_voxels((q + 0.25 * shift).astype(np.float32), f, 0.25, conf)
    np.testing.assert_array_equal(d.voxel_coords, c.voxel_coords + shift)
    np.testing.assert_allclose(d.positions, c.positions + 0.25 * shift, atol=1e-5)
    np.testing.assert_allclose(d.features, c.features, atol=3e-5)


def test_single_sample_voxels_pass_through_bit_exactly():
    p, f, conf = scene(n=300, extent=100.0, seed=11)
    p[:, 0] = np.arange(300, dtype=np.float32) + 0.1
    r = avsplat.fuse_voxels(p, f, 1.0, conf)
    assert len(r) == 300
    np.testing.assert_array_equal(r.positions[r.sample_voxel], p)
    np.testing.assert_array_equal(r.features[r.sample_voxel], f)
    assert np.all(r.entropy == 0) and np.all(r.kept == 1)


def test_extreme_confidences_give_valid_weights():
    # One voxel, one-hot features: the fused features are the weights.
    n = 7
    p = np.zeros((n, 3), np.float32)
    p[:, 0] = np.linspace(-0.3, 0.3, n)
    f = np.eye(n, dtype=np.float32)
    for conf in ([1e30, -1e30, 1e30, 0, 5, -1e30, 2], [1e30] * n, [-1e30] * n, [FLT_MAX, -FLT_MAX, 0, 1, 2, 3, 4]):
        for policy, knobs in (("occupancy", {}), ("occupancy", dict(weights="sparsemax")), ("softmax", {}),
                              ("mean", {})):
            w = avsplat.fuse_voxels(p, f, 1.0, np.array(conf, np.float32), policy=policy, **knobs).features[0]
            assert np.all(np.isfinite(w)) and np.all(w >= 0), (conf, policy)
            assert abs(w.sum() - 1) < 1e-6


def test_dominant_sample_and_temperature_clip():
    rng = np.random.default_rng(13)
    n = 100_000
    p = rng.uniform(-0.45, 0.45, size=(n, 3)).astype(np.float32)
    f = rng.normal(size=(n, 2)).astype(np.float32)
    conf = np.zeros(n, np.float32)
    conf[777] = 50
    r = avsplat.fuse_voxels(p, f, 1.0, conf)
    assert r.kept[0] == 1 and r.temperature[0] == np.float32(0.15)
    np.testing.assert_array_equal(r.features[0], f[777])
    r = avsplat.fuse_voxels(p[:2], f[:2], 1.0, conf[:2], tau0=50)
    assert r.temperature[0] == np.float32(2.0)


def test_result_shapes_dtypes_and_views():
    p, f, conf = scene(n=500, c=3, seed=15)
    r = avsplat.fuse_voxels(p, f, 0.5, conf)
    m = len(r)
    assert r.positions.shape == (m, 3) and r.positions.dtype == np.float32
    assert r.features.shape == (m, 3) and r.features.dtype == np.float32
    assert r.voxel_coords.shape == (m, 3) and r.voxel_coords.dtype == np.int32
    assert r.sample_voxel.shape == (500,) and r.sample_voxel.dtype == np.int32
    for name in ("temperature", "variance", "reliability", "entropy"):
        assert getattr(r, name).shape == (m,) and getattr(r, name).dtype == np.float32
    for name in ("occupancy", "kept"):
        assert getattr(r, name).shape == (m,) and getattr(r, name).dtype == np.int32
    assert r.occupancy.sum() == 500 and r.dropped == 0 and r.channels == 3
    assert repr(r) == f"FeatureFusionResult(voxels={m}, channels=3, samples=500, dropped=0)"
    # The arrays are views of the result (no copy out): they outlive a deleted result object.
    feats = r.features
    del r
    assert feats.sum() == feats.sum()
    # Any float dtype and layout is accepted; an empty input gives an empty result.
    r64 = avsplat.fuse_voxels(p.astype(np.float64), np.asfortranarray(f), 0.5, conf.astype(np.float64))
    np.testing.assert_array_equal(r64.features, avsplat.fuse_voxels(p, f, 0.5, conf).features)
    empty = avsplat.fuse_voxels(np.zeros((0, 3)), np.zeros((0, 4)), 0.1)
    assert len(empty) == 0 and empty.features.shape == (0, 4)


def test_sparse_voxel_grid_binding():
    p, _, _ = scene(n=3000, seed=17)
    g = avsplat.SparseVoxelGrid(p, 0.2)
    keys = ref_keys(p, 0.2)
    uniq, inverse, counts = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    assert len(g) == g.num_voxels == len(uniq) and g.num_samples == 3000 and g.dropped == 0
    np.testing.assert_array_equal(g.voxel_coords, uniq)
    np.testing.assert_array_equal(g.sample_voxel, inverse.reshape(-1))
    np.testing.assert_array_equal(g.occupancy, counts)
    assert g.voxel_offsets.dtype == np.int64 and g.voxel_offsets[-1] == 3000
    for v in (0, len(uniq) // 2, len(uniq) - 1):
        ids = g.sample_indices[g.voxel_offsets[v]:g.voxel_offsets[v + 1]]
        np.testing.assert_array_equal(ids, np.nonzero(inverse.reshape(-1) == v)[0])
    assert not g.voxel_coords.flags.writeable
    assert g.max_occupancy == counts.max() and g.voxel_size == 0.2
    assert repr(g).startswith(f"SparseVoxelGrid(voxels={len(uniq)}, samples=3000")
    p[5, 1] = np.nan
    with pytest.raises(ValueError, match=r"positions\[5, 1\]"):
        avsplat.SparseVoxelGrid(p, 0.2)
    assert avsplat.SparseVoxelGrid(p, 0.2, on_invalid="drop").dropped == 1


def test_errors_name_the_field_and_index():
    p, f, conf = scene(n=200, seed=19)
    bad = f.copy()
    bad[42, 1] = np.inf
    with pytest.raises(ValueError, match=r"features\[42, 1\]"):
        avsplat.fuse_voxels(p, bad, 0.3, conf)
    r = avsplat.fuse_voxels(p, bad, 0.3, conf, on_invalid="drop")
    assert r.dropped == 1 and r.sample_voxel[42] == -1
    c = conf.copy()
    c[9] = np.nan
    with pytest.raises(ValueError, match=r"confidence\[9\]"):
        avsplat.fuse_voxels(p, f, 0.3, c)
    with pytest.raises(ValueError, match=r"outside \[0, 1\]"):
        avsplat.fuse_voxels(p, f, 0.3, np.full(200, 2.0, np.float32), confidence_mapping="probability")
    big = p.copy()
    big[3, 0] = 1e7
    with pytest.raises(ValueError, match=r"positions\[3, 0\].*int32"):
        avsplat.fuse_voxels(big, f, 1e-3, conf)
    with pytest.raises(ValueError, match="features: expected shape"):
        avsplat.fuse_voxels(p, f[:10], 0.3)
    with pytest.raises(ValueError, match="confidence: expected shape"):
        avsplat.fuse_voxels(p, f, 0.3, conf[:10])
    with pytest.raises(ValueError, match="voxel_size"):
        avsplat.fuse_voxels(p, f, 0.0)



def test_a_bad_feature_in_a_trimmed_sample_is_still_found():
    # One voxel of 20 samples whose confidences fall steeply: trimming keeps the first few, and
    # when every row is finite pass 2 reads only theirs (fuse_features.cpp). A NaN or Inf in the
    # row of a sample it leaves out must still be named, or dropped and counted.
    rng = np.random.default_rng(5)
    p = rng.uniform(-0.01, 0.01, (20, 3)).astype(np.float32)
    f = rng.standard_normal((20, 4)).astype(np.float32)
    conf = np.linspace(6, -6, 20).astype(np.float32)
    clean = avsplat.fuse_voxels(p, f, 1.0, conf)
    assert len(clean.features) == 1 and clean.kept[0] < 10
    for value in (np.nan, np.inf):
        bad = f.copy()
        bad[19, 2] = value
        with pytest.raises(ValueError, match=r"features\[19, 2\]"):
            avsplat.fuse_voxels(p, bad, 1.0, conf)
        r = avsplat.fuse_voxels(p, bad, 1.0, conf, on_invalid="drop")
        assert r.dropped == 1 and r.sample_voxel[19] == -1
        np.testing.assert_array_equal(r.features, avsplat.fuse_voxels(p[:19], f[:19], 1.0, conf[:19]).features)
        # Without zero weights no row is skipped (and no scan runs): found all the same.
        for policy in ("mean", "softmax"):
            with pytest.raises(ValueError, match=r"features\[19, 2\]"):
                avsplat.fuse_voxels(p, bad, 1.0, conf, policy=policy)

def test_knobs_are_checked():
    p, f, conf = scene(n=100, seed=21)
    with pytest.raises(TypeError, match="'tau_0', 'temp'"):
        avsplat.fuse_voxels(p, f, 0.3, conf, tau_0=1.0, temp=2)
    with pytest.raises(TypeError, match="shape"):
        avsplat.fuse_voxels(p, f, 0.3, conf, shape="moment")
    with pytest.raises(ValueError, match="weights: 'softermax'"):
        avsplat.fuse_voxels(p, f, 0.3, conf, weights="softermax")
    with pytest.raises(ValueError, match="policy"):
        avsplat.fuse_voxels(p, f, 0.3, conf, policy="median")
    with pytest.raises(ValueError, match="FusionParams.tau_max"):
        avsplat.fuse_voxels(p, f, 0.3, conf, tau_min=1.0, tau_max=0.5)
    with pytest.raises(TypeError, match="tau0: expected a number"):
        avsplat.fuse_voxels(p, f, 0.3, conf, tau0="hot")
    # Numpy scalars and ints are numbers; trim_mass=None is off.
    a = avsplat.fuse_voxels(p, f, 0.3, conf, tau0=np.float32(0.5), n_ref=4, trim_mass=None)
    b = avsplat.fuse_voxels(p, f, 0.3, conf, tau0=0.5, n_ref=4.0, trim_mass=0.0)
    np.testing.assert_array_equal(a.features, b.features)


def test_fuse_gaussians_against_reference():
    rng = np.random.default_rng(23)
    n = 3000
    cloud = avsplat.GaussianCloud(
        means=rng.uniform(-1, 1, size=(n, 3)), scales=rng.uniform(0.01, 0.1, size=(n, 3)),
        rotations=rng.normal(size=(n, 4)), opacities=rng.uniform(0, 1, size=n),
        sh=rng.normal(size=(n, 4, 3)), confidence=rng.normal(0, 2, size=n))
    for shape in ("average", "moment"):
        r = avsplat.fuse_gaussians(cloud, 0.2, shape=shape)
        # Opacities and SH are features fused with the same weights.
        feats = np.concatenate([cloud.opacities[:, None], cloud.sh.reshape(n, -1)], axis=1)
        ref = reference(cloud.means, feats, 0.2, cloud.confidence)
        np.testing.assert_array_equal(r.voxel_coords, ref["voxel_coords"])
        np.testing.assert_allclose(r.cloud.opacities, ref["features"][:, 0], atol=1e-5)
        np.testing.assert_allclose(r.cloud.sh.reshape(len(r), -1), ref["features"][:, 1:], atol=1e-5)
        np.testing.assert_allclose(r.positions, ref["positions"], atol=1e-5)
        np.testing.assert_array_equal(r.kept, ref["kept"])
        multi = r.occupancy > 1
        np.testing.assert_allclose(np.linalg.norm(r.cloud.rotations[multi], axis=1), 1, rtol=1e-6)
        assert np.all(r.cloud.rotations[multi, 0] >= 0)
        r.cloud.validate()
    with pytest.raises(TypeError, match="'wrong'"):
        avsplat.fuse_gaussians(cloud, 0.2, wrong=1)
    assert repr(avsplat.fuse_gaussians(cloud, 0.2)).startswith("GaussianFusionResult(voxels=")


def test_runs_in_threads():
    # The GIL is released while fusing: several threads fuse concurrently and agree.
    p, f, conf = scene(n=20000, seed=25)
    expected = avsplat.fuse_voxels(p, f, 0.05, conf).features
    results = [None] * 3

    def work(i):
        results[i] = avsplat.fuse_voxels(p, f, 0.05, conf).features

    threads = [threading.Thread(target=work, args=(i,)) for i in range(3)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for r in results:
        np.testing.assert_array_equal(r, expected)
