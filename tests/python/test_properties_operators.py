"""Property-based tests (hypothesis) of the operators and formats: transform, prune,
reduce_sh, simplify, the Assist-View operators, the raw-feature decoder and every Gaussian file
format. On random inputs, extreme values, any dtype and degenerate shapes each call gives a
result that keeps its stated invariant, or the documented exception (ValueError naming the
argument, OSError naming the file), never a crash or a silent non-finite result."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import avsplat

EXTREMES = st.sampled_from([np.nan, np.inf, -np.inf, 1e38, -1e38, 1e-45, 0.0, -0.0])
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
FIELDS = ("means", "scales", "rotations", "opacities", "sh")


def arrays(seed, n, degree=0):
    rng = np.random.default_rng(seed)
    return dict(means=rng.normal(size=(n, 3)) * 0.5, scales=rng.uniform(0.01, 0.2, (n, 3)),
                rotations=rng.normal(size=(n, 4)), opacities=rng.uniform(0.05, 1, n),
                sh=rng.normal(size=(n, (degree + 1) ** 2, 3)) * 0.3)


def cloud_of(a):
    return avsplat.GaussianCloud(*(np.asarray(a[k], np.float32) for k in FIELDS))


def with_extreme(a, field, index, value):
    a = {k: np.array(v, np.float64) for k, v in a.items()}
    a[field].reshape(len(a["opacities"]), -1)[index, 0] = value
    return a


def camera():
    return avsplat.Camera.look_at(np.array([0, 0, -3.0]), np.zeros(3), np.array([0, -1, 0.0]), 30, 24, 18)


def finite_cloud(c):
    return all(np.isfinite(np.asarray(getattr(c, k))).all() for k in FIELDS)


@settings(max_examples=40, **SETTINGS)
@given(n=st.integers(0, 20), degree=st.integers(0, 3), seed=st.integers(0, 2**16),
       angle=st.floats(-7, 7), scale=st.one_of(st.floats(1e-3, 1e3), EXTREMES))
def test_transform_is_exact_under_its_inverse_or_a_value_error(n, degree, seed, angle, scale):
    c = cloud_of(arrays(seed, n, degree))
    r = np.array([[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]])
    try:
        moved = avsplat.transform(c, r, [0.5, -1, 2], scale)
    except ValueError as e:
        assert "scale" in str(e)
        assert not (np.isfinite(scale) and scale > 0)
        return
    back = avsplat.transform(avsplat.transform(moved, None, [-0.5, 1, -2], 1.0), r.T, None, 1.0 / scale)
    np.testing.assert_allclose(np.asarray(back.means), np.asarray(c.means), atol=1e-4 * max(1, scale, 1 / scale))
    np.testing.assert_allclose(np.asarray(back.sh), np.asarray(c.sh), atol=1e-4)
    assert back.sh_degree == c.sh_degree and len(back) == len(c)


@settings(max_examples=40, **SETTINGS)
@given(field=st.sampled_from(FIELDS), value=EXTREMES, index=st.integers(0, 5), seed=st.integers(0, 99))
def test_prune_counts_every_gaussian_once_and_keeps_only_valid_ones(field, value, index, seed):
    a = with_extreme(arrays(seed, 6, 1), field, index, value)
    try:
        c = cloud_of(a)
    except ValueError as e:
        assert field in str(e)
        return
    r = avsplat.prune(c, [camera()])
    assert r.kept + r.removed == len(c)
    assert r.removed == r.degenerate + r.low_opacity + r.invisible
    assert len(r.cloud) == r.kept and finite_cloud(r.cloud)
    r.cloud.validate()


@settings(max_examples=40, **SETTINGS)
@given(degree=st.integers(0, 3), max_error=st.one_of(st.floats(0, 1), EXTREMES), seed=st.integers(0, 99),
       magnitude=st.sampled_from([0.0, 1e-6, 1e-2, 1.0, 1e3]))
def test_reduce_sh_meets_its_bound_or_is_a_value_error(degree, max_error, seed, magnitude):
    a = arrays(seed, 8, degree)
    a["sh"][:, 1:, :] *= magnitude
    c = cloud_of(a)
    try:
        r = avsplat.reduce_sh(c, max_error)
    except ValueError as e:
        assert "max_error" in str(e)
        assert not (np.isfinite(max_error) and max_error >= 0)
        return
    assert r.sh_degree <= degree and r.cloud.sh_degree == r.sh_degree
    assert r.max_error_bound <= max_error * (1 + 1e-6) + 1e-12
    k = (r.sh_degree + 1) ** 2
    np.testing.assert_array_equal(np.asarray(r.cloud.sh), np.asarray(c.sh)[:, :k, :])


@settings(max_examples=25, **SETTINGS)
@given(n=st.integers(1, 60), target=st.integers(-2, 70), method=st.sampled_from(["merge", "voxel"]),
       seed=st.integers(0, 99), collapse=st.booleans())
def test_simplify_gives_a_valid_cloud_of_at_most_the_target_or_a_value_error(n, target, method, seed, collapse):
    a = arrays(seed, n, 1)
    if collapse:  # every Gaussian at one point
        a["means"][:] = 0.25
    c = cloud_of(a)
    try:
        r = avsplat.simplify(c, target_count=target, method=method)
    except ValueError as e:
        assert "target_count" in str(e)
        assert target < 1
        return
    assert 1 <= len(r.cloud) <= len(c) and finite_cloud(r.cloud)
    r.cloud.validate()
    if method == "merge":
        assert len(r.cloud) == min(target, n)


@settings(max_examples=30, **SETTINGS)
@given(s=st.integers(1, 6), p=st.integers(1, 9), c=st.integers(1, 8), k=st.integers(0, 6), m=st.integers(0, 8),
       value=st.one_of(st.none(), EXTREMES), dtype=st.sampled_from([np.float32, np.float64, np.int16]),
       seed=st.integers(0, 99))
def test_assist_selection_and_conditioning_are_valid_or_a_value_error(s, p, c, k, m, value, dtype, seed):
    rng = np.random.default_rng(seed)
    tokens = (rng.normal(size=(s, p, c)) * 3).astype(dtype)
    if value is not None and np.issubdtype(dtype, np.floating):
        tokens[rng.integers(s), rng.integers(p), rng.integers(c)] = value
    try:
        sel = avsplat.select_assist_views(tokens, k=k, m=m, p_sub=4)
    except ValueError as e:
        assert "tokens" in str(e) or "k" in str(e) or "m" in str(e)
        return
    a = np.asarray(sel.assists)
    assert a.shape[0] == s and a.shape[1] == min(k, m, s - 1)
    for v in range(s):
        assert v not in a[v] and len(set(a[v].tolist())) == a.shape[1]
    w = [rng.normal(size=(c, c)).astype(np.float32) * 0.1 for _ in range(4)]
    out = np.asarray(avsplat.condition_tokens(np.asarray(tokens, np.float32), a, *w, heads=1))
    assert out.shape == (s, p, c) and np.isfinite(out).all()


@settings(max_examples=40, **SETTINGS)
@given(n=st.integers(0, 12), degree=st.integers(0, 3), value=st.one_of(st.none(), EXTREMES),
       seed=st.integers(0, 99))
def test_decode_gaussians_inverts_encode_or_is_a_value_error(n, degree, value, seed):
    layout = avsplat.FeatureLayout(sh_degree=degree)
    c = cloud_of(arrays(seed, n, degree))
    f = np.asarray(avsplat.encode_gaussians(c, layout)).copy()
    if value is not None and n:
        f[seed % n, seed % f.shape[1]] = value
    try:
        back = avsplat.decode_gaussians(np.asarray(c.means), f, layout)
    except ValueError as e:
        assert "features" in str(e)
        return
    assert len(back) == n and finite_cloud(back)
    if value is None:
        np.testing.assert_allclose(np.asarray(back.means), np.asarray(c.means))
        np.testing.assert_allclose(np.asarray(back.opacities), np.asarray(c.opacities), atol=1e-5)


@settings(max_examples=30, **SETTINGS)
@given(name=st.sampled_from(["a.ply", "a.compressed.ply", "a.splat", "a.spz", "a.sog"]), n=st.integers(0, 40),
       degree=st.integers(0, 3), seed=st.integers(0, 99), far=st.booleans())
def test_every_format_reads_back_what_it_wrote_within_its_loss(tmp_path_factory, name, n, degree, seed, far):
    a = arrays(seed, n, degree)
    if far:  # a scene far from the origin
        a["means"] += 1500.0
    c = cloud_of(a)
    path = str(tmp_path_factory.mktemp("fmt") / name)
    try:
        avsplat.write_gaussians(path, c)
    except (ValueError, OSError) as e:  # a format that cannot hold the cloud says so by name
        assert name.split(".")[-1] in str(e) or "GaussianCloud" in str(e)
        return
    back = avsplat.read_gaussians(path)
    assert len(back) == n and finite_cloud(back)
    assert avsplat.detect_gaussian_format(path).format == {
        "a.ply": "ply", "a.compressed.ply": "compressed_ply", "a.splat": "splat", "a.spz": "spz", "a.sog": "sog"}[name]
    if name == "a.ply":  # lossless for positions, order kept
        np.testing.assert_array_equal(np.asarray(back.means), np.asarray(c.means))
    if n:  # every format keeps the cloud's bounding box within its quantisation
        lo, hi = np.asarray(c.means).min(0), np.asarray(c.means).max(0)
        span = np.maximum(hi - lo, 1e-3)
        got = np.asarray(back.means)
        assert np.all(got >= lo - 0.02 * span - 1e-2) and np.all(got <= hi + 0.02 * span + 1e-2)
