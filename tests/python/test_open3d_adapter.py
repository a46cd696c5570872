import numpy as np
import open3d as o3d
import pytest

import avsplat


def cloud(n=6, k=9, seed=0):
    rng = np.random.default_rng(seed)
    c = avsplat.GaussianCloud(rng.normal(size=(n, 3)), rng.uniform(0.1, 1, (n, 3)), rng.normal(size=(n, 4)),
                              rng.uniform(0.05, 0.95, n), rng.normal(size=(n, k, 3)), confidence=rng.normal(size=n))
    c.set_extra("depth_error", rng.uniform(size=n))
    return c


def test_to_open3d_names_shapes_and_encodings():
    c = cloud()
    pcd = c.to_open3d(layout="packed")
    assert isinstance(pcd, o3d.t.geometry.PointCloud)
    shapes = {k: tuple(pcd.point[k].shape) for k in ("positions", "scale", "rot", "opacity", "f_dc", "f_rest", "confidence", "depth_error")}
    assert shapes == {"positions": (6, 3), "scale": (6, 3), "rot": (6, 4), "opacity": (6, 1), "f_dc": (6, 3),
                      "f_rest": (6, 8, 3), "confidence": (6, 1), "depth_error": (6, 1)}
    logit = pcd.point["opacity"].numpy()[:, 0].astype(np.float64)
    np.testing.assert_allclose(1 / (1 + np.exp(-logit)), c.opacities, rtol=1e-6)
    np.testing.assert_array_equal(pcd.point["f_rest"].numpy(), c.sh[:, 1:, :])


@pytest.mark.parametrize("layout", ["ply", "packed"])
def test_round_trip_through_open3d(layout):
    c = cloud(k=16)
    back = avsplat.from_open3d(c.to_open3d(layout), extra_keys=["confidence", "depth_error"])
    assert back.sh_degree == 3
    for name in ("means", "rotations", "sh", "confidence"):
        np.testing.assert_array_equal(getattr(back, name), getattr(c, name))
    np.testing.assert_allclose(back.scales, c.scales, rtol=1e-6)  # exp(log) in the ply layout
    np.testing.assert_allclose(back.opacities, c.opacities, rtol=1e-6)
    np.testing.assert_array_equal(back.extras["depth_error"], c.extras["depth_error"])
    d0 = cloud(k=1)
    assert "f_rest" not in d0.to_open3d(layout).point and "f_rest_0" not in d0.to_open3d(layout).point
    assert avsplat.GaussianCloud.from_open3d(d0.to_open3d(layout)).sh_degree == 0


def test_ply_layout_is_the_3dgs_file_encoding():
    c = cloud(k=4)
    pcd = c.to_open3d()
    # Channel-major f_rest as the INRIA file: f_rest_{c (K-1) + k} holds coefficient k + 1 of channel c.
    np.testing.assert_array_equal(pcd.point["f_rest_4"].numpy()[:, 0], c.sh[:, 2, 1])
    np.testing.assert_allclose(np.exp(pcd.point["scale_2"].numpy()[:, 0].astype(np.float64)), c.scales[:, 2], rtol=1e-6)
    np.testing.assert_array_equal(pcd.point["rot_0"].numpy()[:, 0], c.rotations[:, 0])
    with pytest.raises(ValueError, match="layout"):
        c.to_open3d("flat")


@pytest.mark.parametrize("k", [1, 4, 16])
def test_from_open3d_reads_what_open3ds_reader_returns_for_a_3dgs_ply(tmp_path, k):
    c = cloud(n=50, k=k, seed=k)
    path = tmp_path / "scene.ply"
    avsplat.write_ply(path, c)
    pcd = o3d.t.io.read_point_cloud(str(path))  # Open3D's own reader, not ours
    back = avsplat.from_open3d(pcd, extra_keys=["confidence"])
    ref = avsplat.read_ply(path)
    assert back.sh_degree == ref.sh_degree
    for name in ("means", "rotations", "sh", "confidence"):
        np.testing.assert_array_equal(getattr(back, name), getattr(ref, name), err_msg=name)
    np.testing.assert_allclose(back.scales, ref.scales, rtol=1e-6)
    np.testing.assert_allclose(back.opacities, ref.opacities, rtol=1e-6)


@pytest.mark.parametrize("k", [1, 9])
def test_open3ds_writer_writes_what_to_open3d_returns(tmp_path, k):
    c = cloud(n=40, k=k, seed=3)
    path = tmp_path / "from_open3d.ply"
    assert o3d.t.io.write_point_cloud(str(path), c.to_open3d())  # Open3D's own writer
    back = avsplat.read_ply(path)  # a 3DGS PLY file: our reader finds every field by its name
    assert len(back) == len(c) and back.sh_degree == c.sh_degree
    for name in ("means", "rotations", "sh", "confidence"):
        np.testing.assert_array_equal(getattr(back, name), getattr(c, name), err_msg=name)
    np.testing.assert_allclose(back.scales, c.scales, rtol=1e-6)
    np.testing.assert_allclose(back.opacities, c.opacities, rtol=1e-6)
    np.testing.assert_array_equal(back.extras["depth_error"], c.extras["depth_error"])


def test_from_open3d_errors_name_the_attribute():
    pcd = cloud().to_open3d(layout="packed")
    pcd.point["rot"] = o3d.core.Tensor(np.zeros((6, 3), np.float32))
    with pytest.raises(ValueError, match="'rot'"):
        avsplat.from_open3d(pcd)
    pcd = o3d.t.geometry.PointCloud()
    with pytest.raises(ValueError, match="'positions'"):
        avsplat.from_open3d(pcd)


def test_legacy_preview_colours():
    c = cloud(k=1)
    legacy = c.to_open3d_legacy()
    np.testing.assert_allclose(np.asarray(legacy.points), c.means, rtol=0)
    expect = np.clip(0.5 + 0.28209479177387814 * c.sh[:, 0, :].astype(np.float64), 0, 1)
    np.testing.assert_allclose(np.asarray(legacy.colors), expect, atol=1e-12)


def test_splat_and_extension_dispatch(tmp_path):
    c = cloud(k=4)
    avsplat.write_gaussians(tmp_path / "a.splat", c)
    back = avsplat.read_gaussians(tmp_path / "a.splat")
    assert len(back) == len(c) and back.sh_degree == 0
    # Records are sorted by volume * opacity; compare as sets of positions.
    np.testing.assert_array_equal(np.sort(back.means, axis=0), np.sort(c.means, axis=0))
    assert (raw := (tmp_path / "a.splat").read_bytes()) and len(raw) == 32 * len(c)
    with pytest.raises(OSError, match="unsupported extension"):
        avsplat.write_gaussians(tmp_path / "a.obj", c)
