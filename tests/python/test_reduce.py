"""Leave out what a scene does not need: per-Gaussian contributions of the renderer, prune and
reduce_sh (reduce/prune.h, reduce/reduce_sh.h), and their CLI (`avsplat prune`, `avsplat convert
--sh-degree / --sh-max-error`).

References written here: a numpy compositor of isotropic Gaussians seen by an axis camera (the
3DGS rules spelled out: EWA covariance with the 0.3 low-pass, 3-sigma box, alpha threshold 1/255,
stop below T = 1e-4), and renders before/after each reduction from random cameras.
"""
import os
import subprocess

import numpy as np
import pytest

import avsplat

C0 = 0.28209479177387814
BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")


def isotropic_scene(n, seed, degree=0, band_scale=0.3):
    """n isotropic Gaussians in front of an axis camera, inside its view (no Jacobian clamp)."""
    rng = np.random.default_rng(seed)
    z = rng.uniform(1.5, 5.0, n)
    means = np.stack([rng.uniform(-0.4, 0.4, n) * z, rng.uniform(-0.3, 0.3, n) * z, z], 1)
    scales = np.repeat(np.exp(rng.uniform(np.log(0.02), np.log(0.3), n))[:, None], 3, 1)
    rotations = np.tile([1.0, 0.0, 0.0, 0.0], (n, 1))
    opacities = rng.uniform(0, 1, n) ** 2
    opacities[::11] = 1.0
    opacities[::13] = 0.0
    k = (degree + 1) ** 2
    sh = rng.normal(size=(n, k, 3))
    sh[:, 1:] *= band_scale
    return avsplat.GaussianCloud(means, scales, rotations, opacities, sh)


def numpy_contributions(cloud, cam):
    """(max, sum) over pixels of alpha T per Gaussian and the colour image, by brute force."""
    means = np.asarray(cloud.means, np.float64)
    s = np.asarray(cloud.scales, np.float64)[:, 0]
    op = np.asarray(cloud.opacities, np.float64)
    dc = np.asarray(cloud.sh, np.float64)[:, 0, :]
    x, y, z = means.T
    fx, fy, cx, cy = cam.fx, cam.fy, cam.cx, cam.cy
    # J Sigma J^T with Sigma = s^2 I, plus the low-pass 0.3 on the diagonal.
    a = s**2 * (fx**2 / z**2 + fx**2 * x**2 / z**4) + 0.3
    b = s**2 * (fx * fy * x * y / z**4)
    c = s**2 * (fy**2 / z**2 + fy**2 * y**2 / z**4) + 0.3
    det = a * c - b * b
    ca, cb, cc = c / det, -b / det, a / det
    mx, my = fx * x / z + cx, fy * y / z + cy
    rx, ry = 3 * np.sqrt(a), 3 * np.sqrt(c)
    rgb = np.maximum(C0 * dc + 0.5, 0)
    order = sorted(range(len(op)), key=lambda i: (np.float32(z[i]), i))
    H, W = cam.height, cam.width
    px, py = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5)
    T = np.ones((H, W))
    done = np.zeros((H, W), bool)
    color = np.zeros((H, W, 3))
    cmax, csum = np.zeros(len(op)), np.zeros(len(op))
    for i in order:
        if op[i] < 1 / 255:
            continue
        dx, dy = px - mx[i], py - my[i]
        inside = (np.abs(dx) <= rx[i]) & (np.abs(dy) <= ry[i]) & ~done
        power = -0.5 * (ca[i] * dx * dx + cc[i] * dy * dy) - cb[i] * dx * dy
        alpha = np.where(power <= 0, np.minimum(0.99, op[i] * np.exp(np.minimum(power, 0))), 0)
        takes_part = inside & (alpha >= np.float32(1 / 255))
        contrib = np.where(takes_part, alpha * T, 0)
        cmax[i], csum[i] = contrib.max(), contrib.sum()
        stops = takes_part & (T * (1 - alpha) < np.float32(1e-4))
        blended = takes_part & ~stops
        color += np.where(blended, alpha * T, 0)[..., None] * rgb[i]
        T = np.where(blended, T * (1 - alpha), T)
        done |= stops
    return cmax, csum, color  # background 0


def random_cameras(seed, count, width=48, height=36, distance=3.0):
    rng = np.random.default_rng(seed)
    cams = []
    for _ in range(count):
        eye = rng.normal(size=3)
        eye = distance * eye / np.linalg.norm(eye)
        up = [1.0, 0.0, 0.0] if abs(eye[1]) > 0.9 * distance else [0.0, 1.0, 0.0]
        cams.append(avsplat.Camera.look_at(eye, [0.0, 0.0, 0.0], up, 60.0, width, height))
    return cams


def ball_scene(n, seed, degree=1, band_scale=0.3):
    """Random Gaussians in a unit ball with floaters, random rotations and scales."""
    rng = np.random.default_rng(seed)
    means = rng.uniform(-1, 1, (n, 3))
    means[::10] *= 6.0
    scales = np.exp(rng.uniform(np.log(0.02), np.log(0.5), (n, 3)))
    opacities = rng.uniform(0, 1, n) ** 2
    opacities[::17] = 0.0
    opacities[::13] = 1.0
    k = (degree + 1) ** 2
    sh = rng.normal(size=(n, k, 3))
    sh[:, 1:] *= band_scale
    return avsplat.GaussianCloud(means, scales, rng.normal(size=(n, 4)), opacities, sh)


# ---------------------------------------------------------------------------------------------
# render(..., gaussian_contributions=True)

@pytest.mark.parametrize("seed", [0, 1, 2])
def test_contributions_match_a_numpy_compositor(seed):
    cloud = isotropic_scene(60, seed)
    cam = avsplat.Camera(60.0, 60.0, 26.0, 19.0, 53, 37)
    cmax, csum, color = numpy_contributions(cloud, cam)
    r = avsplat.render(cloud, cam, precision="float64", gaussian_contributions=True)
    assert r.contribution_max.shape == (60,) and r.contribution_max.dtype == np.float32
    np.testing.assert_allclose(r.color, color, atol=1e-6)  # the reference composites as the renderer
    np.testing.assert_allclose(r.contribution_max, cmax, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(r.contribution_sum, csum, rtol=1e-6, atol=1e-12)
    assert np.array_equal(r.contribution_max == 0, cmax == 0)
    assert (cmax == 0).any() and (cmax > 0).any()
    r32 = avsplat.render(cloud, cam, gaussian_contributions=True)
    np.testing.assert_allclose(r32.contribution_sum, csum, rtol=1e-4, atol=1e-6)
    plain = avsplat.render(cloud, cam)
    assert plain.contribution_max is None and plain.contribution_sum is None
    assert np.array_equal(plain.color, r32.color)


def test_contributions_are_cpu_only():
    cloud = isotropic_scene(3, 0)
    with pytest.raises(avsplat.DeviceError, match="gaussian_contributions"):
        avsplat.render(cloud, avsplat.Camera(10, 10, 5, 5, 10, 10), backend="cuda", gaussian_contributions=True)


# ---------------------------------------------------------------------------------------------
# prune

@pytest.mark.parametrize("precision", ["float32", "float64"])
def test_prune_keeps_every_render_from_the_cameras(precision):
    cloud = ball_scene(500, 3, degree=2)
    cams = random_cameras(3, 3, distance=2.5)
    r = avsplat.prune(cloud, cams, precision=precision, background=(0.1, 0.2, 0.3))
    assert r.kept + r.removed == len(cloud) == len(r.cloud) + r.removed
    assert r.removed == r.degenerate + r.low_opacity + r.invisible
    assert r.low_opacity > 0 and r.invisible > 0 and r.cameras == 3
    assert r.max_removed_contribution == 0.0
    for cam in cams:
        a = avsplat.render(cloud, cam, precision=precision, background=(0.1, 0.2, 0.3))
        b = avsplat.render(r.cloud, cam, precision=precision, background=(0.1, 0.2, 0.3))
        assert np.array_equal(a.color, b.color) and np.array_equal(a.depth, b.depth)
    assert "PruneResult(kept" in repr(r) and f"invisible {r.invisible}" in r.summary()


def test_prune_invisible_is_what_the_contributions_say():
    cloud = ball_scene(300, 4)
    cams = random_cameras(4, 2)
    best = np.max([avsplat.render(cloud, c, gaussian_contributions=True).contribution_max for c in cams], axis=0)
    r = avsplat.prune(cloud, cams, min_opacity=0.0)
    assert r.kept == int((best > 0).sum())
    np.testing.assert_array_equal(r.cloud.means, np.asarray(cloud.means)[best > 0])
    r = avsplat.prune(cloud, cams, min_opacity=0.0, min_contribution=0.05)
    assert r.kept == int((best >= 0.05).sum())
    assert 0 < r.max_removed_contribution < 0.05


def test_prune_stiff_inputs():
    cams = random_cameras(5, 2)
    empty = avsplat.GaussianCloud(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 4)), np.zeros(0),
                                  np.zeros((0, 4, 3)))
    r = avsplat.prune(empty, cams)
    assert len(r.cloud) == 0 and r.removed == 0 and r.cloud.sh_degree == 1
    cloud = ball_scene(90, 6)
    means = np.asarray(cloud.means)
    means[:] = 0.1
    scales = np.asarray(cloud.scales)
    scales[0::3], scales[1::3] = 1e-8, 1e4
    opacities = np.asarray(cloud.opacities)
    opacities[0::2], opacities[1::2] = 0.0, 1.0
    r = avsplat.prune(cloud, cams)
    assert r.low_opacity == 45
    for cam in cams:
        assert np.array_equal(avsplat.render(cloud, cam).color, avsplat.render(r.cloud, cam).color)
    # Invalid Gaussians are degenerate (the renderer would refuse them), counted once each.
    means[3] = np.nan
    scales[4] = -1.0
    opacities[5] = 2.0
    r = avsplat.prune(cloud)
    assert r.degenerate == 3 and r.cameras == 0 and r.invisible == 0
    with pytest.raises(ValueError, match="min_opacity"):
        avsplat.prune(empty, min_opacity=2.0)
    with pytest.raises(ValueError, match="min_contribution"):
        avsplat.prune(empty, cams, min_contribution=-1.0)
    with pytest.raises(ValueError, match="cameras"):
        avsplat.prune(empty, ["not a camera"])
    assert avsplat.prune(cloud.select_mask(np.isfinite(means[:, 0]) & (scales[:, 0] >= 0) & (opacities <= 1)),
                         cams[0]).cameras == 1


# ---------------------------------------------------------------------------------------------
# reduce_sh

def test_reduce_sh_changes_no_pixel_by_more_than_the_bound():
    reduced = 0
    for seed in range(9):
        degree = 1 + seed % 3
        cloud = ball_scene(300, 10 + seed, degree=degree, band_scale=0.0005 if seed % 2 else 0.02)
        r = avsplat.reduce_sh(cloud)  # max_error 1/255
        assert r.max_error_bound <= 1 / 255 and r.cloud.sh_degree == r.sh_degree <= degree
        assert r.sh_degree_before == degree and sum(r.gaussians_by_degree) == len(cloud)
        assert r.bytes_saved == len(cloud) * ((degree + 1) ** 2 - (r.sh_degree + 1) ** 2) * 12
        reduced += r.sh_degree < degree
        for cam in random_cameras(seed, 2, distance=2.5):
            a = avsplat.render(cloud, cam, precision="float64").color
            b = avsplat.render(r.cloud, cam, precision="float64").color
            assert np.abs(a - b).max() <= min(r.max_error_bound, 1 / 255) + 1e-12
    assert reduced >= 3


def test_reduce_sh_forced_degree_and_errors():
    cloud = ball_scene(50, 1, degree=3, band_scale=0.5)
    r = avsplat.reduce_sh(cloud, degree=0)
    assert r.sh_degree == 0 and r.cloud.sh.shape == (50, 1, 3) and r.max_error_bound > 1 / 255
    np.testing.assert_array_equal(r.cloud.sh[:, 0], np.asarray(cloud.sh)[:, 0])
    # Rendered pixels stay within the reported bound, and the forced drop does change them.
    worst = 0.0
    for cam in random_cameras(1, 3, distance=2.5):
        a = avsplat.render(cloud, cam, precision="float64").color
        b = avsplat.render(r.cloud, cam, precision="float64").color
        worst = max(worst, np.abs(a - b).max())
    assert 0 < worst <= r.max_error_bound
    assert avsplat.reduce_sh(cloud, degree=3).bytes_saved == 0
    for bad in (4, -1):
        with pytest.raises(ValueError, match="degree"):
            avsplat.reduce_sh(cloud, degree=bad)
    with pytest.raises(ValueError, match="max_error"):
        avsplat.reduce_sh(cloud, max_error=float("nan"))
    assert "ReduceShResult" in repr(r) and "bytes saved" in r.summary()


# ---------------------------------------------------------------------------------------------
# CLI

cli = pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")


@cli
def test_cli_prune_and_convert_sh_degree(tmp_path):
    cloud = ball_scene(400, 7, degree=3, band_scale=0.001)
    src, cams_json = tmp_path / "in.ply", tmp_path / "cams.json"
    avsplat.write_ply(src, cloud)
    cams = random_cameras(7, 2)
    avsplat.write_cameras_json(cams_json, cams)
    p = subprocess.run([BIN, "prune", src, tmp_path / "out.splat", "--cameras", cams_json], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    expect = avsplat.prune(avsplat.read_ply(src), cams)
    assert f"removed {expect.removed} (degenerate 0, low_opacity {expect.low_opacity}, invisible {expect.invisible}" \
        in p.stdout
    assert len(avsplat.read_gaussians(tmp_path / "out.splat")) == expect.kept
    p = subprocess.run([BIN, "prune", src, tmp_path / "out.ply", "--cameras", cams_json, "--min-contribution",
                        "0.05"], capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    expect = avsplat.prune(avsplat.read_ply(src), cams, min_contribution=0.05)
    assert f"invisible {expect.invisible} " in p.stdout and "largest contribution removed" in p.stdout
    assert len(avsplat.read_ply(tmp_path / "out.ply")) == expect.kept
    p = subprocess.run([BIN, "prune", src, tmp_path / "bad.ply", "--min-contribution", "-0.5"], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode != 0 and "min_contribution" in p.stderr and len(p.stderr.strip().splitlines()) == 1
    p = subprocess.run([BIN, "convert", src, tmp_path / "dc.ply", "--sh-max-error", str(1 / 255)],
                       capture_output=True, text=True, timeout=120)
    assert p.returncode == 0, p.stderr
    expect = avsplat.reduce_sh(avsplat.read_ply(src), 1 / 255)
    assert f"SH degree 3 -> {expect.sh_degree}" in p.stdout
    assert avsplat.read_ply(tmp_path / "dc.ply").sh_degree == expect.sh_degree
    p = subprocess.run([BIN, "convert", src, tmp_path / "d1.ply", "--sh-degree", "1"], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode == 0 and "SH degree 3 -> 1" in p.stdout
    assert avsplat.read_ply(tmp_path / "d1.ply").sh_degree == 1
    p = subprocess.run([BIN, "convert", src, tmp_path / "x.ply", "--sh-degree", "5"], capture_output=True,
                       text=True, timeout=120)
    assert p.returncode != 0 and len(p.stderr.strip().splitlines()) == 1
