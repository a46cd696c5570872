"""avsplat.render with backend="cuda".

Without a CUDA renderer or device, backend="cuda" must raise avsplat.DeviceError (a RuntimeError)
that says which of the two is missing. With a device, the CUDA images must match the CPU
renderer's: max abs error <= 1e-4 on colour and alpha, identical contributor counts and counters
(the GPU path performs the CPU's float operations, see lib/src/render/cuda/kernel_bodies.h). The GPU cases
are skipped, saying so, only when the error says the renderer or the device is missing; any
other DeviceError fails them.
"""
import numpy as np
import pytest

import avsplat

MISSING = ("no CUDA device: ", "render: avsplat was built without the CUDA renderer")


def random_cloud(n, seed, sh_degree=3):
    rng = np.random.default_rng(seed)
    means = rng.uniform(-1.6, 1.6, (n, 3))
    scales = np.exp(rng.uniform(np.log(0.004), np.log(0.25), (n, 3)))
    quats = rng.normal(size=(n, 4))
    opacities = rng.uniform(0.0, 1.0, n)
    k = (sh_degree + 1) ** 2
    sh = rng.normal(size=(n, k, 3)) * np.where(np.arange(k) == 0, 1.2, 0.3)[None, :, None]
    return avsplat.GaussianCloud(means, scales, quats, opacities, sh)


def camera(width=157, height=93):
    return avsplat.Camera.look_at([2.1, -0.7, 2.8], [0.05, 0.0, 0.0], [0, 1, 0], 55.0, width, height,
                                  near=0.2, far=6.0)


def cuda_or_reason(cloud, cam, **options):
    """(result, None) when the CUDA renderer ran, (None, message) when it or a device is missing."""
    try:
        return avsplat.render(cloud, cam, backend="cuda", **options), None
    except avsplat.DeviceError as e:
        message = str(e)
        assert message.startswith(MISSING), f"unexpected DeviceError: {message}"
        return None, message


def test_cuda_unavailable_is_a_clear_device_error():
    cloud = random_cloud(20, 1)
    result, reason = cuda_or_reason(cloud, camera())
    if result is not None:
        pytest.skip("a CUDA device is present: the comparison tests cover backend='cuda'")
    assert issubclass(avsplat.DeviceError, RuntimeError)
    with pytest.raises(RuntimeError, match="no CUDA device: |built without the CUDA renderer"):
        avsplat.render(cloud, camera(), backend="cuda")
    # The option checks still come first, with the usual ValueError.
    with pytest.raises(ValueError, match="alpha_threshold"):
        avsplat.render(cloud, camera(), backend="cuda", alpha_threshold=0.0)


@pytest.mark.parametrize("precision", ["float32", "float64"])
@pytest.mark.parametrize("antialiased", [False, True])
def test_cuda_matches_cpu(precision, antialiased):
    cloud = random_cloud(20000, 2)
    cam = camera(333, 211)
    options = dict(precision=precision, antialiased=antialiased, background=(0.1, 0.2, 0.3))
    gpu, reason = cuda_or_reason(cloud, cam, **options)
    if gpu is None:
        pytest.skip(f"SKIPPED: {reason}")
    cpu = avsplat.render(cloud, cam, backend="cpu", **options)
    assert np.abs(gpu.color - cpu.color).max() <= 1e-4
    assert np.abs(gpu.alpha - cpu.alpha).max() <= 1e-4
    np.testing.assert_allclose(gpu.depth, cpu.depth, rtol=1e-4, atol=1e-4)
    np.testing.assert_array_equal(gpu.contributors, cpu.contributors)
    for name in ("gaussians", "visible", "tile_instances", "blends", "contributions"):
        assert getattr(gpu.stats, name) == getattr(cpu.stats, name), name
    assert cpu.stats.visible > 1000  # the scene is not trivially empty


def test_cuda_empty_cloud_gives_the_background():
    cloud = avsplat.GaussianCloud.empty(0, 2)
    gpu, reason = cuda_or_reason(cloud, camera(40, 20), background=(0.25, 0.5, 0.75))
    if gpu is None:
        pytest.skip(f"SKIPPED: {reason}")
    assert gpu.color.shape == (20, 40, 3)
    np.testing.assert_array_equal(gpu.color, np.broadcast_to([0.25, 0.5, 0.75], (20, 40, 3)).astype(np.float32))
    assert not gpu.alpha.any()
    assert not gpu.contributors.any()
