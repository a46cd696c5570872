"""The CPU renderer's tile kernels from Python: AVSPLAT_CPU_KERNEL=scalar (the portable kernel),
=avx2 and =avx512 give the same image bit for bit, each matches the numpy brute-force renderer of
test_render.py, and an unknown value is refused (lib/src/render/cpu/cpu_kernel.h)."""
import numpy as np
import pytest

import avsplat
from test_render import assert_matches_numpy, numpy_render, random_cloud
from test_render_workspace import assert_same


def render_with(monkeypatch, kernel, *args, **kwargs):
    monkeypatch.setenv("AVSPLAT_CPU_KERNEL", kernel)
    return avsplat.render(*args, **kwargs)


def vector_or_skip(monkeypatch, kernel, *args, **kwargs):
    try:
        return render_with(monkeypatch, kernel, *args, **kwargs)
    except ValueError as e:
        if "has no AVX" in str(e):
            pytest.skip(f"this build or CPU has no {kernel} kernel")
        raise


@pytest.mark.parametrize("kernel", ["avx2", "avx512"])
def test_scalar_and_vector_kernels_give_the_same_image(monkeypatch, kernel):
    cloud = random_cloud(3000, 21, max_opacity=1.0, sh_degree=3)
    cam = avsplat.Camera.look_at([0.1, -0.2, -0.4], [0, 0, 4], [0, -1, 0], 70.0, 203, 117)
    scalar = render_with(monkeypatch, "scalar", cloud, cam, background=(0.1, 0.2, 0.3))
    vec = vector_or_skip(monkeypatch, kernel, cloud, cam, background=(0.1, 0.2, 0.3))
    assert scalar.stats.blends > 100000
    assert np.max(np.abs(scalar.color - vec.color)) <= 1e-6
    assert_same(scalar, vec)


@pytest.mark.parametrize("kernel", ["scalar", "avx2", "avx512"])
def test_each_kernel_matches_numpy_brute_force(monkeypatch, kernel):
    cloud = random_cloud(120, 5)
    cam = avsplat.Camera.look_at([0.2, -0.3, -0.5], [0, 0, 4], [0, -1, 0], 75.0, 64, 48)
    background = (0.2, 0.3, 0.9)
    if kernel != "scalar":
        r = vector_or_skip(monkeypatch, kernel, cloud, cam, background=background)
    else:
        r = render_with(monkeypatch, kernel, cloud, cam, background=background)
    assert_matches_numpy(r, numpy_render(cloud, cam, background), 2e-5)  # test_render.py's float32 tolerance


def test_unknown_kernel_is_refused(monkeypatch):
    cloud = random_cloud(10, 1)
    cam = avsplat.Camera(90.0, 90.0, 32.0, 24.0, 64, 48)
    with pytest.raises(ValueError, match="AVSPLAT_CPU_KERNEL"):
        render_with(monkeypatch, "sse9", cloud, cam)
