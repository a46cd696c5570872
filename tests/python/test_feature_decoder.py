"""decode_gaussians / encode_gaussians (raw head features <-> Gaussians) against numpy, and the
raw-feature fusion path: fuse_voxels on raw features, then decode."""

import numpy as np
import pytest

import avsplat


def _numpy_decode(features, layout):
    f = features.astype(np.float64)
    opacity = 1.0 / (1.0 + np.exp(-f[:, layout.opacity]))
    scale = np.exp(f[:, layout.scale:layout.scale + 3])
    q = f[:, layout.rotation:layout.rotation + 4]
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    K = (layout.sh_degree + 1) ** 2
    sh = f[:, layout.sh:layout.sh + 3 * K].reshape(-1, K, 3)
    return opacity, scale, q, sh


@pytest.mark.parametrize("layout", [avsplat.FeatureLayout(),
                                    avsplat.FeatureLayout(opacity=13, scale=0, rotation=3, sh=7, sh_degree=0),
                                    avsplat.FeatureLayout(sh_degree=2)])
def test_decode_matches_numpy(layout):
    rng = np.random.default_rng(0)
    n, C = 500, layout.channels + 3
    features = rng.normal(0, 3, (n, C)).astype(np.float32)
    positions = rng.normal(0, 1, (n, 3)).astype(np.float32)
    conf = rng.normal(0, 1, n).astype(np.float32)
    g = avsplat.decode_gaussians(positions, features, layout, confidence=conf)
    opacity, scale, q, sh = _numpy_decode(features, layout)
    assert len(g) == n and g.sh_degree == layout.sh_degree
    np.testing.assert_array_equal(g.means, positions)
    np.testing.assert_allclose(g.opacities, opacity, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(g.scales, scale, rtol=1e-6)
    np.testing.assert_allclose(g.rotations, q, atol=1e-7)
    np.testing.assert_array_equal(g.sh, sh.astype(np.float32))
    np.testing.assert_array_equal(g.confidence, conf)


def test_extreme_logits_and_round_trip():
    layout = avsplat.FeatureLayout()
    f = np.zeros((4, layout.channels), np.float32)
    f[:, 4] = 1
    f[:, 0] = [-1e30, -100, 100, 1e30]
    f[:, 1:4] = [[-100, 0, 88.7]] * 4
    g = avsplat.decode_gaussians(np.zeros((4, 3)), f)
    np.testing.assert_allclose(g.opacities, [0, 1 / (1 + np.exp(100.0)), 1, 1], rtol=1e-6, atol=1e-44)  # subnormal
    assert np.all(np.isfinite(g.scales)) and g.confidence is None
    # encode is the inverse on valid Gaussians.
    rng = np.random.default_rng(1)
    n = 200
    cloud = avsplat.GaussianCloud(rng.normal(size=(n, 3)), np.exp(rng.normal(size=(n, 3))),
                                  rng.normal(size=(n, 4)), rng.uniform(0.01, 0.99, n), rng.normal(size=(n, 1, 3)))
    enc = avsplat.encode_gaussians(cloud)
    assert enc.shape == (n, layout.channels) and enc.dtype == np.float32
    back = avsplat.decode_gaussians(cloud.means, enc)
    np.testing.assert_allclose(back.opacities, cloud.opacities, rtol=1e-5)
    np.testing.assert_allclose(back.scales, cloud.scales, rtol=1e-5)
    q = cloud.rotations / np.linalg.norm(cloud.rotations, axis=1, keepdims=True)
    np.testing.assert_allclose(back.rotations, q, atol=1e-6)
    np.testing.assert_array_equal(back.sh, cloud.sh)


def test_bad_input_names_the_sample():
    layout = avsplat.FeatureLayout()
    f = np.zeros((5, layout.channels), np.float32)
    f[:, 4] = 1
    p = np.zeros((5, 3), np.float32)
    bad = f.copy(); bad[3, 2] = np.nan
    with pytest.raises(ValueError, match=r"features\[3, 2\]"):
        avsplat.decode_gaussians(p, bad)
    bad = f.copy(); bad[2, 1] = 89.0
    with pytest.raises(ValueError, match=r"features\[2, 1\].*overflow"):
        avsplat.decode_gaussians(p, bad)
    bad = f.copy(); bad[1, 4:8] = 0
    with pytest.raises(ValueError, match=r"features\[1, 4..7\].*zero"):
        avsplat.decode_gaussians(p, bad)
    with pytest.raises(ValueError, match="channels"):
        avsplat.decode_gaussians(p, f[:, :10])
    with pytest.raises(ValueError, match="features"):
        avsplat.decode_gaussians(p, f[:4])
    with pytest.raises(ValueError, match="overlap"):
        avsplat.FeatureLayout(opacity=2)
    with pytest.raises(ValueError, match="sh_degree"):
        avsplat.FeatureLayout(sh_degree=4)
    with pytest.raises(ValueError, match="SH degree"):
        avsplat.encode_gaussians(avsplat.GaussianCloud(np.zeros((1, 3)), np.ones((1, 3)), [[1, 0, 0, 0]], [0.5],
                                                       np.zeros((1, 4, 3))))


def test_fuse_raw_features_then_decode_against_numpy():
    """The AnySplat / AVSplat order: average the raw features per voxel, then decode. With the mean
    policy each voxel's fused Gaussian is the decode of the plain mean of its raw features: the
    sigmoid of the mean logit, the geometric mean of the scales."""
    rng = np.random.default_rng(2)
    n = 3000
    pos = rng.uniform(0, 1, (n, 3)).astype(np.float32)
    layout = avsplat.FeatureLayout()
    feat = rng.normal(0, 1, (n, layout.channels)).astype(np.float32)
    feat[:, 4] += 3  # quaternions near identity, so their mean is far from zero
    r = avsplat.fuse_voxels(pos, feat, 0.1, policy="mean")
    g = avsplat.decode_gaussians(r.positions, r.features, layout)
    keys = np.round(pos.astype(np.float64) / 0.1).astype(np.int64)
    _, inverse = np.unique(keys, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    mean = np.zeros((inverse.max() + 1, layout.channels))
    np.add.at(mean, inverse, feat.astype(np.float64))
    mean /= np.bincount(inverse)[:, None]
    opacity, scale, q, sh = _numpy_decode(mean, layout)
    np.testing.assert_allclose(g.opacities, opacity, rtol=2e-6, atol=1e-7)
    np.testing.assert_allclose(g.scales, scale, rtol=2e-6)
    np.testing.assert_allclose(g.rotations, q, atol=1e-6)
    np.testing.assert_allclose(g.sh[:, 0, :], sh[:, 0, :], atol=1e-6)
    # Raw fusion differs from fusing decoded Gaussians: the mean of opacities is not the sigmoid of
    # the mean logit.
    decoded = avsplat.fuse_gaussians(avsplat.decode_gaussians(pos, feat, layout), 0.1, policy="mean")
    assert np.abs(decoded.cloud.opacities - g.opacities).max() > 0.05


def test_simulated_features_decode_to_the_per_pixel_gaussians():
    p = avsplat.simulate_predictions(views=2, width=40, height=30, target_views=1)
    a, b = p.gaussians(), p.decoded_gaussians()
    assert p.feature_layout.channels == p.features.shape[-1] == 11
    np.testing.assert_array_equal(a.means, b.means)
    np.testing.assert_allclose(b.opacities, a.opacities, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(b.scales, a.scales, rtol=1e-5)
    np.testing.assert_allclose(np.abs(np.sum(b.rotations * a.rotations / np.linalg.norm(a.rotations, axis=1,
                                                                                          keepdims=True), axis=1)),
                               1, atol=1e-6)
    np.testing.assert_allclose(b.sh, a.sh, atol=1e-6)
