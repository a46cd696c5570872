import numpy as np
import pytest

import avsplat


def make(n=4, k=4, seed=0, confidence=False):
    rng = np.random.default_rng(seed)
    args = dict(
        means=rng.normal(size=(n, 3)),
        scales=rng.uniform(0.01, 1, size=(n, 3)),
        rotations=rng.normal(size=(n, 4)),
        opacities=rng.uniform(0, 1, size=n),
        sh=rng.normal(size=(n, k, 3)),
    )
    if confidence:
        args["confidence"] = rng.normal(size=n)
    return args


def test_construct_converts_to_float32_and_exposes_views():
    a = make(confidence=True)
    c = avsplat.GaussianCloud(**a)
    assert len(c) == 4 and c.sh_degree == 1 and c.sh_coeffs == 4
    for name in ("means", "scales", "rotations", "opacities", "sh", "confidence"):
        got = getattr(c, name)
        assert got.dtype == np.float32
        np.testing.assert_array_equal(got, a[name].astype(np.float32))
    # Properties are views: writing through them changes the cloud.
    c.means[1, 2] = 42.0
    assert c.means[1, 2] == 42.0
    view = c.scales
    c.scales = np.full((4, 3), 0.5)
    assert view[0, 0] == 0.5  # assignment copies into the same storage
    assert "GaussianCloud(n=4, sh_degree=1, confidence=yes)" == repr(c)


def test_non_contiguous_and_shorthand_shapes():
    a = make(k=1)
    means = np.asfortranarray(a["means"])
    c = avsplat.GaussianCloud(means, a["scales"], a["rotations"], a["opacities"][:, None], a["sh"][:, 0, :])
    assert c.sh_degree == 0
    np.testing.assert_allclose(c.means, a["means"], rtol=1e-6)
    assert c.confidence is None


@pytest.mark.parametrize(
    "field,value,message",
    [
        ("scales", np.ones((4, 2)), "scales: expected shape (N, 3), got (4, 2)"),
        ("rotations", np.ones((3, 4)), "rotations: expected shape (N, 4)"),
        ("sh", np.ones((4, 5, 3)), "sh: K = 5"),
        ("opacities", np.ones(5), "opacities: expected shape (N)"),
        ("confidence", np.ones(2), "confidence: expected shape (N)"),
    ],
)
def test_wrong_shapes_raise_value_error_naming_the_argument(field, value, message):
    a = make()
    a[field] = value
    with pytest.raises(ValueError, match=message.replace("(", r"\(").replace(")", r"\)")):
        avsplat.GaussianCloud(**a)


def test_validate_and_sanitize():
    a = make(n=5)
    a["opacities"][2] = 1.5
    a["means"][4, 0] = np.nan
    c = avsplat.GaussianCloud(**a)
    with pytest.raises(ValueError, match=r"GaussianCloud.opacities\[2\]"):
        c.validate()
    rep = c.sanitize()
    assert (rep.kept, rep.dropped, rep.non_finite, rep.opacity_range) == (3, 2, 1, 1)
    assert len(c) == 3
    np.testing.assert_array_equal(c.means, a["means"][[0, 1, 3]].astype(np.float32))
    c.validate()


def test_select_concatenate_covariance_extras():
    c = avsplat.GaussianCloud(**make(n=5, k=9, seed=3))
    s = c.select([4, 0])
    np.testing.assert_array_equal(s.sh, c.sh[[4, 0]])
    m = c.select_mask(np.array([True, False, True, False, False]))
    np.testing.assert_array_equal(m.means, c.means[[0, 2]])
    with pytest.raises(IndexError):
        c.select([7])
    d0 = avsplat.GaussianCloud(**make(n=2, k=1, seed=4))
    cat = avsplat.concatenate([d0, c])
    assert len(cat) == 7 and cat.sh_degree == 2
    np.testing.assert_array_equal(cat.sh[:2, 1:], 0)
    # Covariance against numpy: R diag(s^2) R^T with R from the normalised quaternion.
    q = c.rotations[1].astype(np.float64)
    w, x, y, z = q / np.linalg.norm(q)
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                  [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                  [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])
    S = np.diag(c.scales[1].astype(np.float64) ** 2)
    np.testing.assert_allclose(c.covariance(1), R @ S @ R.T, atol=1e-6)
    lo, hi = c.bounding_box()
    np.testing.assert_array_equal(lo, c.means.min(axis=0))
    np.testing.assert_array_equal(hi, c.means.max(axis=0))
    c.set_extra("label", np.arange(5))
    np.testing.assert_array_equal(c.extras["label"], np.arange(5, dtype=np.float32))
    with pytest.raises(ValueError, match="values: expected shape"):
        c.set_extra("bad", np.arange(3))
