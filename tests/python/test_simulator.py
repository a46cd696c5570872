import numpy as np
import pytest

import avsplat

if not hasattr(avsplat, "simulate_predictions"):
    pytest.skip("avsplat built without Open3D (no simulator)", allow_module_level=True)

SMALL = dict(views=3, width=40, height=30, target_views=2)


def test_shapes_dtypes_and_views():
    p = avsplat.simulate_predictions(**SMALL)
    S, H, W = 3, 30, 40
    for name, shape, dtype in [
        ("points", (S, H, W, 3), np.float32),
        ("colors", (S, H, W, 3), np.float32),
        ("confidence", (S, H, W), np.float32),
        ("true_error", (S, H, W), np.float32),
        ("true_points", (S, H, W, 3), np.float32),
        ("normals", (S, H, W, 3), np.float32),
        ("valid", (S, H, W), np.bool_),
        ("object_id", (S, H, W), np.int32),
    ]:
        a = getattr(p, name)
        assert a.shape == shape and a.dtype == dtype, name
    assert len(p.cameras) == S and len(p.true_cameras) == S and len(p.target_cameras) == 2
    assert (p.views, p.height, p.width) == (S, H, W)
    v = p.valid
    assert 0.5 < v.mean() < 1.0
    np.testing.assert_array_equal(v, p.object_id >= 0)
    np.testing.assert_allclose(np.linalg.norm(p.normals[v], axis=1), 1.0, atol=1e-5)
    assert np.all(p.colors >= 0) and np.all(p.colors <= 1)
    # The error is the distance between predicted and true points.
    np.testing.assert_allclose(p.true_error[v], np.linalg.norm(p.points[v] - p.true_points[v], axis=1), atol=1e-6)
    assert repr(p).startswith("Predictions(views=3, 40x30, valid=")


def test_deterministic_for_a_seed():
    a = avsplat.simulate_predictions(seed=7, **SMALL)
    b = avsplat.simulate_predictions(seed=7, **SMALL)
    c = avsplat.simulate_predictions(seed=8, **SMALL)
    for name in ("points", "colors", "confidence", "true_error", "normals", "valid"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert not np.array_equal(a.points, c.points)
    np.testing.assert_array_equal(a.valid, c.valid)


def test_noise_free_predictions_are_the_true_points():
    p = avsplat.simulate_predictions(pose_noise_rot_deg=0, pose_noise_trans=0, depth_noise=0,
                                     flying_pixels=False, **SMALL)
    v = p.valid
    np.testing.assert_allclose(p.points[v], p.true_points[v], atol=1e-6)
    assert p.true_error[v].max() < 1e-6
    ground = p.object_id == int(avsplat.SceneObject.Ground)
    np.testing.assert_allclose(p.points[ground][:, 2], 0.0, atol=1e-6)
    for pred, true in zip(p.cameras, p.true_cameras):
        np.testing.assert_array_equal(pred.world_to_camera, true.world_to_camera)


def test_confidence_ranks_like_the_error():
    p = avsplat.simulate_predictions(views=4, width=64, height=48, target_views=3)
    v = p.valid
    conf, err = p.confidence[v], p.true_error[v]

    def ranks(x):
        r = np.empty(len(x))
        r[np.argsort(x, kind="stable")] = np.arange(len(x))
        return r

    rho = np.corrcoef(ranks(conf), ranks(-err))[0, 1]
    assert 0.3 < rho < 0.99


def test_gaussians_one_per_valid_pixel():
    p = avsplat.simulate_predictions(**SMALL)
    g = p.gaussians()
    assert len(g) == p.valid.sum()
    np.testing.assert_array_equal(g.means, p.points[p.valid])
    np.testing.assert_array_equal(g.confidence, p.confidence[p.valid])
    np.testing.assert_allclose(g.opacities, 1 / (1 + np.exp(-p.confidence[p.valid].astype(np.float64))), rtol=1e-5)
    # Keyword arguments are those of gaussians_from_point_maps.
    wider = p.gaussians(scale_multiplier=1.0)  # the default is 0.5
    np.testing.assert_allclose(wider.scales[:, 1], 2 * g.scales[:, 1], rtol=1e-6)
    with pytest.raises(TypeError):
        p.gaussians(no_such_option=1)


def test_ground_truth_render():
    cams = avsplat.target_cameras(views=5, width=48, height=36, target_views=2)
    assert len(cams) == 2
    gt = avsplat.ground_truth(cams[0], supersample=1, background=(0.1, 0.2, 0.3))
    assert gt.color.shape == (36, 48, 3) and gt.depth.shape == (36, 48) and gt.alpha.shape == (36, 48)
    assert gt.normals.shape == (36, 48, 3) and gt.object_id.dtype == np.int32
    miss = gt.object_id < 0
    assert miss.any() and (~miss).any()
    np.testing.assert_allclose(gt.color[miss], np.broadcast_to([0.1, 0.2, 0.3], (miss.sum(), 3)), atol=1e-7)
    assert np.all(gt.depth[miss] == 0) and np.all(gt.alpha[miss] == 0) and np.all(gt.alpha[~miss] == 1)
    # Colours are the scene's texture at the hit points (rebuilt from depth; a pixel right on a
    # texture edge may flip, so a few are allowed to differ).
    c = cams[0]
    rows, cols = np.nonzero(~miss)
    rays = np.stack([(cols + 0.5 - c.cx) / c.fx, (rows + 0.5 - c.cy) / c.fy, np.ones(len(rows))], axis=1)
    hits = c.position + (rays * gt.depth[rows, cols][:, None]) @ c.world_to_camera[:3, :3]
    expected = avsplat.scene_color(hits, gt.object_id[rows, cols])
    same = np.all(np.abs(expected - gt.color[rows, cols]) < 1e-5, axis=1)
    assert same.mean() > 0.99
    assert "GroundTruthImage(48x36)" == repr(gt)


def test_bunny_mesh_matches_the_committed_file():
    o3d = pytest.importorskip("open3d")
    import os

    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    mesh = o3d.io.read_triangle_mesh(os.path.join(root, "lib", "data", "bunny.ply"))
    v, f = avsplat.bunny_mesh()
    np.testing.assert_allclose(v, np.asarray(mesh.vertices) - [0, 0, 0.01], atol=1e-6)
    np.testing.assert_array_equal(f, np.asarray(mesh.triangles))


def test_bad_options_raise_value_error():
    with pytest.raises(ValueError, match="SimulatorOptions.views"):
        avsplat.simulate_predictions(views=0)
    with pytest.raises(ValueError, match="SimulatorOptions.target_views"):
        avsplat.target_cameras(views=3, target_views=3)
    with pytest.raises(ValueError, match=r"background: expected shape \(3\)"):
        avsplat.simulate_predictions(background=(0, 0), **SMALL)
    with pytest.raises(ValueError, match="not a scene object"):
        avsplat.scene_color(np.zeros((1, 3)), np.array([-1]))
