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
