"""The enum words (core/names.h) are the same in every binding: each valid word is accepted, and a
bad word is a ValueError naming the argument and listing every valid word."""

import numpy as np
import pytest

import avsplat

# The words as the docstrings and the command line spell them, written out here by hand.
WORDS = {
    "policy": ["mean", "softmax", "occupancy"],
    "weights": ["softmax", "sparsemax"],
    "confidence_mapping": ["logit", "probability", "positive"],
    "precision": ["float32", "float64"],
    "on_invalid": ["raise", "drop"],
}


def fuse(**kw):
    pos = np.array([[0.1, 0.1, 0.1], [0.2, 0.2, 0.2]], np.float32)
    feat = np.eye(2, dtype=np.float32)
    return avsplat.fuse_voxels(pos, feat, 1.0, confidence=np.array([0.25, 0.75], np.float32), **kw)


@pytest.mark.parametrize("knob", sorted(WORDS))
def test_fusion_words(knob):
    for word in WORDS[knob]:
        assert len(fuse(**{knob: word})) == 1
    with pytest.raises(ValueError) as e:
        fuse(**{knob: "bogus"})
    message = str(e.value)
    assert message.startswith(f"{knob}: 'bogus' is not one of")
    assert message.endswith(", ".join(f"'{w}'" for w in WORDS[knob]))


def test_shape_words():
    rng = np.random.default_rng(1)
    cloud = avsplat.GaussianCloud(rng.uniform(0, 1, (8, 3)).astype(np.float32), np.full((8, 3), 0.1, np.float32),
                                  np.tile(np.array([1, 0, 0, 0], np.float32), (8, 1)), np.full(8, 0.5, np.float32),
                                  np.zeros((8, 1, 3), np.float32))
    for word in ("average", "moment"):
        assert len(avsplat.fuse_gaussians(cloud, 10.0, shape=word)) == 1
    with pytest.raises(ValueError, match="shape: 'round' is not one of 'average', 'moment'"):
        avsplat.fuse_gaussians(cloud, 10.0, shape="round")


def test_render_words():
    cam = avsplat.Camera(10.0, 10.0, 4.0, 4.0, 8, 8)
    cloud = avsplat.GaussianCloud(np.array([[0, 0, 2]], np.float32), np.full((1, 3), 0.1, np.float32),
                                  np.array([[1, 0, 0, 0]], np.float32), np.array([0.5], np.float32),
                                  np.zeros((1, 1, 3), np.float32))
    a = avsplat.render(cloud, cam, precision="float32").color
    b = avsplat.render(cloud, cam, precision="float64").color
    assert np.abs(a - b).max() < 1e-5
    with pytest.raises(ValueError, match="backend: 'gpu' is not one of 'cpu', 'cuda'"):
        avsplat.render(cloud, cam, backend="gpu")
    with pytest.raises(ValueError, match="precision: 'half' is not one of 'float32', 'float64'"):
        avsplat.render(cloud, cam, precision="half")


def test_defaults_are_the_library_structs():
    # RenderOptions{} and FusionParams{} as render.h and fusion.h state them, written out by hand.
    r = avsplat.defaults["render"]
    assert r["backend"] == "cpu" and r["precision"] == "float32" and r["antialiased"] is False
    assert r["background"] == (0.0, 0.0, 0.0)
    assert r["low_pass"] == pytest.approx(0.3) and r["alpha_threshold"] == pytest.approx(1 / 255)
    assert r["transmittance_stop"] == pytest.approx(1e-4) and r["extent_sigma"] == 3.0
    f = avsplat.defaults["fusion"]
    assert f == pytest.approx(dict(policy="occupancy", tau0=0.7, alpha=0.5, n_ref=8.0, tau_min=0.15, tau_max=2.0,
                                   b_conf=1.0, b_geo=2.0, k_rel=1.0, eps=1e-6, trim_mass=0.8, weights="softmax",
                                   confidence_mapping="logit", shape="average", on_invalid="raise",
                                   precision="float32"))
    # The keyword defaults of the functions are these values: passing them changes nothing.
    cam = avsplat.Camera(10.0, 10.0, 4.0, 4.0, 8, 8)
    rng = np.random.default_rng(2)
    cloud = avsplat.GaussianCloud(rng.uniform(-0.5, 0.5, (20, 3)).astype(np.float32) + np.float32([0, 0, 2]),
                                  np.full((20, 3), 0.1, np.float32), np.tile(np.float32([1, 0, 0, 0]), (20, 1)),
                                  np.full(20, 0.5, np.float32), rng.normal(size=(20, 1, 3)).astype(np.float32))
    assert np.array_equal(avsplat.render(cloud, cam).color, avsplat.render(cloud, cam, **r).color)
    pos = rng.uniform(0, 1, (50, 3)).astype(np.float32)
    feat = rng.normal(size=(50, 2)).astype(np.float32)
    conf = rng.normal(size=50).astype(np.float32)
    knobs = {k: v for k, v in f.items() if k != "shape"}
    a = avsplat.fuse_voxels(pos, feat, 0.3, confidence=conf)
    b = avsplat.fuse_voxels(pos, feat, 0.3, confidence=conf, **knobs)
    assert np.array_equal(a.features, b.features)
    # The docstring states the same numbers (generated from FusionParams).
    assert f"tau0={f['tau0']:g}" in avsplat.fuse_voxels.__doc__
