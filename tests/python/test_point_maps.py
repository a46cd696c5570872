import numpy as np
import pytest

import avsplat


def brute_nearest(a, b):
    d = np.linalg.norm(a[:, None, :].astype(np.float64) - b[None, :, :].astype(np.float64), axis=2)
    return d.min(axis=1)


def test_knn_scale_matches_numpy_brute_force():
    rng = np.random.default_rng(0)
    p = rng.uniform(-1, 1, size=(300, 3)).astype(np.float32)
    g = avsplat.gaussians_from_point_maps(p, np.full_like(p, 0.5), k=4, flat=False, scale_multiplier=1.0)
    d2 = ((p[:, None, :].astype(np.float64) - p[None].astype(np.float64)) ** 2).sum(axis=2)
    d2.sort(axis=1)
    expected = np.sqrt(d2[:, 1:5].mean(axis=1))  # column 0 is the point itself
    np.testing.assert_allclose(g.scales, np.repeat(expected[:, None], 3, axis=1), rtol=1e-5)
    np.testing.assert_array_equal(g.means, p)


def test_image_layout_cameras_and_valid_mask():
    # A fronto-parallel plane at depth 2 seen by a camera at the origin looking along +z.
    f, w, h, z = 20.0, 6, 4, 2.0
    cam = avsplat.Camera(f, f, w / 2, h / 2, w, h)
    u, v = np.meshgrid(np.arange(w) + 0.5, np.arange(h) + 0.5)
    pts = np.stack([(u - w / 2) / f * z, (v - h / 2) / f * z, np.full_like(u, z)], axis=-1)[None]
    colors = np.full_like(pts, 0.25)
    valid = np.ones((1, h, w), bool)
    valid[0, 1, 2] = False
    normals = np.broadcast_to(np.array([0.0, 0.0, 1.0]), pts.shape)
    g = avsplat.gaussians_from_point_maps(pts, colors, cameras=[cam], normals=normals, valid=valid)
    assert len(g) == h * w - 1
    np.testing.assert_allclose(g.means, pts[valid], rtol=1e-6)
    # Half the in-plane footprint z / f (the default multiplier), stretched by 1 / cos along the
    # slant of the ray.
    cos = z / np.linalg.norm(pts[valid], axis=1)
    np.testing.assert_allclose(g.scales[:, 1], 0.5 * z / f, rtol=1e-5)
    np.testing.assert_allclose(g.scales[:, 0], 0.5 * z / f / cos, rtol=1e-5)
    np.testing.assert_allclose(g.scales[:, 2], 0.05 * z / f, rtol=1e-5)
    np.testing.assert_allclose(0.5 + 0.28209479177387814 * g.sh[:, 0, :], 0.25, atol=1e-6)
    assert g.confidence is None


def test_confidence_becomes_opacity_and_is_kept():
    rng = np.random.default_rng(1)
    p = rng.normal(size=(50, 3))
    c = rng.normal(size=50)
    g = avsplat.gaussians_from_point_maps(p, np.zeros_like(p), confidence=c)
    np.testing.assert_allclose(g.opacities, 1 / (1 + np.exp(-c)), rtol=1e-6)
    np.testing.assert_allclose(g.confidence, c.astype(np.float32))
    pos = np.abs(c) + 0.1
    g = avsplat.gaussians_from_point_maps(p, np.zeros_like(p), confidence=pos, confidence_mapping="positive")
    np.testing.assert_allclose(g.opacities, pos / (1 + pos), rtol=1e-6)
    g = avsplat.gaussians_from_point_maps(p, np.zeros_like(p), default_opacity=0.3)
    np.testing.assert_allclose(g.opacities, 0.3)


def test_point_map_errors_name_the_argument():
    p = np.zeros((10, 3), np.float32)
    with pytest.raises(ValueError, match=r"points: expected shape \(S, H, W, 3\) or \(N, 3\)"):
        avsplat.gaussians_from_point_maps(np.zeros((2, 5, 3)), p)
    with pytest.raises(ValueError, match=r"points: expected shape \(N, 3\), got \(10, 2\)"):
        avsplat.gaussians_from_point_maps(np.zeros((10, 2)), p)
    with pytest.raises(ValueError, match=r"colors: expected shape \(N, 3\), got \(9, 3\)"):
        avsplat.gaussians_from_point_maps(p, np.zeros((9, 3)))
    with pytest.raises(ValueError, match=r"confidence: expected shape \(N\)"):
        avsplat.gaussians_from_point_maps(p, p, confidence=np.zeros(3))
    with pytest.raises(ValueError, match="confidence_mapping"):
        avsplat.gaussians_from_point_maps(p, p, confidence_mapping="sigmoid")
    bad = np.random.default_rng(2).normal(size=(10, 3))
    bad[4, 1] = np.nan
    with pytest.raises(ValueError, match=r"points\[4\] \(view 0, row 0, col 4\) is not finite"):
        avsplat.gaussians_from_point_maps(bad, p)


def test_outlier_removal_matches_open3d():
    o3d = pytest.importorskip("open3d")
    rng = np.random.default_rng(3)
    p = np.concatenate([rng.normal(size=(400, 3)), rng.normal(size=(20, 3)) * 4]).astype(np.float32)
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(p.astype(np.float64)))
    for nb, ratio in [(5, 0.5), (20, 2.0), (8, 1.0)]:
        _, expected = pcd.remove_statistical_outlier(nb_neighbors=nb, std_ratio=ratio)
        kept, idx = avsplat.remove_statistical_outliers(p, nb_neighbors=nb, std_ratio=ratio)
        np.testing.assert_array_equal(idx, np.asarray(expected))
        np.testing.assert_array_equal(kept, p[idx])
        assert idx.dtype == np.int64


def test_outlier_removal_of_a_cloud_keeps_the_cloud_type():
    rng = np.random.default_rng(4)
    p = np.concatenate([rng.normal(size=(200, 3)), [[30.0, 30.0, 30.0]]])
    cloud = avsplat.gaussians_from_point_maps(p, np.zeros_like(p))
    kept, idx = avsplat.remove_statistical_outliers(cloud, nb_neighbors=10, std_ratio=2.0)
    assert isinstance(kept, avsplat.GaussianCloud)
    assert 200 not in idx and len(kept) == len(idx)
    np.testing.assert_array_equal(kept.means, cloud.means[idx])


def test_distances_match_numpy_brute_force():
    rng = np.random.default_rng(5)
    a = rng.uniform(-1, 1, size=(250, 3)).astype(np.float32)
    b = rng.uniform(-0.5, 1.5, size=(180, 3)).astype(np.float32)
    ab, ba = brute_nearest(a, b), brute_nearest(b, a)
    np.testing.assert_allclose(avsplat.compute_point_cloud_distance(a, b), ab, rtol=1e-6)
    r = avsplat.accuracy_completeness(a, b, threshold=0.1)
    assert r.accuracy == pytest.approx(ab.mean(), rel=1e-9)
    assert r.completeness == pytest.approx(ba.mean(), rel=1e-9)
    assert r.chamfer == pytest.approx((ab.mean() + ba.mean()) / 2, rel=1e-9)
    P, R = (ab < 0.1).mean(), (ba < 0.1).mean()
    assert r.precision == pytest.approx(P) and r.recall == pytest.approx(R)
    assert r.fscore == pytest.approx(2 * P * R / (P + R))
    assert avsplat.chamfer_distance(a, b) == pytest.approx(r.chamfer, rel=1e-12)
    assert "AccuracyCompleteness(accuracy=" in repr(r)


def test_distance_errors():
    a = np.zeros((3, 3), np.float32)
    with pytest.raises(ValueError, match="threshold"):
        avsplat.accuracy_completeness(a, a, threshold=-1.0)
    with pytest.raises(ValueError, match="empty"):
        avsplat.chamfer_distance(a, np.zeros((0, 3)))
    with pytest.raises(ValueError, match=r"b: expected shape \(N, 3\)"):
        avsplat.chamfer_distance(a, np.zeros((4, 2)))
