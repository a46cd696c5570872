"""Report `views`: which input views to fuse: greedy coverage order against capture order."""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Sequence

import numpy as np

import avsplat

from ..render import render
from ._common import Progress, Row, aggregate, best_time
from ._report import machine, md_table, write_report

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..core import GaussianCloud
    from ..sim import Predictions

# How the first n views are chosen.
STRATEGIES: tuple[str, ...] = ("coverage", "coverage_confident", "capture", "uniform")


@dataclass
class ViewsSettings:
    """What run_views measures; the defaults are the committed report's."""

    views: int = 64  # input views simulated (an arc of cameras, in capture order)
    counts: tuple[int, ...] = (2, 4, 8, 16, 32, 64)  # views fused
    width: int = 160
    height: int = 120
    target_views: int = 6
    seeds: tuple[int, ...] = (0, 1, 2)
    voxel: float = 0.02  # fusion voxel, about one pixel footprint at the centre of the scene
    coverage_voxel: float = 0.04  # the voxel of the coverage selection (about 2 footprints)
    # coverage_confident: a coarser voxel, and only pixels whose confidence is above this quantile
    # of the valid pixels' confidences (chosen on seed 0 of this scene: optimistic, see the report).
    confident_voxel: float = 0.08
    confident_quantile: float = 0.5
    policy: str = "occupancy"

    @staticmethod
    def quick() -> "ViewsSettings":
        return ViewsSettings(views=6, counts=(2, 6), width=40, height=30, target_views=1, seeds=(0,), voxel=0.05,
                             coverage_voxel=0.1, confident_voxel=0.2)


def choose_views(preds: Predictions, strategy: str, n: int, s: ViewsSettings) -> tuple[list[int], float]:
    """The first n views of one strategy: coverage (select_views_by_coverage on the predicted
    points, valid pixels only), coverage_confident (the same at s.confident_voxel, counting only
    pixels whose confidence is above the s.confident_quantile quantile), capture (the first n in
    capture order) or uniform (n evenly spaced over the capture order). Returns the view indices
    and the selection time in seconds."""
    views = preds.views
    if strategy == "capture":
        return list(range(n)), 0.0
    if strategy == "uniform":
        return sorted({int(round(i * (views - 1) / max(n - 1, 1))) for i in range(n)}), 0.0
    t0 = time.perf_counter()
    if strategy == "coverage":
        r = avsplat.select_views_by_coverage(preds.points, s.coverage_voxel, budget=n, valid=preds.valid)
    else:
        conf, valid = preds.confidence, preds.valid
        threshold = float(np.quantile(conf[valid], s.confident_quantile))
        r = avsplat.select_views_by_coverage(preds.points, s.confident_voxel, budget=n, valid=valid, confidence=conf,
                                             min_confidence=threshold)
    return r.order.tolist(), time.perf_counter() - t0


def subset_gaussians(preds: Predictions, views: Sequence[int]) -> GaussianCloud:
    """Predictions.gaussians() restricted to some views: one Gaussian per valid pixel of each."""
    idx = np.asarray(views)
    return avsplat.gaussians_from_point_maps(preds.points[idx], preds.colors[idx], preds.confidence[idx],
                                             [preds.cameras[i] for i in views], preds.normals[idx],
                                             preds.valid[idx])


def run_views(out_dir: str, settings: ViewsSettings | None = None, quick: bool = False) -> list[Row]:
    """Greedy coverage view selection against capture order (AVSplat's Assist-View idea on the
    geometry side): with n of S input views, which n give the best fused scene?

    For each seed: simulate_predictions(views=S) -> for each n and strategy (coverage: greedy
    coverage of the predicted points; capture: the first n views; uniform: n views evenly spaced
    over the capture order) -> one Gaussian per valid pixel of those views -> fuse_gaussians (one
    policy, fixed voxel) -> render the held-out views -> PSNR and SSIM against the ray-cast ground
    truth. Writes views.csv, views.png (PSNR and fusion time against n) and views.md. Returns the rows.

    Parameters
    ----------
    out_dir : str
        Folder for views.csv, views.png and views.md.
    settings : ViewsSettings, optional
        The report's settings; the defaults when None.
    quick : bool
        Tiny settings (seconds; for smoke tests, not for conclusions).

    Returns
    -------
    list of Row
        One row per measurement, as written to views.csv.
    """
    s = settings or (ViewsSettings.quick() if quick else ViewsSettings())
    os.makedirs(out_dir, exist_ok=True)
    targets = avsplat.target_cameras(views=s.views, target_views=s.target_views, width=s.width, height=s.height)
    truth = [avsplat.ground_truth(cam).color.copy() for cam in targets]
    progress = Progress("views", len(s.seeds) * len(s.counts))
    rows: list[Row] = []
    for seed in s.seeds:
        preds = avsplat.simulate_predictions(views=s.views, width=s.width, height=s.height,
                                             target_views=s.target_views, seed=seed)
        for n in s.counts:
            for strategy in STRATEGIES:
                chosen, select_s = choose_views(preds, strategy, n, s)
                cloud = subset_gaussians(preds, chosen)
                result, fuse_s = best_time(lambda: avsplat.fuse_gaussians(cloud, s.voxel, policy=s.policy), 1)
                psnr, ssim = [], []
                for cam, gt in zip(targets, truth):
                    image = render(result.cloud, cam).color
                    psnr.append(avsplat.psnr(image, gt))
                    ssim.append(avsplat.ssim(image, gt))
                rows.append(dict(seed=seed, n=n, strategy=strategy, views=" ".join(map(str, chosen)),
                                 psnr=float(np.mean(psnr)), ssim=float(np.mean(ssim)), samples=len(cloud),
                                 gaussians=len(result), select_s=select_s, fusion_s=fuse_s))
            progress.advance(f"seed {seed}, {n} views")
    columns = ["seed", "n", "strategy", "psnr", "ssim", "samples", "gaussians", "select_s", "fusion_s", "views"]
    write_report(out_dir, "views", rows, columns, plot=lambda plt: _plot(plt, rows, s),
                 title="View selection by greedy coverage", body=_markdown(rows, s), quick=quick, dpi=100)
    return rows


def _plot(plt: ModuleType, rows: Sequence[Row], s: ViewsSettings) -> Figure:
    fig, axes = plt.subplots(1, 3, figsize=(16, 4.4))
    colors = {"coverage": "tab:green", "coverage_confident": "tab:olive", "capture": "tab:gray", "uniform": "tab:blue"}
    for ax, (value, label) in zip(axes, [("psnr", "PSNR (dB), held-out views"), ("ssim", "SSIM, held-out views"),
                                         ("fusion_s", "fusion time (s)")]):
        agg = aggregate(rows, ["strategy", "n"], value)
        for strategy in STRATEGIES:
            xs = [n for n in s.counts if (strategy, n) in agg]
            ax.errorbar(xs, [agg[(strategy, n)][0] for n in xs], yerr=[agg[(strategy, n)][1] for n in xs],
                        marker="o", markersize=4, capsize=3, color=colors[strategy], label=strategy)
        ax.set_xscale("log")
        ax.set_xticks(list(s.counts))
        ax.set_xticklabels([str(n) for n in s.counts])
        ax.minorticks_off()
        ax.set_xlabel("views fused n")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"{s.views} simulated views, {s.width}x{s.height}; {s.policy} fusion at voxel {s.voxel:g}; "
                 f"coverage voxel {s.coverage_voxel:g}; {len(s.seeds)} seed(s)")
    return fig


def _markdown(rows: Sequence[Row], s: ViewsSettings) -> str:
    key = ["strategy", "n"]
    psnr, ssim = aggregate(rows, key, "psnr"), aggregate(rows, key, "ssim")
    fuse, select = aggregate(rows, key, "fusion_s"), aggregate(rows, key, "select_s")
    count = aggregate(rows, key, "gaussians")
    table = []
    for n in s.counts:
        for strategy in STRATEGIES:
            k = (strategy, n)
            table.append([n, strategy, f"{psnr[k][0]:.2f} ± {psnr[k][1]:.2f}", f"{ssim[k][0]:.4f} ± {ssim[k][1]:.4f}",
                          f"{count[k][0]:.0f}", f"{fuse[k][0]:.3f}", f"{select[k][0]:.4f}"])
    facts = []
    full = max(s.counts)
    for n in s.counts:
        gap = {(a, b): psnr[(a, n)][0] - psnr[(b, n)][0] for a in ("coverage", "coverage_confident")
               for b in ("capture", "uniform")}
        facts.append(f"- {n} views: coverage - capture {gap[('coverage', 'capture')]:+.2f} dB, coverage - uniform "
                     f"{gap[('coverage', 'uniform')]:+.2f} dB, coverage_confident - uniform "
                     f"{gap[('coverage_confident', 'uniform')]:+.2f} dB; best of them minus all {full} views "
                     f"{max(psnr[(k, n)][0] for k in STRATEGIES) - psnr[('uniform', full)][0]:+.2f} dB.")
    return f"""With n of {s.views} input views, which n give the best fused scene? Simulated predictions of the default
scene (avsplat.simulate_predictions, default errors), {s.width}x{s.height} per view, cameras on an arc in capture
order. Strategies: **coverage** picks views by greedy voxel coverage of their predicted points
(avsplat.select_views_by_coverage, voxel {s.coverage_voxel:g}, valid pixels); **coverage_confident** does the
same at voxel {s.confident_voxel:g} counting only pixels whose confidence is above the
{s.confident_quantile:g} quantile (a setting chosen by trying a few on seed 0 of this scene, so its figures are
optimistic); **capture** takes the first n views; **uniform** takes n views evenly spaced over the capture
order, which on this scene's regular arc of cameras is a strong baseline that needs no geometry. The chosen views' per-pixel
Gaussians are fused ({s.policy}, voxel {s.voxel:g}) and rendered at {s.target_views} held-out views; PSNR and SSIM
against the ray-cast ground truth, mean ± standard deviation over {len(s.seeds)} seed(s). Times on {machine()}:
fusion is the fuse_gaussians call, selection the select_views_by_coverage call.

{md_table(["n", "strategy", "PSNR (dB)", "SSIM", "Gaussians", "fusion (s)", "selection (s)"], table)}

{chr(10).join(facts)}
"""
