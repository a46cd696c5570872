"""avsplat.plotting with the Agg backend: the figures hold the artists and numbers they claim.

The PSNR in show_comparison's title is checked against avsplat.psnr, the histograms against
numpy counts of the fusion diagnostics, the scatter against the voxels it subsamples.
"""
import matplotlib

matplotlib.use("Agg")  # before pyplot is imported anywhere: no display needed

import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402

import avsplat  # noqa: E402
from avsplat import plotting  # noqa: E402


@pytest.fixture(autouse=True)
def close_figures():
    yield
    plt.close("all")


def images(seed=0, h=12, w=16):
    rng = np.random.default_rng(seed)
    a = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
    b = np.clip(a + rng.normal(0, 0.05, a.shape), 0, 1).astype(np.float32)
    return a, b


def fusion_result(n=2000, seed=1):
    rng = np.random.default_rng(seed)
    # Clusters of very different sizes so that occupancy spans orders of magnitude.
    centres = rng.uniform(-2, 2, (40, 3))
    pick = np.minimum(rng.zipf(1.6, n), 40) - 1
    pos = (centres[pick] + rng.normal(0, 0.05, (n, 3))).astype(np.float32)
    return avsplat.fuse_voxels(pos, rng.normal(size=(n, 2)), 0.2, confidence=rng.normal(size=n))


def test_show_comparison_panels_and_psnr_title():
    a, b = images()
    fig = plotting.show_comparison(a, b, title="view 3")
    assert isinstance(fig, matplotlib.figure.Figure)
    panels = fig.axes[:3]
    assert len(fig.axes) == 4  # three panels and the error colour bar
    assert [len(ax.images) for ax in panels] == [1, 1, 1]
    np.testing.assert_array_equal(panels[0].images[0].get_array(), a)
    np.testing.assert_array_equal(panels[1].images[0].get_array(), b)
    np.testing.assert_allclose(panels[2].images[0].get_array(), np.abs(a - b).mean(axis=2), rtol=1e-6)
    assert panels[0].get_title() == f"rendered (PSNR {avsplat.psnr(a, b):.2f} dB)"
    assert fig._suptitle.get_text() == "view 3"


def test_show_comparison_accepts_render_results_and_given_axes():
    cloud = avsplat.GaussianCloud([[0, 0, 3.0]], [[0.3] * 3], [[1, 0, 0, 0]], [0.8], np.ones((1, 1, 3)))
    cam = avsplat.Camera(30, 30, 16, 12, 32, 24)
    r = avsplat.render(cloud, cam)
    fig, axes = plt.subplots(1, 3)
    assert plotting.show_comparison(r, r, axes=axes) is fig
    assert axes[0].get_title() == "rendered (PSNR inf dB)"  # identical images
    assert axes[2].images[0].get_clim() == (0, 1e-6)  # zero error: the scale floor


def test_show_comparison_rejects_wrong_shapes():
    a, b = images()
    with pytest.raises(ValueError, match=r"H x W x 3 image, got shape \(12, 16\)"):
        plotting.show_comparison(a[..., 0], b)
    with pytest.raises(ValueError, match=r"rendered \(12, 16, 3\) and reference \(6, 16, 3\) differ"):
        plotting.show_comparison(a, b[:6])


def test_occupancy_temperature_histograms_count_every_voxel():
    r = fusion_result()
    assert r.occupancy.max() >= 20  # the log axis has something to show
    fig = plotting.plot_occupancy_temperature(r, bins=30)
    assert isinstance(fig, matplotlib.figure.Figure) and len(fig.axes) == 2
    occ_ax, tau_ax = fig.axes
    assert occ_ax.get_xscale() == "log"
    assert sum(p.get_height() for p in occ_ax.patches) == len(r)
    assert len(tau_ax.patches) == 30
    assert sum(p.get_height() for p in tau_ax.patches) == np.isfinite(r.temperature).sum()
    # The mean policy's temperatures are inf: left out of the histogram, not an error.
    mean = avsplat.fuse_voxels(np.zeros((4, 3)), np.zeros((4, 1)), 1.0, policy="mean")
    fig = plotting.plot_occupancy_temperature(mean)
    assert sum(p.get_height() for p in fig.axes[1].patches) == 0


def test_temperature_vs_occupancy_scatter_subsamples_with_its_seed():
    r = fusion_result()
    fig = plotting.plot_temperature_vs_occupancy(r)
    assert isinstance(fig, matplotlib.figure.Figure) and len(fig.axes) == 2  # plot and colour bar
    ax = fig.axes[0]
    (sc,) = ax.collections
    np.testing.assert_array_equal(sc.get_offsets(), np.column_stack([r.occupancy, r.temperature]))
    np.testing.assert_allclose(sc.get_array(), r.reliability)
    assert ax.get_xscale() == "log" and fig.axes[1].get_ylabel() == "reliability"
    few = plotting.plot_temperature_vs_occupancy(r, max_points=10, seed=3).axes[0].collections[0]
    again = plotting.plot_temperature_vs_occupancy(r, max_points=10, seed=3).axes[0].collections[0]
    assert len(few.get_offsets()) == 10
    np.testing.assert_array_equal(few.get_offsets(), again.get_offsets())


class FakeResult:
    def __init__(self, occupancy, temperature, reliability):
        self.occupancy, self.temperature, self.reliability = occupancy, temperature, reliability


def test_fusion_plots_reject_wrong_shapes_and_empty_results():
    bad = FakeResult(np.ones(5, np.int32), np.ones((5, 2)), np.ones(5))
    with pytest.raises(ValueError, match=r"result.temperature: expected shape \(5,\), got \(5, 2\)"):
        plotting.plot_occupancy_temperature(bad)
    short = FakeResult(np.ones(5, np.int32), np.ones(5), np.ones(4))
    with pytest.raises(ValueError, match=r"result.reliability: expected shape \(5,\), got \(4,\)"):
        plotting.plot_temperature_vs_occupancy(short)
    empty = avsplat.fuse_voxels(np.zeros((0, 3)), np.zeros((0, 1)), 1.0)
    with pytest.raises(ValueError, match="no fused voxels"):
        plotting.plot_occupancy_temperature(empty)
    with pytest.raises(ValueError, match="no fused voxels"):
        plotting.plot_temperature_vs_occupancy(empty)
