"""Cameras for scenes that came without any: robust bounds, default framing, orbits, COLMAP."""

import struct

import numpy as np
import pytest

import avsplat


def box_scene(n=2000, floaters=10, seed=1):
    """Means uniform in [-1, 3] x [0, 1] x [2, 4], plus `floaters` points 800 units away."""
    rng = np.random.default_rng(seed)
    m = rng.uniform([-1, 0, 2], [3, 1, 4], size=(n + floaters, 3)).astype(np.float32)
    m[n:] = [500, -300, 800]
    k = len(m)
    return avsplat.GaussianCloud(m, np.full((k, 3), 0.02, np.float32), np.tile(np.float32([1, 0, 0, 0]), (k, 1)),
                                 np.full(k, 0.9, np.float32), np.full((k, 1, 3), 0.3, np.float32))


def project(cam, points):
    p = np.c_[points, np.ones(len(points))] @ cam.world_to_camera.T
    return np.c_[cam.fx * p[:, 0] / p[:, 2] + cam.cx, cam.fy * p[:, 1] / p[:, 2] + cam.cy, p[:, 2]]


def corners(lo, hi):
    return np.array([[(hi if k & (1 << a) else lo)[a] for a in range(3)] for k in range(8)])


def test_robust_bounds_match_numpy_percentiles():
    cloud = box_scene()
    lo, hi = avsplat.robust_bounds(cloud, 5.0, 95.0)
    m = np.asarray(cloud.means, np.float64)
    np.testing.assert_allclose(lo, np.percentile(m, 5, axis=0), rtol=1e-12)
    np.testing.assert_allclose(hi, np.percentile(m, 95, axis=0), rtol=1e-12)
    with pytest.raises(ValueError, match="percentiles"):
        avsplat.robust_bounds(cloud, 50, 10)


@pytest.mark.parametrize("width,height,fov", [(1024, 768, 50.0), (200, 600, 20.0), (1920, 400, 90.0)])
def test_default_camera_keeps_the_robust_box_in_the_image(width, height, fov):
    cloud = box_scene()
    cam = avsplat.default_camera(cloud, width=width, height=height, fov_y_degrees=fov)
    uvz = project(cam, corners(*avsplat.robust_bounds(cloud)))
    assert (uvz[:, 2] > cam.near).all()
    assert (uvz[:, 0] >= 0).all() and (uvz[:, 0] <= width).all()
    assert (uvz[:, 1] >= 0).all() and (uvz[:, 1] <= height).all()
    # The floaters are not framed: the camera is where it is without them, within sampling noise.
    clean = avsplat.default_camera(box_scene(floaters=0), width=width, height=height, fov_y_degrees=fov)
    assert np.linalg.norm(cam.position - clean.position) < 0.05 * np.linalg.norm(clean.position - [1, 0.5, 3])
    # Up is -y: the camera sits above the box (smaller y) at the default elevation.
    assert cam.position[1] < 0.5


def test_default_camera_renders_the_scene_in_the_middle_of_the_image():
    cloud = box_scene(floaters=0)
    cam = avsplat.default_camera(cloud, width=64, height=48)
    alpha = np.asarray(avsplat.render(cloud, cam).alpha)
    assert alpha[24, 32] > 0.5
    assert alpha[0, :].max() < 0.01 and alpha[:, 0].max() < 0.01  # borders stay empty


def test_orbit_cameras_share_target_distance_and_elevation():
    cloud = box_scene()
    cams = avsplat.orbit_cameras(cloud, 8, elevation_degrees=30.0, radius=5.0, target=(1.0, 0.5, 3.0))
    assert [c.name for c in cams] == [f"orbit_{k:03d}" for k in range(8)]
    pos = np.array([c.position for c in cams])
    np.testing.assert_allclose(np.linalg.norm(pos - [1, 0.5, 3], axis=1), 5.0, rtol=1e-12)
    np.testing.assert_allclose(pos[:, 1], 0.5 - 5.0 * np.sin(np.radians(30)), rtol=1e-12)
    # Azimuth 0 looks along +z; the camera 90 degrees on (index 2) looks along -x.
    np.testing.assert_allclose(cams[0].world_to_camera[2, :3], [0, np.sin(np.radians(30)), np.cos(np.radians(30))],
                               atol=1e-12)
    np.testing.assert_allclose(cams[2].world_to_camera[2, :3], [-np.cos(np.radians(30)), np.sin(np.radians(30)), 0],
                               atol=1e-12)
    with pytest.raises(ValueError, match="n must be"):
        avsplat.orbit_cameras(cloud, 0)


def test_look_at_up_is_the_image_up_direction():
    cam = avsplat.Camera.look_at(eye=(0, 0, -5), target=(0, 0, 0), up=(0, -1, 0), fov_y_degrees=60, width=100,
                                 height=100)
    # A point at smaller y (up for a y-down scene) is above the centre: smaller row.
    assert project(cam, np.array([[0.0, -1.0, 0.0]]))[0, 1] < 50
    np.testing.assert_allclose(cam.world_to_camera[:3, :3], np.eye(3), atol=1e-15)


def write_colmap_bin(d, cameras, images):
    with open(d / "cameras.bin", "wb") as f:
        f.write(struct.pack("<Q", len(cameras)))
        for cid, model, w, h, params in cameras:
            f.write(struct.pack("<iiQQ", cid, model, w, h) + struct.pack(f"<{len(params)}d", *params))
    with open(d / "images.bin", "wb") as f:
        f.write(struct.pack("<Q", len(images)))
        for iid, q, t, cid, name in images:
            f.write(struct.pack("<I7dI", iid, *q, *t, cid) + name.encode() + b"\0" + struct.pack("<Q", 0))


def test_read_colmap_cameras_binary_and_text_agree(tmp_path):
    # Hand-computed pose: q = (cos 45, sin 45, 0, 0), a quarter turn about x: R maps y to z.
    h = np.sqrt(0.5)
    R = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    (tmp_path / "bin").mkdir()
    write_colmap_bin(tmp_path / "bin", [(1, 1, 640, 480, [500, 520, 320, 240])],
                     [(1, (h, h, 0, 0), (0.5, -1, 2), 1, "a.png")])
    (tmp_path / "txt").mkdir()
    (tmp_path / "txt" / "cameras.txt").write_text("# comment\n1 PINHOLE 640 480 500 520 320 240\n")
    (tmp_path / "txt" / "images.txt").write_text(f"1 {h!r} {h!r} 0 0 0.5 -1 2 1 a.png\n1 2 -1\n")
    for d in ("bin", "txt"):
        (cam,) = avsplat.read_colmap_cameras(tmp_path / d)
        assert cam.name == "a.png" and (cam.fx, cam.fy, cam.cx, cam.cy, cam.width, cam.height) == (
            500, 520, 320, 240, 640, 480)
        np.testing.assert_allclose(cam.world_to_camera[:3, :3], R, atol=1e-15)
        np.testing.assert_allclose(cam.position, -R.T @ [0.5, -1, 2], atol=1e-15)
    (tmp_path / "txt" / "cameras.txt").write_text("1 OPENCV_FISHEYE 640 480 500 500 320 240 0 0 0 0\n")
    with pytest.raises(OSError, match=r"cameras.txt: line 1: camera 1 has model OPENCV_FISHEYE"):
        avsplat.read_colmap_cameras(tmp_path / "txt")
