"""avsplat.RenderWorkspace: renders that reuse one give the images of fresh renders bit for bit
(several clouds, sizes, precisions, contributions), match the numpy brute-force renderer of
test_render.py, hold memory until release(), and refuse concurrent use
(lib/src/render/cpu/render_workspace.h)."""
import threading

import numpy as np
import pytest

import avsplat
from test_render import assert_matches_numpy, numpy_render, random_cloud


def assert_same(a, b):
    np.testing.assert_array_equal(a.color, b.color)
    np.testing.assert_array_equal(a.alpha, b.alpha)
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.contributors, b.contributors)
    assert a.stats.blends == b.stats.blends and a.stats.tile_instances == b.stats.tile_instances
    if a.contribution_max is None:
        assert b.contribution_max is None
    else:
        np.testing.assert_array_equal(a.contribution_max, b.contribution_max)
        np.testing.assert_array_equal(a.contribution_sum, b.contribution_sum)


def test_workspace_reuse_gives_fresh_images():
    big = random_cloud(3000, 31, max_opacity=1.0, sh_degree=3)
    small = random_cloud(200, 32, max_opacity=1.0, sh_degree=1)
    wide = avsplat.Camera.look_at([0.1, -0.2, -0.4], [0, 0, 4], [0, -1, 0], 70.0, 203, 117)
    narrow = avsplat.Camera.look_at([0.0, 0.1, -0.2], [0, 0, 4], [0, -1, 0], 60.0, 40, 90)
    ws = avsplat.RenderWorkspace()
    assert ws.bytes == 0 and "0 bytes" in repr(ws)
    held = 0
    for cloud, cam, kw in [(big, wide, {}), (small, narrow, {}), (big, narrow, dict(gaussian_contributions=True)),
                           (small, wide, dict(precision="float64")), (big, wide, dict(background=(0.2, 0.1, 0.0)))]:
        assert_same(avsplat.render(cloud, cam, workspace=ws, **kw), avsplat.render(cloud, cam, **kw))
        assert ws.bytes >= held
        held = ws.bytes
    assert held > 3000 * 64
    ws.release()
    assert ws.bytes == 0
    assert_same(avsplat.render(small, narrow, workspace=ws), avsplat.render(small, narrow))


def test_workspace_render_matches_numpy_brute_force():
    cloud = random_cloud(120, 5)
    cam = avsplat.Camera.look_at([0.2, -0.3, -0.5], [0, 0, 4], [0, -1, 0], 75.0, 64, 48)
    background = (0.2, 0.3, 0.9)
    reference = numpy_render(cloud, cam, background)
    ws = avsplat.RenderWorkspace()
    for precision, tol in [("float64", 1e-6), ("float32", 2e-5), ("float64", 1e-6)]:
        r = avsplat.render(cloud, cam, precision=precision, background=background, workspace=ws)
        assert_matches_numpy(r, reference, tol)


def test_workspace_refuses_concurrent_renders():
    cloud = random_cloud(20000, 34, max_opacity=1.0, sh_degree=3)
    cam = avsplat.Camera.look_at([0.1, -0.2, -0.4], [0, 0, 4], [0, -1, 0], 70.0, 320, 240)
    expected = avsplat.render(cloud, cam)
    ws = avsplat.RenderWorkspace()
    outcomes = []

    def work():
        for _ in range(5):
            try:
                r = avsplat.render(cloud, cam, workspace=ws)
                outcomes.append(np.array_equal(r.color, expected.color))
            except RuntimeError as e:
                assert "RenderWorkspace is in use" in str(e)
                outcomes.append("refused")

    threads = [threading.Thread(target=work) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(outcomes) == 20
    assert True in outcomes and False not in outcomes


def test_workspace_argument_is_checked():
    cloud = random_cloud(10, 35)
    cam = avsplat.Camera(60.0, 60.0, 16.0, 12.0, 32, 24)
    with pytest.raises(TypeError):
        avsplat.render(cloud, cam, workspace="not a workspace")
