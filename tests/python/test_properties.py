"""Property-based tests (hypothesis) of the public functions that test_hostile.py does not cover:
render, gaussians_from_point_maps, the metrics, the cameras, and every reader on random and
mutated bytes. Each call gives a correct result or the documented exception (ValueError naming
the argument, OSError naming the file), never a crash; where a reference exists (numpy, brute
force, the clean float32 call) the result is held to it."""

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

import avsplat

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
CORPUS = os.path.join(ROOT, "tests", "fuzz", "corpus")

DTYPES = st.sampled_from([np.float16, np.float32, np.float64, np.int8, np.int32, np.uint16, np.bool_])
EXTREMES = st.sampled_from([np.nan, np.inf, -np.inf, 1e38, -1e38, 1e-45, 0.0, -0.0])
SETTINGS = dict(deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])


def random_cloud_arrays(rng, n, degree=0):
    k = (degree + 1) ** 2
    return dict(means=rng.normal(size=(n, 3)) * 0.5, scales=rng.uniform(0.01, 0.2, (n, 3)),
                rotations=rng.normal(size=(n, 4)), opacities=rng.uniform(0.05, 1, n),
                sh=rng.normal(size=(n, k, 3)))


def cloud_of(a, dtype=np.float32):
    return avsplat.GaussianCloud(*(np.asarray(a[k]).astype(dtype) for k in
                                   ("means", "scales", "rotations", "opacities", "sh")))


def front_camera(width, height):
    return avsplat.Camera.look_at(np.array([0, 0, -3.0]), np.zeros(3), np.array([0, -1, 0.0]), 50, width, height)


# ---- render ------------------------------------------------------------------------------------

@settings(max_examples=40, **SETTINGS)
@given(n=st.integers(0, 30), degree=st.integers(0, 3), width=st.integers(1, 40), height=st.integers(1, 40),
       seed=st.integers(0, 2**16), reverse=st.booleans())
def test_render_any_layout_equals_the_contiguous_float32_call(n, degree, width, height, seed, reverse):
    a = random_cloud_arrays(np.random.default_rng(seed), n, degree)
    if reverse:  # negative strides and float64: converted once, the same Gaussians
        a = {k: np.asarray(v, np.float64)[::-1] for k, v in a.items()}
    cam = front_camera(width, height)
    got = avsplat.render(cloud_of(a, np.float64), cam)
    want = avsplat.render(cloud_of({k: np.ascontiguousarray(v, np.float32) for k, v in a.items()}), cam)
    assert np.asarray(got.color).shape == (height, width, 3)
    for name in ("color", "alpha", "depth", "contributors"):
        np.testing.assert_array_equal(np.asarray(getattr(got, name)), np.asarray(getattr(want, name)), err_msg=name)
    alpha = np.asarray(got.alpha)
    assert np.all((alpha >= 0) & (alpha <= 1))
    assert np.isfinite(np.asarray(got.color)).all()


@settings(max_examples=60, **SETTINGS)
@given(field=st.sampled_from(["means", "scales", "rotations", "opacities", "sh"]), value=EXTREMES,
       index=st.integers(0, 7))
def test_render_of_an_extreme_value_is_a_value_error_naming_it_or_finite(field, value, index):
    a = random_cloud_arrays(np.random.default_rng(index), 8)
    a[field] = np.array(a[field], np.float64)
    a[field].reshape(8, -1)[index, 0] = value
    try:
        cloud = cloud_of(a)
        image = avsplat.render(cloud, front_camera(16, 12))
    except ValueError as e:
        assert field in str(e)
        return
    assert np.isfinite(np.asarray(image.color)).all() and np.isfinite(np.asarray(image.alpha)).all()


@settings(max_examples=40, **SETTINGS)
@given(fx=st.one_of(st.floats(-1e6, 1e6), EXTREMES), width=st.integers(-3, 64), height=st.integers(-3, 64),
       near=st.floats(-1, 10), far=st.one_of(st.floats(-1, 1e12), EXTREMES))
def test_cameras_are_valid_or_a_value_error(fx, width, height, near, far):
    try:
        cam = avsplat.Camera(fx, abs(fx), width / 2, height / 2, width, height, None, near, far)
        cam.validate()
    except ValueError:
        return
    image = avsplat.render(cloud_of(random_cloud_arrays(np.random.default_rng(0), 5)), cam)
    assert np.asarray(image.color).shape == (height, width, 3)


@settings(max_examples=30, **SETTINGS)
@given(fx=st.floats(1, 1e4), cx=st.floats(-100, 100), width=st.integers(1, 5000), height=st.integers(1, 5000),
       eye=st.lists(st.floats(-10, 10), min_size=3, max_size=3))
def test_camera_json_round_trip(tmp_path, fx, cx, width, height, eye):
    assume(np.linalg.norm(eye) > 1e-3)
    try:
        cam = avsplat.Camera.look_at(np.array(eye), np.zeros(3), np.array([0, 0, 1.0]), 40, width, height)
    except ValueError as e:  # documented: an up vector parallel to the view direction
        assert "parallel" in str(e)
        assert np.linalg.norm(np.cross(eye, [0, 0, 1.0])) < 1e-3 * np.linalg.norm(eye)
        return
    cam2 = avsplat.Camera(fx, fx * 1.5, cx, cx + 1, width, height, cam.world_to_camera)
    path = tmp_path / "cam.json"
    avsplat.write_camera_json(str(path), cam2)
    back = avsplat.read_camera_json(str(path))
    assert (back.fx, back.fy, back.cx, back.cy, back.width, back.height) == (cam2.fx, cam2.fy, cam2.cx, cam2.cy,
                                                                              width, height)
    np.testing.assert_array_equal(back.world_to_camera, cam2.world_to_camera)


# ---- gaussians_from_point_maps -----------------------------------------------------------------

@settings(max_examples=40, **SETTINGS)
@given(s=st.integers(1, 3), h=st.integers(1, 6), w=st.integers(1, 6), dtype=DTYPES, bad=st.one_of(st.none(), EXTREMES),
       with_conf=st.booleans(), seed=st.integers(0, 2**16))
def test_gaussians_from_point_maps_gives_one_gaussian_per_valid_pixel_or_a_value_error(s, h, w, dtype, bad,
                                                                                       with_conf, seed):
    rng = np.random.default_rng(seed)
    points = rng.normal(size=(s, h, w, 3)) + np.array([0, 0, 3.0])
    if bad is not None:
        points[0, 0, 0, 1] = bad
    colors = rng.uniform(0, 1, (s, h, w, 3)).astype(dtype)
    conf = rng.normal(size=(s, h, w)) if with_conf else None
    try:
        cloud = avsplat.gaussians_from_point_maps(points.astype(np.float64), colors, conf)
    except ValueError as e:
        nonfinite = bad is not None and not np.isfinite(np.float32(bad))
        if "at least 2 valid points" in str(e):  # documented for the kNN scale
            assert s * h * w - nonfinite < 2
        else:
            assert "points" in str(e) and nonfinite
        return
    assert len(cloud) <= s * h * w
    assert np.isfinite(np.asarray(cloud.means)).all() and (np.asarray(cloud.scales) > 0).all()


@settings(max_examples=30, **SETTINGS)
@given(shape=st.lists(st.integers(0, 4), min_size=0, max_size=5))
def test_gaussians_from_point_maps_wrong_shapes_name_the_argument(shape):
    points = np.zeros(shape, np.float32)
    assume(not (points.ndim == 4 and points.shape[-1] == 3) and not (points.ndim == 2 and points.shape[-1] == 3))
    with pytest.raises(ValueError, match="points"):
        avsplat.gaussians_from_point_maps(points, np.zeros_like(points))


# ---- metrics -----------------------------------------------------------------------------------

@settings(max_examples=50, **SETTINGS)
@given(h=st.integers(1, 24), w=st.integers(1, 24), c=st.sampled_from([None, 1, 3]), dtype=DTYPES,
       seed=st.integers(0, 2**16))
def test_psnr_matches_numpy_and_ssim_of_an_image_with_itself_is_one(h, w, c, dtype, seed):
    rng = np.random.default_rng(seed)
    shape = (h, w) if c is None else (h, w, c)
    a = rng.uniform(0, 1, shape).astype(dtype)
    b = rng.uniform(0, 1, shape).astype(dtype)
    a32, b32 = a.astype(np.float32).astype(np.float64), b.astype(np.float32).astype(np.float64)
    mse = np.mean((a32 - b32) ** 2)
    got = avsplat.psnr(a, b)
    if mse == 0:
        assert got == np.inf
    else:
        assert got == pytest.approx(10 * np.log10(1.0 / mse), rel=1e-5, abs=1e-5)
    assert avsplat.psnr(a, a) == np.inf
    if h >= 11 and w >= 11:
        assert avsplat.ssim(a, a) == pytest.approx(1.0, abs=1e-6)
        assert -1.0 <= avsplat.ssim(a, b) <= 1.0


@settings(max_examples=30, **SETTINGS)
@given(sa=st.lists(st.integers(0, 5), min_size=0, max_size=4), sb=st.lists(st.integers(0, 5), min_size=0, max_size=4))
def test_metrics_on_mismatched_or_malformed_images_raise_value_error(sa, sb):
    # As documented: psnr takes arrays of any one shape (not empty); ssim (H, W) or (H, W, C)
    # images with every size > 0.
    a, b = np.zeros(sa, np.float32), np.zeros(sb, np.float32)
    psnr_ok = a.shape == b.shape and a.size > 0
    ssim_ok = a.shape == b.shape and a.ndim in (2, 3) and a.size > 0
    for f, ok in ((avsplat.psnr, psnr_ok), (avsplat.ssim, ssim_ok)):
        if ok:
            assert f(a, b) in (np.inf, 1.0)
        else:
            with pytest.raises(ValueError):
                f(a, b)


@settings(max_examples=40, **SETTINGS)
@given(na=st.integers(1, 40), nb=st.integers(1, 40), seed=st.integers(0, 2**16))
def test_chamfer_distance_equals_brute_force(na, nb, seed):
    rng = np.random.default_rng(seed)
    a, b = rng.normal(size=(na, 3)).astype(np.float32), rng.normal(size=(nb, 3)).astype(np.float32)
    d = np.sqrt(((a[:, None, :].astype(np.float64) - b[None, :, :]) ** 2).sum(-1))
    got = avsplat.chamfer_distance(a, b)
    # Both symmetric conventions in use are means of nearest distances; accept exactly one.
    candidates = [d.min(1).mean() + d.min(0).mean(), 0.5 * (d.min(1).mean() + d.min(0).mean())]
    assert any(abs(got - c) <= 1e-5 * max(1.0, c) for c in candidates), (got, candidates)


# ---- readers on random and mutated bytes ---------------------------------------------------------

READERS = [avsplat.read_ply, avsplat.read_ply_data, avsplat.read_splat, avsplat.read_gaussians,
           avsplat.read_camera_json, avsplat.read_cameras_json]


def seeds():
    out = []
    for sub in ("ply", "splat", "cameras", "gaussians"):
        d = os.path.join(CORPUS, sub)
        if os.path.isdir(d):
            for name in sorted(os.listdir(d))[:4]:
                with open(os.path.join(d, name), "rb") as f:
                    out.append(f.read()[:4096])
    return out


SEEDS = seeds()


@settings(max_examples=150, **SETTINGS)
@given(data=st.one_of(st.binary(max_size=600),
                      st.tuples(st.sampled_from(range(len(SEEDS))), st.integers(0, 4095), st.integers(0, 255),
                                st.integers(0, 4096))),
       reader=st.sampled_from(READERS), suffix=st.sampled_from([".ply", ".splat", ".json"]))
def test_readers_on_random_and_mutated_bytes_give_a_result_or_os_error(tmp_path, data, reader, suffix):
    if isinstance(data, tuple):  # a seed file with one byte set and possibly cut short
        k, at, byte, cut = data
        raw = bytearray(SEEDS[k])
        if raw:
            raw[at % len(raw)] = byte
        data = bytes(raw[:cut])
    path = tmp_path / ("input" + suffix)
    path.write_bytes(data)
    try:
        reader(str(path))
    except OSError as e:
        assert str(path) in str(e) or "input" in str(e)
