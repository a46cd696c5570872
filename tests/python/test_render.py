"""avsplat.render against numpy references written here, and the PNG writers.

The references: the closed-form image of one isotropic Gaussian, and a brute-force numpy
renderer (every Gaussian against every pixel, 3DGS rules, no tiles) on scenes whose opacities
are low enough (<= 0.35) that a splat is below 1/255 outside its 3-sigma box, where the
renderer's box cannot matter.
"""
import threading
import time

import numpy as np
import pytest

import avsplat

C0 = 0.28209479177387814


def make_cloud(means, scales, quats, opacities, rgb):
    dc = (np.asarray(rgb, np.float64) - 0.5) / C0
    return avsplat.GaussianCloud(means, scales, quats, opacities, dc[:, None, :])


def random_cloud(n, seed, max_opacity=0.35, sh_degree=0):
    rng = np.random.default_rng(seed)
    z = rng.uniform(1.5, 6.0, n)
    means = np.stack([rng.uniform(-1, 1, n) * z * 0.9, rng.uniform(-1, 1, n) * z * 0.7, z], axis=1)
    scales = np.exp(rng.uniform(np.log(0.02), np.log(0.3), (n, 3)))
    quats = rng.normal(size=(n, 4))
    opac = rng.uniform(0, max_opacity, n)
    k = (sh_degree + 1) ** 2
    sh = rng.normal(size=(n, k, 3)) * np.where(np.arange(k) == 0, 1.0, 0.3)[None, :, None]
    return avsplat.GaussianCloud(means, scales, quats, opac, sh)


def quat_to_matrix(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def numpy_render(cloud, cam, background=(0.0, 0.0, 0.0), low_pass=0.3):
    """Brute-force 3DGS rendering of a degree-0 cloud in float64."""
    assert cloud.sh_degree == 0
    W2C = np.asarray(cam.world_to_camera)
    R, t = W2C[:3, :3], W2C[:3, 3]
    means = np.asarray(cloud.means, np.float64)
    splats = []
    for i in range(len(cloud)):
        mc = R @ means[i] + t
        if mc[2] < cam.near or mc[2] > cam.far:
            continue
        M = quat_to_matrix(np.asarray(cloud.rotations[i], np.float64)) * np.asarray(cloud.scales[i], np.float64)
        Sc = R @ (M @ M.T) @ R.T
        tan_x, tan_y = 0.5 * cam.width / cam.fx, 0.5 * cam.height / cam.fy
        u = np.clip(mc[0] / mc[2], -(cam.cx / cam.fx + 0.3 * tan_x), (cam.width - cam.cx) / cam.fx + 0.3 * tan_x)
        v = np.clip(mc[1] / mc[2], -(cam.cy / cam.fy + 0.3 * tan_y), (cam.height - cam.cy) / cam.fy + 0.3 * tan_y)
        J = np.array([[cam.fx / mc[2], 0, -cam.fx * u / mc[2]], [0, cam.fy / mc[2], -cam.fy * v / mc[2]]])
        cov = J @ Sc @ J.T + low_pass * np.eye(2)
        rgb = np.maximum(0.5 + C0 * np.asarray(cloud.sh[i, 0], np.float64), 0)
        mean2 = np.array([cam.fx * mc[0] / mc[2] + cam.cx, cam.fy * mc[1] / mc[2] + cam.cy])
        splats.append((np.float32(mc[2]), i, mc[2], mean2, np.linalg.inv(cov), float(cloud.opacities[i]), rgb))
    splats.sort(key=lambda s: (s[0], s[1]))
    py, px = np.mgrid[0:cam.height, 0:cam.width] + 0.5
    T = np.ones((cam.height, cam.width))
    color = np.zeros((cam.height, cam.width, 3))
    dsum = np.zeros_like(T)
    count = np.zeros(T.shape, np.int32)
    done = np.zeros(T.shape, bool)
    for _, _, z, m, conic, opacity, rgb in splats:
        dx, dy = px - m[0], py - m[1]
        power = -0.5 * (conic[0, 0] * dx * dx + conic[1, 1] * dy * dy) - conic[0, 1] * dx * dy
        alpha = np.where(power > 0, 0.0, np.minimum(0.99, opacity * np.exp(power)))
        visible = (alpha >= 1 / 255) & ~done
        nxt = T * (1 - alpha)
        saturated = visible & (nxt < 1e-4)
        blended = visible & ~saturated
        w = np.where(blended, alpha * T, 0.0)
        color += w[..., None] * rgb
        dsum += w * z
        T = np.where(blended, nxt, T)
        count += blended
        done |= saturated
    color += T[..., None] * np.asarray(background)
    a = 1 - T
    depth = np.where(a > 0, dsum / np.where(a > 0, a, 1), 0)
    return color, a, depth, count


def assert_matches_numpy(r, reference, tol):
    """Holds a RenderResult to numpy_render's (color, alpha, depth, count): colour and alpha
    within tol, depth within its relative tolerance, the contributor counts exactly."""
    color, alpha, depth, count = reference
    np.testing.assert_allclose(r.color, color, atol=tol)
    np.testing.assert_allclose(r.alpha, alpha, atol=tol)
    np.testing.assert_allclose(r.depth, depth, rtol=3e-5, atol=1e-6)
    np.testing.assert_array_equal(r.contributors, count)


def test_result_arrays_shapes_dtypes_and_repr():
    cloud = random_cloud(50, 1)
    cam = avsplat.Camera(60.0, 60.0, 40.0, 30.0, 80, 60)
    r = avsplat.render(cloud, cam)
    assert (r.width, r.height) == (80, 60)
    assert r.color.shape == (60, 80, 3) and r.color.dtype == np.float32
    assert r.alpha.shape == (60, 80) and r.alpha.dtype == np.float32
    assert r.depth.shape == (60, 80) and r.depth.dtype == np.float32
    assert r.contributors.shape == (60, 80) and r.contributors.dtype == np.int32
    assert r.stats.gaussians == 50 and r.stats.visible <= 50
    assert r.stats.contributions == int(r.contributors.sum())
    assert "RenderResult(80x60" in repr(r) and "RenderStats(" in repr(r.stats)


def test_single_gaussian_closed_form_and_pixel_centres():
    # Mean on the optical axis, principal point at (20.5, 15.5): the splat is centred on the
    # centre of pixel (20, 15) when pixel (i, j) has its centre at (i + 0.5, j + 0.5).
    f, z, s, o = 50.0, 2.0, 0.04, 0.8
    cam = avsplat.Camera(f, f, 20.5, 15.5, 41, 31)
    cloud = make_cloud([[0, 0, z]], [[s, s, s]], [[1, 0, 0, 0]], [o], [[0.9, 0.2, 0.4]])
    r = avsplat.render(cloud, cam, background=(0.0, 0.5, 0.0), precision="float64")
    var = (f * s / z) ** 2 + 0.3
    py, px = np.mgrid[0:31, 0:41] + 0.5
    d2 = (px - 20.5) ** 2 + (py - 15.5) ** 2
    alpha = o * np.exp(-0.5 * d2 / var)
    radius = 3 * np.sqrt(var)
    alpha[(alpha < 1 / 255) | (np.abs(px - 20.5) > radius) | (np.abs(py - 15.5) > radius)] = 0
    np.testing.assert_allclose(r.alpha, alpha, atol=1e-6)
    assert np.unravel_index(np.argmax(r.alpha), r.alpha.shape) == (15, 20)
    expect = alpha[..., None] * np.array([0.9, 0.2, 0.4]) + (1 - alpha[..., None]) * np.array([0, 0.5, 0])
    np.testing.assert_allclose(r.color, expect, atol=1e-6)
    np.testing.assert_allclose(r.depth, np.where(alpha > 0, z, 0), rtol=1e-6)
    np.testing.assert_array_equal(r.contributors, (alpha > 0).astype(np.int32))


@pytest.mark.parametrize("precision,tol", [("float64", 1e-6), ("float32", 2e-5)])
def test_matches_numpy_brute_force(precision, tol):
    cloud = random_cloud(120, 5)
    cam = avsplat.Camera.look_at([0.2, -0.3, -0.5], [0, 0, 4], [0, -1, 0], 75.0, 64, 48)
    background = (0.2, 0.3, 0.9)
    r = avsplat.render(cloud, cam, precision=precision, background=background)
    assert_matches_numpy(r, numpy_render(cloud, cam, background), tol)


def test_float32_close_to_float64_and_deterministic():
    cloud = random_cloud(2000, 9, max_opacity=1.0, sh_degree=3)
    cam = avsplat.Camera(90.0, 90.0, 64.0, 48.0, 128, 96)
    a = avsplat.render(cloud, cam)
    b = avsplat.render(cloud, cam, precision="float64")
    assert np.mean(np.abs(a.color - b.color)) < 2e-6
    assert np.max(np.abs(a.color - b.color)) < 1e-2
    again = avsplat.render(cloud, cam)
    np.testing.assert_array_equal(a.color, again.color)
    np.testing.assert_array_equal(a.contributors, again.contributors)


def test_options_are_validated():
    cloud = random_cloud(5, 2)
    cam = avsplat.Camera(10.0, 10.0, 8.0, 8.0, 16, 16)
    with pytest.raises(ValueError, match="backend"):
        avsplat.render(cloud, cam, backend="gpu")
    with pytest.raises(ValueError, match="precision"):
        avsplat.render(cloud, cam, precision="half")
    with pytest.raises(ValueError, match="alpha_threshold"):
        avsplat.render(cloud, cam, alpha_threshold=0.0)
    with pytest.raises(ValueError, match="extent_sigma"):
        avsplat.render(cloud, cam, extent_sigma=-1.0)
    with pytest.raises(TypeError):
        avsplat.render(cloud, cam, background=(1.0, 2.0))


def test_cuda_backend_renders_or_raises_device_error():
    cloud = random_cloud(5, 2)
    cam = avsplat.Camera(10.0, 10.0, 8.0, 8.0, 16, 16)
    try:
        r = avsplat.render(cloud, cam, backend="cuda")
    except avsplat.DeviceError as e:
        assert isinstance(e, RuntimeError) and "CUDA" in str(e)
    else:
        assert r.color.shape == (16, 16, 3)


def test_options_change_the_image_as_documented():
    cloud = random_cloud(300, 4, max_opacity=1.0)
    cam = avsplat.Camera(60.0, 60.0, 40.0, 30.0, 80, 60)
    base = avsplat.render(cloud, cam)
    # antialiased: compensation <= 1 only lowers opacities
    aa = avsplat.render(cloud, cam, antialiased=True)
    assert np.all(aa.alpha <= base.alpha + 1e-6) and np.any(aa.alpha < base.alpha - 1e-3)
    # background only fills the transmittance
    bg = avsplat.render(cloud, cam, background=(1.0, 1.0, 1.0))
    np.testing.assert_allclose(bg.color - base.color, np.repeat((1 - base.alpha)[..., None], 3, -1), atol=1e-6)
    # a larger stop transmittance saturates pixels earlier
    early = avsplat.render(cloud, cam, transmittance_stop=0.5)
    assert np.all(early.contributors <= base.contributors) and np.all(early.alpha <= base.alpha + 1e-6)


def test_render_releases_the_gil():
    n = 300000
    rng = np.random.default_rng(0)
    means = np.stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(3, 5, n)], axis=1)
    cloud = avsplat.GaussianCloud(means, np.full((n, 3), 0.02), np.tile([1.0, 0, 0, 0], (n, 1)),
                                  np.full(n, 0.05), np.zeros((n, 1, 3)))
    cam = avsplat.Camera(400.0, 400.0, 320.0, 240.0, 640, 480)
    span = {}

    def work():
        span["start"] = time.perf_counter()
        avsplat.render(cloud, cam, precision="float64")
        span["end"] = time.perf_counter()

    thread = threading.Thread(target=work)
    ticks = []
    thread.start()
    while thread.is_alive():
        ticks.append(time.perf_counter())
        time.sleep(0.001)
    thread.join()
    during = [t for t in ticks if span["start"] + 0.01 < t < span["end"] - 0.01]
    assert span["end"] - span["start"] > 0.05, "the render was too short to tell"
    assert len(during) >= 3, "the main thread did not run while render() was running"


def test_png_writers_round_trip(tmp_path):
    if not hasattr(avsplat, "write_color_png"):
        pytest.skip("avsplat was built without Open3D")
    import open3d as o3d
    cloud = random_cloud(200, 6, max_opacity=1.0)
    cam = avsplat.Camera(60.0, 60.0, 40.0, 30.0, 80, 60)
    r = avsplat.render(cloud, cam, background=(0.1, 0.1, 0.1))

    avsplat.write_color_png(str(tmp_path / "color.png"), r.color)
    back = np.asarray(o3d.io.read_image(str(tmp_path / "color.png")))
    assert back.shape == (60, 80, 3) and back.dtype == np.uint8
    np.testing.assert_array_equal(back, np.round(np.clip(r.color.astype(np.float64), 0, 1) * 255).astype(np.uint8))

    avsplat.write_alpha_png(str(tmp_path / "alpha.png"), r.alpha)
    back = np.asarray(o3d.io.read_image(str(tmp_path / "alpha.png")))
    np.testing.assert_array_equal(np.squeeze(back), np.round(r.alpha.astype(np.float64) * 255).astype(np.uint8))

    avsplat.write_depth_png(str(tmp_path / "depth.png"), r.depth)
    back = np.asarray(o3d.io.read_image(str(tmp_path / "depth.png")))
    valid = r.depth > 0
    assert np.all(back[~valid] == 0)
    lo, hi = r.depth[valid].min(), r.depth[valid].max()
    t = (r.depth[valid].astype(np.float64) - lo) / (hi - lo)
    expect = np.array([avsplat.turbo_colormap(float(v)) for v in t])
    np.testing.assert_allclose(back[valid] / 255.0, expect, atol=0.6 / 255 + 1e-6)

    with pytest.raises(ValueError, match="rgb: expected shape"):
        avsplat.write_color_png(str(tmp_path / "x.png"), r.alpha)
    with pytest.raises(OSError):
        avsplat.write_color_png(str(tmp_path / "missing" / "x.png"), r.color)


def test_turbo_colormap_is_close_to_matplotlib_turbo():
    if not hasattr(avsplat, "turbo_colormap"):
        pytest.skip("avsplat was built without Open3D")
    matplotlib = pytest.importorskip("matplotlib")
    turbo = matplotlib.colormaps["turbo"] if hasattr(matplotlib, "colormaps") else matplotlib.cm.get_cmap("turbo")
    t = np.linspace(0.0, 1.0, 256)
    ours = np.array([avsplat.turbo_colormap(float(v)) for v in t])
    np.testing.assert_allclose(ours, turbo(t)[:, :3], atol=0.0075)
