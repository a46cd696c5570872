"""Small matplotlib helpers for notebooks.

matplotlib is imported when a function is called, so ``import avsplat`` never needs it. Every
function draws into the axes it is given (or a new figure) and returns the figure, so notebooks
can compose them.
"""

from __future__ import annotations

from types import ModuleType
from typing import TYPE_CHECKING, Sequence

import numpy as np
import numpy.typing as npt

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

    from .render import RenderResult


def _pyplot() -> ModuleType:
    try:
        import matplotlib.pyplot as plt
    except ImportError as e:  # pragma: no cover - depends on the machine
        raise ImportError("avsplat.plotting needs matplotlib (Debian: python3-matplotlib)") from e
    return plt


def _image(x: RenderResult | npt.ArrayLike) -> npt.NDArray[np.float32]:
    """H x W x 3 float array in [0, 1] from a RenderResult or an array."""
    a = np.asarray(getattr(x, "color", x), dtype=np.float32)
    if a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"expected an H x W x 3 image, got shape {a.shape}")
    return np.clip(a, 0.0, 1.0)


def _diagnostics(result: object, *names: str) -> list[npt.NDArray[np.generic]]:
    """The named per-voxel arrays of a fusion result, checked to be 1-D and of equal length."""
    arrays = [np.asarray(getattr(result, name)) for name in names]
    for name, a in zip(names, arrays):
        if a.ndim != 1 or len(a) != len(arrays[0]):
            raise ValueError(f"result.{name}: expected shape ({len(arrays[0])},), got {a.shape}")
    if len(arrays[0]) == 0:
        raise ValueError("result: no fused voxels to plot")
    return arrays


def show_comparison(rendered: RenderResult | npt.ArrayLike, reference: RenderResult | npt.ArrayLike,
                    title: str | None = None, axes: Sequence[Axes] | None = None,
                    error_scale: float | None = None) -> Figure:
    """Show a render, its reference and the per-pixel error side by side.

    Values are clipped to [0, 1] before display and scoring. The error map is the mean absolute
    error over the channels, shown with a colour bar; the PSNR of `rendered` against
    `reference` goes into the title of the first panel.

    Parameters
    ----------
    rendered, reference : array_like, shape (H, W, 3), or RenderResult
        Images in [0, 1], or objects with a ``color`` attribute.
    title : str, optional
        A figure title.
    axes : sequence of 3 matplotlib Axes, optional
        Where to draw; None for a new 1 x 3 figure.
    error_scale : float, optional
        Upper limit of the error map's colours (default: its maximum).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        When an image is not H x W x 3 or the two shapes differ.
    """
    plt = _pyplot()
    a, b = _image(rendered), _image(reference)
    if a.shape != b.shape:
        raise ValueError(f"rendered {a.shape} and reference {b.shape} differ in shape")
    err = np.abs(a - b).mean(axis=2)
    mse = float(np.mean((a.astype(np.float64) - b) ** 2))
    psnr = float("inf") if mse == 0 else 10 * np.log10(1.0 / mse)
    if axes is None:
        fig, axes = plt.subplots(1, 3, figsize=(12, 4))
    fig = axes[0].figure
    axes[0].imshow(a)
    axes[0].set_title(f"rendered (PSNR {psnr:.2f} dB)")
    axes[1].imshow(b)
    axes[1].set_title("reference")
    im = axes[2].imshow(err, cmap="inferno", vmin=0, vmax=error_scale or max(float(err.max()), 1e-6))
    axes[2].set_title("|error| (mean over RGB)")
    fig.colorbar(im, ax=axes[2], fraction=0.046)
    for ax in axes:
        ax.set_axis_off()
    if title:
        fig.suptitle(title)
    return fig


def plot_occupancy_temperature(result: object, axes: Sequence[Axes] | None = None, bins: int = 50) -> Figure:
    """Histograms of voxel occupancy and temperature from a fusion result.

    Occupancy is drawn on a log axis since it spans orders of magnitude in dense-view scenes.
    Temperatures that are not finite (the ``mean`` policy's inf) are left out.

    Parameters
    ----------
    result : FeatureFusionResult or GaussianFusionResult
        What ``fuse_voxels`` / ``fuse_gaussians`` return (arrays ``occupancy`` and
        ``temperature``, one value per fused voxel).
    axes : sequence of 2 matplotlib Axes, optional
        Where to draw; None for a new 1 x 2 figure.
    bins : int
        Number of temperature bins (occupancy bins are integer, log-spaced).

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        When the arrays are not 1-D of one length or the result has no voxels.
    """
    plt = _pyplot()
    occ, tau = _diagnostics(result, "occupancy", "temperature")
    if axes is None:
        fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    fig = axes[0].figure
    edges = np.unique(np.geomspace(1, max(int(occ.max()), 2) + 1, bins).astype(int))
    axes[0].hist(occ, bins=edges, color="tab:blue")
    axes[0].set_xscale("log")
    axes[0].set_xlabel("samples per voxel (occupancy)")
    axes[0].set_ylabel("voxels")
    finite = tau[np.isfinite(tau)]
    axes[1].hist(finite, bins=bins, color="tab:orange")
    axes[1].set_xlabel("temperature")
    axes[1].set_ylabel("voxels")
    return fig


def plot_temperature_vs_occupancy(result: object, ax: Axes | None = None, max_points: int = 50000,
                                  seed: int = 0) -> Figure:
    """Scatter of temperature against occupancy, coloured by reliability.

    Shows Algorithm 2 at work: temperature falls with occupancy and rises where reliability is
    low.

    Parameters
    ----------
    result : FeatureFusionResult or GaussianFusionResult
        With ``occupancy``, ``temperature`` and ``reliability``, one value per voxel.
    ax : matplotlib Axes, optional
        Where to draw; None for a new figure.
    max_points : int
        At most this many voxels are drawn (a random subset).
    seed : int
        Seed of that subset.

    Returns
    -------
    matplotlib.figure.Figure

    Raises
    ------
    ValueError
        When the arrays are not 1-D of one length or the result has no voxels.
    """
    plt = _pyplot()
    occ, tau, rel = _diagnostics(result, "occupancy", "temperature", "reliability")
    idx = np.arange(len(occ))
    if len(idx) > max_points:
        idx = np.random.default_rng(seed).choice(idx, max_points, replace=False)
    if ax is None:
        fig, ax = plt.subplots(figsize=(6, 4))
    fig = ax.figure
    sc = ax.scatter(occ[idx], tau[idx], c=rel[idx], s=4, cmap="viridis", vmin=0, vmax=1)
    ax.set_xscale("log")
    ax.set_xlabel("occupancy (samples per voxel)")
    ax.set_ylabel("temperature")
    fig.colorbar(sc, ax=ax, label="reliability")
    return fig
