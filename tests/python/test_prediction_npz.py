"""avsplat.read_prediction_npz, the one reader of the prediction .npz layout (the CLI's `fuse`, the
Python API and avsplat.dask share it), against numpy's own view of the same arrays."""
import numpy as np
import pytest

import avsplat

C0 = 0.28209479177387814


def arrays(shape=(2, 3, 4), channels=5, seed=0):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=shape + (3,)).astype(np.float32)
    valid = rng.uniform(size=shape) > 0.3
    confidence = rng.normal(size=shape).astype(np.float32)
    features = rng.normal(size=shape + (channels,)).astype(np.float32)
    return points, valid, confidence, features


def test_raw_features_keep_the_valid_pixels_in_order(tmp_path):
    points, valid, confidence, features = arrays()
    path = tmp_path / "features.npz"
    np.savez_compressed(path, points=points, valid=valid, confidence=confidence, features=features.astype(np.float64))
    samples = avsplat.read_prediction_npz(path)
    assert samples.kind == "features" and samples.gaussians is None
    np.testing.assert_array_equal(samples.positions, points[valid])
    np.testing.assert_array_equal(samples.features, features[valid])
    np.testing.assert_array_equal(samples.confidence, confidence[valid])
    assert len(samples) == valid.sum()
    assert samples.description == "raw features (2 x 3 x 4, C = 5)"
    assert repr(samples) == f"PredictionSamples({valid.sum()} samples: raw features (2 x 3 x 4, C = 5))"


def test_per_pixel_gaussians_with_colors_become_sh_degree_zero(tmp_path):
    points, valid, confidence, _ = arrays(shape=(7,))
    rng = np.random.default_rng(1)
    scales = rng.uniform(0.01, 0.1, (7, 3)).astype(np.float32)
    q = rng.normal(size=(7, 4)).astype(np.float32)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    opacities = rng.uniform(0, 1, 7).astype(np.float32)
    colors = rng.uniform(0, 1, (7, 3)).astype(np.float32)
    path = tmp_path / "gaussians.npz"
    np.savez(path, points=points, valid=valid, confidence=confidence, scales=scales, rotations=q,
             opacities=opacities, colors=colors)
    samples = avsplat.read_prediction_npz(str(path))
    cloud = samples.gaussians
    assert samples.kind == "gaussians" and samples.positions is None and samples.features is None
    np.testing.assert_array_equal(cloud.means, points[valid])
    np.testing.assert_array_equal(cloud.scales, scales[valid])
    np.testing.assert_array_equal(cloud.rotations, q[valid])
    np.testing.assert_array_equal(cloud.opacities, opacities[valid])
    np.testing.assert_allclose(cloud.sh[:, 0, :], (colors[valid] - 0.5) / C0, rtol=1e-6)
    np.testing.assert_array_equal(cloud.confidence, confidence[valid])


def test_point_maps_go_through_gaussians_from_point_maps(tmp_path):
    points, valid, confidence, _ = arrays(shape=(1, 6, 8))
    colors = np.full(points.shape, 0.25, np.float32)
    path = tmp_path / "maps.npz"
    np.savez(path, points=points, valid=valid, confidence=confidence, colors=colors)
    samples = avsplat.read_prediction_npz(path)
    want = avsplat.gaussians_from_point_maps(points, colors, confidence, valid=valid)
    np.testing.assert_array_equal(samples.gaussians.means, want.means)
    np.testing.assert_array_equal(samples.gaussians.scales, want.scales)
    assert "point maps (1 x 6 x 8, kNN scale)" == samples.description


@pytest.mark.parametrize("content, message", [
    (dict(colors=np.zeros((4, 3))), "no array 'points'"),
    (dict(points=np.zeros((4, 2))), "array 'points' has shape (4, 2), expected (S, H, W, 3) or (N, 3)"),
    (dict(points=np.zeros((4, 3)), features=np.zeros((5, 2))), "array 'features' has shape (5, 2)"),
    (dict(points=np.zeros((4, 3)), scales=np.ones((4, 3))), "no array 'rotations'"),
    (dict(points=np.zeros((4, 3))), "'points' alone is not enough"),
])
def test_bad_layouts_name_the_file_and_the_array(tmp_path, content, message):
    path = tmp_path / "bad.npz"
    np.savez(path, **content)
    with pytest.raises(avsplat.FileError) as error:
        avsplat.read_prediction_npz(path)
    assert str(path) in str(error.value) and message in str(error.value)
