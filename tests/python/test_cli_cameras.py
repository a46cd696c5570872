"""The tool's cameras: default framing, --orbit, --eye/--target, COLMAP models, `avsplat cameras`."""

import json
import os
import subprocess

import numpy as np
import pytest

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")

pytestmark = pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")


def run(*args):
    return subprocess.run([BIN, *map(str, args)], capture_output=True, text=True, timeout=120)


def ok(*args):
    p = run(*args)
    assert p.returncode == 0, f"avsplat {' '.join(map(str, args))} failed:\n{p.stdout}\n{p.stderr}"
    return p


@pytest.fixture()
def scene(tmp_path):
    rng = np.random.default_rng(5)
    n = 400
    m = rng.uniform([-1, 0, 2], [3, 1, 4], size=(n, 3)).astype(np.float32)
    m[-3:] = [900, 0, 900]  # floaters
    cloud = avsplat.GaussianCloud(m, np.full((n, 3), 0.05, np.float32), np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
                                  np.full(n, 0.9, np.float32), np.full((n, 1, 3), 0.5, np.float32))
    path = tmp_path / "scene.ply"
    avsplat.write_ply(path, cloud)
    return path, cloud


def read_png(path):
    import matplotlib.image

    return (matplotlib.image.imread(str(path)) * 255).round().astype(np.uint8)


def test_render_without_camera_flags_frames_the_scene(tmp_path, scene):
    path, cloud = scene
    ok("render", path, "-o", tmp_path / "x.png", "--size", "64x48")
    expected = np.asarray(avsplat.render(cloud, avsplat.default_camera(cloud, width=64, height=48)).color)
    img = read_png(tmp_path / "x.png")[..., :3]
    assert img.shape == (48, 64, 3)
    np.testing.assert_allclose(img, np.clip(expected, 0, 1) * 255, atol=1.0)
    assert img[24, 32].max() > 20  # the scene is in the middle, not off-screen


def test_render_orbit_writes_one_image_per_view(tmp_path, scene):
    path, cloud = scene
    ok("render", path, "--orbit", 3, "--elevation", 10, "--size", "32x24", "-o", tmp_path / "v_%02d.png")
    cams = avsplat.orbit_cameras(cloud, 3, elevation_degrees=10, width=32, height=24)
    for k, cam in enumerate(cams):
        expected = np.clip(np.asarray(avsplat.render(cloud, cam).color), 0, 1) * 255
        np.testing.assert_allclose(read_png(tmp_path / f"v_{k:02d}.png")[..., :3], expected, atol=1.0)
    (tmp_path / "views").mkdir()
    ok("render", path, "--orbit", 2, "--size", "32x24", "-o", f"{tmp_path / 'views'}/")
    assert sorted(os.listdir(tmp_path / "views")) == ["view_000.png", "view_001.png"]
    p = run("render", path, "--orbit", 2, "-o", tmp_path / "one.png")
    assert p.returncode == 2 and "%d" in p.stderr
    p = run("render", path, "--orbit", 2, "-o", tmp_path / "bad_%s.png")
    assert p.returncode == 2 and "one %d" in p.stderr


def test_render_eye_target_up_fov_size(tmp_path, scene):
    path, cloud = scene
    ok("render", path, "--eye", "1,-2,-3", "--target", "1,0.5,3", "--up", "0,-1,0", "--fov", 40, "--size", "40x30",
       "-o", tmp_path / "e.png")
    cam = avsplat.Camera.look_at((1, -2, -3), (1, 0.5, 3), (0, -1, 0), 40.0, 40, 30)
    expected = np.clip(np.asarray(avsplat.render(cloud, cam).color), 0, 1) * 255
    np.testing.assert_allclose(read_png(tmp_path / "e.png")[..., :3], expected, atol=1.0)
    p = run("render", path, "--size", "40by30", "-o", tmp_path / "e.png")
    assert p.returncode == 2 and "--size" in p.stderr


def test_cameras_orbit_and_colmap_write_camera_json(tmp_path, scene):
    path, cloud = scene
    ok("cameras", "orbit", path, "--orbit", 4, "--radius", 7, "-o", tmp_path / "cams.json")
    cams = avsplat.read_cameras_json(tmp_path / "cams.json")
    assert len(cams) == 4 and cams[1].name == "orbit_001"
    for a, b in zip(cams, avsplat.orbit_cameras(cloud, 4, radius=7.0)):
        np.testing.assert_allclose(a.world_to_camera, b.world_to_camera, atol=1e-12)
    model = tmp_path / "sparse"
    model.mkdir()
    (model / "cameras.txt").write_text("1 SIMPLE_PINHOLE 32 24 30 16 12\n")
    (model / "images.txt").write_text("4 1 0 0 0 -1 -0.5 1 1 frame.png\n\n")
    ok("cameras", "colmap", model, "-o", tmp_path / "colmap.json")
    (cam,) = avsplat.read_cameras_json(tmp_path / "colmap.json")
    assert cam.name == "frame.png" and cam.fx == 30 and cam.fy == 30
    np.testing.assert_allclose(cam.position, [1, 0.5, -1])
    # render reads the COLMAP model directly too.
    ok("render", path, "--cameras", model, "-o", tmp_path / "c.png")
    assert read_png(tmp_path / "c.png").shape[:2] == (24, 32)
    (model / "cameras.txt").write_text("1 SIMPLE_RADIAL 32 24 30 16 12 0.1\n")
    p = run("cameras", "colmap", model, "-o", tmp_path / "colmap.json")
    assert p.returncode == 3
    assert "cameras.txt" in p.stderr and "camera 1" in p.stderr and "SIMPLE_RADIAL" in p.stderr


def test_prune_and_simplify_take_an_orbit(tmp_path, scene):
    path, cloud = scene
    p = ok("prune", path, tmp_path / "p.ply", "--orbit", 4, "--size", "48x36")
    assert "prune:" in p.stdout
    pruned = avsplat.prune(cloud, avsplat.orbit_cameras(cloud, 4, width=48, height=36))
    assert len(avsplat.read_ply(tmp_path / "p.ply")) == len(pruned.cloud) < len(cloud)  # the floaters are unseen
    p = ok("simplify", path, tmp_path / "s.ply", "--max-error", "0.5", "--orbit", 2, "--size", "32x24")
    assert "at 2 cameras" in p.stdout
    p = run("simplify", path, tmp_path / "s.ply", "--max-error", "0.5")
    assert p.returncode == 2 and "--orbit" in p.stderr


def test_camera_file_and_orbit_exclude_each_other(tmp_path, scene):
    path, cloud = scene
    avsplat.write_cameras_json(tmp_path / "c.json", [avsplat.default_camera(cloud)])
    p = run("render", path, "--cameras", tmp_path / "c.json", "--orbit", 3, "-o", tmp_path / "x_%d.png")
    assert p.returncode == 2 and "exclude" in p.stderr.lower()
    assert json.loads((tmp_path / "c.json").read_text())[0]["name"] == "default"
