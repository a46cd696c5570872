"""avsplat.psnr and avsplat.ssim against numpy references written here.

The SSIM reference follows the 3DGS evaluation code: an 11 x 11 Gaussian window with sigma 1.5,
applied per channel as a same-size convolution with zero padding, here as two 1D passes.
"""
import numpy as np
import pytest

import avsplat


def gaussian_window(size=11, sigma=1.5):
    x = np.arange(size) - size // 2
    g = np.exp(-(x ** 2) / (2 * sigma ** 2))
    return g / g.sum()


def filter_same_zero_pad(plane, g):
    """Separable same-size filtering of a 2D array with zero padding."""
    half = len(g) // 2
    h, w = plane.shape
    padded = np.zeros((h + 2 * half, w + 2 * half))
    padded[half:half + h, half:half + w] = plane
    rows = sum(g[k] * padded[:, k:k + w] for k in range(len(g)))
    return sum(g[k] * rows[k:k + h, :] for k in range(len(g)))


def numpy_ssim(a, b):
    a = np.asarray(a, np.float64)
    b = np.asarray(b, np.float64)
    if a.ndim == 2:
        a, b = a[..., None], b[..., None]
    g = gaussian_window()
    c1, c2 = 0.01 ** 2, 0.03 ** 2
    maps = []
    for c in range(a.shape[2]):
        x, y = a[..., c], b[..., c]
        mx, my = filter_same_zero_pad(x, g), filter_same_zero_pad(y, g)
        sxx = filter_same_zero_pad(x * x, g) - mx * mx
        syy = filter_same_zero_pad(y * y, g) - my * my
        sxy = filter_same_zero_pad(x * y, g) - mx * my
        maps.append(((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx ** 2 + my ** 2 + c1) * (sxx + syy + c2)))
    return float(np.mean(maps))


def numpy_psnr(a, b, max_value=1.0):
    mse = np.mean((np.asarray(a, np.float64) - np.asarray(b, np.float64)) ** 2)
    return 10 * np.log10(max_value ** 2 / mse)


@pytest.mark.parametrize("shape", [(24, 31, 3), (40, 17, 3), (9, 12), (30, 30, 1)])
def test_ssim_matches_numpy_reference(shape):
    rng = np.random.default_rng(sum(shape))
    a = rng.random(shape).astype(np.float32)
    b = np.clip(a + rng.normal(0, 0.08, shape), 0, 1).astype(np.float32)
    value = avsplat.ssim(a, b)
    assert value == pytest.approx(numpy_ssim(a, b), abs=1e-6)
    assert value < 1.0
    assert avsplat.ssim(a, a) == pytest.approx(1.0, abs=1e-12)


def test_ssim_of_smooth_images_against_numpy():
    y, x = np.mgrid[0:48, 0:64] / 64.0
    a = np.stack([np.sin(6 * x), np.cos(4 * y), x * y], axis=-1).astype(np.float32) * 0.5 + 0.5
    b = np.roll(a, 1, axis=1)
    assert avsplat.ssim(a, b) == pytest.approx(numpy_ssim(a, b), abs=1e-6)


def test_psnr_matches_numpy_reference():
    rng = np.random.default_rng(3)
    a = rng.random((20, 30, 3)).astype(np.float32)
    b = np.clip(a + rng.normal(0, 0.05, a.shape), 0, 1).astype(np.float32)
    assert avsplat.psnr(a, b) == pytest.approx(numpy_psnr(a, b), abs=1e-9)
    assert avsplat.psnr(a, b, max_value=255.0) == pytest.approx(numpy_psnr(a, b, 255.0), abs=1e-9)
    assert avsplat.psnr(a, a) == float("inf")
    # float64 input is accepted and converted to float32
    assert avsplat.psnr(a.astype(np.float64), b) == pytest.approx(numpy_psnr(a, b), abs=1e-9)


def test_metrics_reject_mismatched_shapes_and_bad_values():
    a = np.zeros((8, 8, 3), np.float32)
    with pytest.raises(ValueError, match="b: expected shape"):
        avsplat.ssim(a, np.zeros((8, 9, 3), np.float32))
    with pytest.raises(ValueError, match="b: expected shape"):
        avsplat.psnr(a, np.zeros((8, 8), np.float32))
    with pytest.raises(ValueError, match="a: expected"):
        avsplat.ssim(np.zeros(5, np.float32), np.zeros(5, np.float32))
    bad = a.copy()
    bad[1, 2, 0] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        avsplat.ssim(a, bad)


def test_psnr_of_uint8_images_uses_their_0_255_range():
    rng = np.random.default_rng(4)
    a = rng.integers(0, 256, size=(8, 8, 3), dtype=np.uint8)
    b = np.clip(a.astype(int) + rng.integers(-3, 4, size=a.shape), 0, 255).astype(np.uint8)
    mse = np.mean((a.astype(np.float64) - b) ** 2)
    assert avsplat.psnr(a, b) == pytest.approx(10 * np.log10(255.0**2 / mse), rel=1e-6)
    assert avsplat.psnr(a, b) == pytest.approx(avsplat.psnr(a / 255.0, b / 255.0), rel=1e-6)
    assert avsplat.psnr(a.astype(np.uint16), b.astype(np.uint16)) == pytest.approx(10 * np.log10(65535.0**2 / mse),
                                                                                   rel=1e-6)
    assert avsplat.psnr(a, b, max_value=255.0) == pytest.approx(avsplat.psnr(a, b), rel=1e-12)
    with pytest.raises(ValueError, match="a is uint8, b is float32"):
        avsplat.psnr(a, b.astype(np.float32))
    # Signed integers: the dtype's whole range, as scikit-image's data_range (65535 for int16).
    assert avsplat.psnr(a.astype(np.int16), b.astype(np.int16)) == pytest.approx(
        10 * np.log10(65535.0**2 / mse), rel=1e-6)
    assert avsplat.psnr(a > 128, a > 128) == np.inf
