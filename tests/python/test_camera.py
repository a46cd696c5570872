import numpy as np
import pytest

import avsplat


def test_camera_defaults_and_projection_convention():
    cam = avsplat.Camera(100.0, 110.0, 32.0, 24.0, 64, 48)
    np.testing.assert_array_equal(cam.world_to_camera, np.eye(4))
    assert cam.near == 0.01 and cam.far == 1e10
    assert "Camera(64x48" in repr(cam)


def test_look_at_matches_numpy_projection():
    eye, target = np.array([1.0, -2.0, 0.5]), np.zeros(3)
    cam = avsplat.Camera.look_at(eye, target, [0, 0, 1], 50.0, 320, 240)
    np.testing.assert_allclose(cam.position, eye, atol=1e-12)
    p = cam.world_to_camera @ np.array([0, 0, 0, 1.0])
    u = cam.fx * p[0] / p[2] + cam.cx
    v = cam.fy * p[1] / p[2] + cam.cy
    np.testing.assert_allclose([u, v], [160, 120], atol=1e-9)


def test_bad_camera_raises_value_error_naming_field():
    with pytest.raises(ValueError, match="Camera.fx"):
        avsplat.Camera(-1.0, 1.0, 0.0, 0.0, 4, 4)
    with pytest.raises(ValueError, match="world_to_camera"):
        avsplat.Camera(1.0, 1.0, 0.0, 0.0, 4, 4, world_to_camera=np.eye(3))


def test_json_round_trip(tmp_path):
    cam = avsplat.Camera.look_at([0, 1, 2], [0, 0, 0], [0, 0, 1], 40.0, 100, 80)
    path = str(tmp_path / "cams.json")
    avsplat.write_cameras_json(path, [cam, cam])
    back = avsplat.read_cameras_json(path)
    assert len(back) == 2
    np.testing.assert_array_equal(back[1].world_to_camera, cam.world_to_camera)
    with pytest.raises(OSError, match="nope.json"):
        avsplat.read_camera_json(str(tmp_path / "nope.json"))
