"""GaussianCloud indexing follows numpy's rules: every field of cloud[key] equals the numpy
arrays indexed with the same key, and numpy's IndexErrors come through."""
import numpy as np
import pytest

import avsplat


def make_cloud(n=10, degree=1, seed=3):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    q = rng.normal(size=(n, 4))
    cloud = avsplat.GaussianCloud(rng.normal(size=(n, 3)), rng.uniform(0.1, 1, (n, 3)), q / np.linalg.norm(q, axis=1)[:, None],
                                  rng.uniform(0, 1, n), rng.normal(size=(n, k, 3)), confidence=rng.normal(size=n))
    cloud.set_extra("label", np.arange(n, dtype=np.float32))
    return cloud


def fields(c):
    return [c.means, c.scales, c.rotations, c.opacities, c.sh, c.confidence, c.extras["label"]]


KEYS = [slice(2, 7), slice(None, None, 2), slice(-3, None), slice(8, 2, -2), slice(20, 30), np.array([4, 0, 4, -1]),
        [1, 2], np.arange(10) % 3 == 0, 3, -1, np.int64(7), np.array([], dtype=np.int64)]


@pytest.mark.parametrize("key", KEYS, ids=repr)
def test_indexing_matches_numpy_on_every_field(key):
    cloud = make_cloud()
    picked = cloud[key]
    assert isinstance(picked, avsplat.GaussianCloud)
    for got, full in zip(fields(picked), fields(cloud)):
        want = full[key]
        if np.ndim(want) == full.ndim - 1:  # an integer key: numpy drops the axis, the cloud keeps one Gaussian
            want = want[None]
        np.testing.assert_array_equal(got, want)
    assert picked.sh_degree == cloud.sh_degree
    assert len(picked) == len(fields(picked)[0])


@pytest.mark.parametrize("key", [10, -11, np.array([0, 10]), np.ones(9, bool), (0, 1), 1.5, "a"], ids=repr)
def test_bad_keys_raise_index_error(key):
    with pytest.raises(IndexError):
        make_cloud()[key]


def test_indexing_copies_so_the_source_is_untouched():
    cloud = make_cloud()
    before = cloud.means.copy()
    picked = cloud[:3]
    picked.means[:] = 0
    np.testing.assert_array_equal(cloud.means, before)


def test_len_and_repr_show_count_degree_and_extras():
    cloud = make_cloud(n=7, degree=2)
    assert len(cloud) == 7
    assert repr(cloud) == "GaussianCloud(n=7, sh_degree=2, confidence=yes, extras=[label])"
