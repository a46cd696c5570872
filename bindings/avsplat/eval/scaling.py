"""Report `scaling`: dense-view scaling, views x fusion policy (AVSplat Table 1 / Fig. 4)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any, Sequence

import numpy as np
import numpy.typing as npt

import avsplat

from ..render import render
from ._common import POLICIES, Progress, Row, aggregate, best_time
from ._report import machine, md_table, write_report

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..core import Camera, GaussianCloud

@dataclass
class ScalingSettings:
    """What run_scaling measures; the defaults are the committed report's."""

    views: tuple[int, ...] = (3, 6, 16, 32, 48, 64)
    policies: tuple[str, ...] = POLICIES
    width: int = 160
    height: int = 120
    target_views: int = 6
    seeds: tuple[int, ...] = (0, 1, 2)
    # About one and two pixel footprints at the arc's centre (2.6 / fy = 0.020 at 160 x 120).
    voxel_sizes: tuple[float, ...] = (0.02, 0.04)
    # How fuse_gaussians combines the shapes: the library default (average of log-scales and
    # rotations, which keeps per-pixel sizes) and moment matching (covers the voxel's spread).
    shapes: tuple[str, ...] = ("average", "moment")
    unfused: bool = True  # also render the raw per-pixel Gaussians (no fusion) as a reference
    # Which simulated error drives the trend: the same runs with one error source switched off
    # (simulator options of simulator.h), at these view counts, first seed, first shape.
    ablation_views: tuple[int, ...] = (6, 64)
    # The same view sweep with the error models of real predictions (regimes.REALISTIC: optical
    # blur, per-view appearance, mixed pixels, head-feature noise), fusing the decoded per-pixel
    # Gaussians (Predictions.decoded_gaussians), first shape mode; ground truth with the inputs'
    # optics. Empty: skipped.
    realistic_seeds: tuple[int, ...] = (0, 1)

    @staticmethod
    def quick() -> "ScalingSettings":
        return ScalingSettings(views=(3, 6), width=40, height=30, target_views=1, seeds=(0,), voxel_sizes=(0.05,),
                               ablation_views=(3,), realistic_seeds=(0,))


# Simulator options (simulator.h) that switch one error source off, for the ablation.
ABLATIONS: dict[str, dict[str, Any]] = {
    "default": {},
    "no flying pixels": dict(flying_pixels=False),
    "no pose noise": dict(pose_noise_rot_deg=0.0, pose_noise_trans=0.0),
    "no depth noise": dict(depth_noise=0.0),
    "no noise": dict(flying_pixels=False, pose_noise_rot_deg=0.0, pose_noise_trans=0.0, depth_noise=0.0),
}


def _score(cloud: GaussianCloud, targets: Sequence[Camera],
           truth: Sequence[npt.NDArray[np.float32]]) -> tuple[float, float, float]:
    """Mean PSNR and SSIM over the targets, and the mean render time."""
    psnrs, ssims, seconds = [], [], 0.0
    for cam, gt in zip(targets, truth):
        r, t = best_time(lambda: render(cloud, cam), 1)
        seconds += t
        psnrs.append(avsplat.psnr(r.color, gt))
        ssims.append(avsplat.ssim(r.color, gt))
    return float(np.mean(psnrs)), float(np.mean(ssims)), seconds / len(targets)


# The condition of the rows with the error models of real predictions on.
REALISTIC_CONDITION = "realistic errors"


def _scaling_rows(cloud: GaussianCloud, views: int, seed: int, condition: str, shapes: Sequence[str],
                  s: ScalingSettings, targets: Sequence[Camera], truth: Sequence[npt.NDArray[np.float32]],
                  with_unfused: bool) -> list[Row]:
    rows: list[Row] = []
    for shape in shapes:
        for voxel in s.voxel_sizes:
            for policy in s.policies:
                result, fuse_s = best_time(
                    lambda: avsplat.fuse_gaussians(cloud, voxel, policy=policy, shape=shape), 1)
                psnr, ssim, render_s = _score(result.cloud, targets, truth)
                rows.append(dict(condition=condition, views=views, shape=shape, voxel=voxel, policy=policy,
                                 seed=seed, psnr=psnr, ssim=ssim, gaussians=len(result), samples=len(cloud),
                                 fusion_s=fuse_s, render_s=render_s))
    if with_unfused:
        psnr, ssim, render_s = _score(cloud, targets, truth)
        rows.append(dict(condition=condition, views=views, shape="", voxel="", policy="unfused", seed=seed,
                         psnr=psnr, ssim=ssim, gaussians=len(cloud), samples=len(cloud), fusion_s="",
                         render_s=render_s))
    return rows


def run_scaling(out_dir: str, settings: ScalingSettings | None = None, quick: bool = False) -> list[Row]:
    """Dense-view scaling (AVSplat Table 1 / Fig. 4): does occupancy-guided fusion keep improving as
    views are added while averaging saturates or degrades?

    For each seed and view count S: simulate_predictions(views=S) of the default scene -> one
    Gaussian per valid pixel (Predictions.gaussians) -> fuse_gaussians with each policy, shape
    mode and fixed voxel size -> render the held-out views -> PSNR and SSIM against ground_truth. The
    held-out cameras are the same for every S (target_cameras of the largest S), so a change with S
    is the views' doing, not the targets'. An ablation repeats the first seed at ablation_views with
    one simulated error source switched off at a time (first shape mode). Writes scaling.csv (one row
    per condition, seed, S, shape, voxel size and policy), scaling.png and scaling.md (mean over
    seeds +- standard deviation). Returns the rows.

    Parameters
    ----------
    out_dir : str
        Folder for scaling.csv, scaling.png and scaling.md.
    settings : ScalingSettings, optional
        The report's settings; the defaults when None.
    quick : bool
        Tiny settings (seconds; for smoke tests, not for conclusions).

    Returns
    -------
    list of Row
        One row per measurement, as written to scaling.csv.
    """
    s = settings or (ScalingSettings.quick() if quick else ScalingSettings())
    os.makedirs(out_dir, exist_ok=True)
    s_max = max(s.views)
    targets = avsplat.target_cameras(views=s_max, target_views=s.target_views, width=s.width, height=s.height)
    truth = [avsplat.ground_truth(cam).color.copy() for cam in targets]
    ablation = [(c, v) for c in ABLATIONS if c != "default" for v in s.ablation_views]
    progress = Progress("scaling", (len(s.seeds) + len(s.realistic_seeds)) * len(s.views) + len(ablation))
    rows: list[Row] = []
    for seed in s.seeds:
        for views in s.views:
            preds = avsplat.simulate_predictions(views=views, width=s.width, height=s.height,
                                                 target_views=min(s.target_views, views - 1), seed=seed)
            rows += _scaling_rows(preds.gaussians(), views, seed, "default", s.shapes, s, targets, truth, s.unfused)
            progress.advance(f"seed {seed}, {views} views")
    from .regimes import REALISTIC

    if s.realistic_seeds:
        realistic_truth = [avsplat.ground_truth(cam, footprint_sigma=REALISTIC["footprint_sigma"],
                                                specular=REALISTIC["specular"]).color.copy() for cam in targets]
    for seed in s.realistic_seeds:
        for views in s.views:
            preds = avsplat.simulate_predictions(views=views, width=s.width, height=s.height,
                                                 target_views=min(s.target_views, views - 1), seed=seed, **REALISTIC)
            rows += _scaling_rows(preds.decoded_gaussians(), views, seed, REALISTIC_CONDITION, s.shapes[:1], s,
                                  targets, realistic_truth, False)
            progress.advance(f"realistic errors, seed {seed}, {views} views")
    for condition, views in ablation:
        preds = avsplat.simulate_predictions(views=views, width=s.width, height=s.height,
                                             target_views=min(s.target_views, views - 1), seed=s.seeds[0],
                                             **ABLATIONS[condition])
        rows += _scaling_rows(preds.gaussians(), views, s.seeds[0], condition, s.shapes[:1], s, targets, truth,
                              False)
        progress.advance(f"{condition}, {views} views")
    columns = ["condition", "views", "shape", "voxel", "policy", "seed", "psnr", "ssim", "gaussians", "samples",
               "fusion_s", "render_s"]
    write_report(out_dir, "scaling", rows, columns, plot=lambda plt: _plot_scaling(plt, rows, s),
                 title="Dense-view scaling", body=_scaling_md(rows, s), quick=quick, dpi=100)
    return rows


def _methods(s: ScalingSettings, shape: str) -> list[tuple[str, str, float]]:
    """(label, policy, voxel) of the curves of one shape mode: each policy at each voxel size."""
    return [(f"{p}, voxel {v:g}", p, v) for v in s.voxel_sizes for p in s.policies]


def _plot_scaling(plt: ModuleType, rows: Sequence[Row], s: ScalingSettings) -> Figure:
    main = [r for r in rows if r["condition"] == "default"]
    fig, axes = plt.subplots(len(s.shapes), 3, figsize=(17, 4.6 * len(s.shapes)), squeeze=False)
    colors = {"mean": "tab:blue", "softmax": "tab:orange", "occupancy": "tab:green", "unfused": "tab:gray"}
    dashes = {v: ("-" if k == 0 else "--") for k, v in enumerate(s.voxel_sizes)}
    # The Gaussian count does not depend on the shape mode: the last column shows it once, then
    # the fusion time.
    last = [("gaussians", "Gaussians after fusion", True), ("fusion_s", "fusion time (s)", True)]
    unfused = aggregate([r for r in main if r["policy"] == "unfused"], ["views"], "psnr")
    unfused_ssim = aggregate([r for r in main if r["policy"] == "unfused"], ["views"], "ssim")
    for k, (row_axes, shape) in enumerate(zip(axes, s.shapes)):
        panels = [("psnr", "PSNR (dB), held-out views", False), ("ssim", "SSIM, held-out views", False),
                  last[min(k, 1)]]
        for ax, (value, label, log) in zip(row_axes, panels):
            agg = aggregate([r for r in main if r["shape"] == shape and r[value] != ""], ["policy", "voxel", "views"],
                             value)
            for name, policy, voxel in _methods(s, shape):
                xs = [v for v in s.views if (policy, voxel, v) in agg]
                ax.errorbar(xs, [agg[(policy, voxel, v)][0] for v in xs],
                            yerr=[agg[(policy, voxel, v)][1] for v in xs], marker="o", markersize=4, capsize=3,
                            linestyle=dashes[voxel], color=colors[policy], label=name)
            ref = {"psnr": unfused, "ssim": unfused_ssim}.get(value)
            if ref:
                xs = [v for v in s.views if (v,) in ref]
                ax.plot(xs, [ref[(v,)][0] for v in xs], ":", marker="o", markersize=3, color=colors["unfused"],
                        label="unfused (every pixel)")
            ax.set_xlabel("input views S")
            ax.set_ylabel(label)
            ax.set_title(f"shape={shape}", fontsize=10)
            ax.set_xscale("log")
            ax.set_xticks(list(s.views))
            ax.set_xticklabels([str(v) for v in s.views])
            ax.minorticks_off()
            if log:
                ax.set_yscale("log")
            ax.grid(alpha=0.3)
        row_axes[0].legend(fontsize=7)
    fig.suptitle(f"Dense-view scaling: {s.width}x{s.height} per view, {s.target_views} held-out views, "
                 f"{len(s.seeds)} seed(s); solid voxel {s.voxel_sizes[0]:g}"
                 + (f", dashed voxel {s.voxel_sizes[1]:g}" if len(s.voxel_sizes) > 1 else ""))
    return fig


def _scaling_md(rows: Sequence[Row], s: ScalingSettings) -> str:
    main = [r for r in rows if r["condition"] == "default"]
    key = ["shape", "policy", "voxel", "views"]
    psnr = aggregate(main, key, "psnr")
    ssim = aggregate(main, key, "ssim")
    count = aggregate(main, key, "gaussians")
    fuse = aggregate([r for r in main if r["fusion_s"] != ""], key, "fusion_s")
    groups = [(shape, voxel) for shape in s.shapes for voxel in s.voxel_sizes] + ([("", "")] if s.unfused else [])
    tables = []
    for shape, voxel in groups:
        table = []
        for v in s.views:
            for p in (s.policies if voxel != "" else ("unfused",)):
                k = (shape, p, voxel, v)
                if k not in psnr:
                    continue
                table.append([v, p, f"{psnr[k][0]:.2f} ± {psnr[k][1]:.2f}", f"{ssim[k][0]:.4f} ± {ssim[k][1]:.4f}",
                              f"{count[k][0]:.0f}", f"{fuse[k][0]:.3f}" if k in fuse else "-"])
        title = (f"### shape={shape}, voxel size {voxel:g}" if voxel != ""
                 else "### Unfused (every per-pixel Gaussian rendered)")
        tables.append(title + "\n\n" + md_table(["views", "policy", "PSNR (dB)", "SSIM", "Gaussians",
                                                    "fusion (s)"], table))
    # The facts the question asks about: the change from the fewest to the most views, and the
    # occupancy-minus-baseline gap at every view count.
    lo, hi = min(s.views), max(s.views)
    facts = []
    for shape, voxel in groups:
        for p in (s.policies if voxel != "" else ("unfused",)):
            pts = [v for v in s.views if (shape, p, voxel, v) in psnr]
            if lo not in pts or hi not in pts:
                continue
            best_v = max(pts, key=lambda v: psnr[(shape, p, voxel, v)][0])
            label = f"{p}, shape={shape}, voxel {voxel:g}" if voxel != "" else "unfused"
            first, last = psnr[(shape, p, voxel, lo)][0], psnr[(shape, p, voxel, hi)][0]
            facts.append(f"- {label}: {first:.2f} dB at {lo} views -> {last:.2f} dB at {hi} views "
                         f"({last - first:+.2f} dB); best at {best_v} views.")
    for shape, voxel in groups:
        for base in ("mean", "softmax"):
            gaps = ", ".join(f"{v}: {psnr[(shape, 'occupancy', voxel, v)][0] - psnr[(shape, base, voxel, v)][0]:+.2f}"
                             for v in s.views
                             if (shape, "occupancy", voxel, v) in psnr and (shape, base, voxel, v) in psnr)
            if gaps:
                facts.append(f"- shape={shape}, voxel {voxel:g}, occupancy - {base} PSNR (dB) by views: {gaps}.")
    shape0 = s.shapes[0]
    abl = {(r["condition"], r["voxel"], r["policy"], r["views"]): r for r in rows
           if r["seed"] == s.seeds[0] and r["views"] in s.ablation_views and r["shape"] == shape0}
    abl_table = []
    for condition in ABLATIONS:
        for voxel in s.voxel_sizes:
            cells = [condition, f"{voxel:g}"]
            for p in s.policies:
                vals = [abl[(condition, voxel, p, v)]["psnr"] for v in s.ablation_views if (condition, voxel, p, v) in abl]
                cells.append(" -> ".join(f"{x:.2f}" for x in vals))
            n = [abl[(condition, voxel, s.policies[0], v)]["gaussians"] for v in s.ablation_views
                 if (condition, voxel, s.policies[0], v) in abl]
            cells.append(" -> ".join(str(x) for x in n))
            abl_table.append(cells)
    views_label = " -> ".join(str(v) for v in s.ablation_views)
    realistic_text = _realistic_md(rows, s)
    tables_text = "\n\n".join(tables)
    return f"""Does occupancy-guided fusion keep improving as views are added while averaging saturates or degrades?
Simulated predictions of the default scene (avsplat.simulate_predictions with its default errors:
depth noise 0.4 %, pose noise 0.2 deg / 0.004, flying pixels, confidence noise 0.5),
{s.width}x{s.height} pixels per view, one flat Gaussian per valid pixel (Predictions.gaussians),
fused with each policy (default knobs) and shape mode ({", ".join(s.shapes)}) at fixed voxel sizes
{", ".join(f"{v:g}" for v in s.voxel_sizes)} (the pixel footprint at the centre of the scene is about 0.02),
rendered at {s.target_views} held-out views (the same cameras for every view count) and scored against the
ray-cast ground truth. Mean ± standard deviation over {len(s.seeds)} seed(s) {list(s.seeds)}. "unfused"
renders every per-pixel Gaussian. Fusion time is the fuse_gaussians call alone, on {machine()}.

{tables_text}

{chr(10).join(facts)}

### Which simulated error drives the trend

Seed {s.seeds[0]}, shape={shape0}, PSNR (dB) at {views_label} views with one error source of the simulator
switched off (simulator options), and the number of fused Gaussians.

{md_table(["condition", "voxel"] + [f"{p} PSNR" for p in s.policies] + ["Gaussians"], abl_table)}

{realistic_text}
"""


def _realistic_md(rows: Sequence[Row], s: ScalingSettings) -> str:
    """The view sweep with the error models of real predictions: PSNR per policy and voxel size,
    and the occupancy gaps."""
    from .regimes import REALISTIC

    real = [r for r in rows if r["condition"] == REALISTIC_CONDITION]
    if not real:
        return ""
    psnr = aggregate(real, ["policy", "voxel", "views"], "psnr")
    table = []
    for v in s.views:
        cells: list[object] = [v]
        for voxel in s.voxel_sizes:
            for p in s.policies:
                m = psnr.get((p, voxel, v))
                cells.append(f"{m[0]:.2f} ± {m[1]:.2f}" if m else "-")
            occ, mean = psnr.get(("occupancy", voxel, v)), psnr.get(("mean", voxel, v))
            cells.append(f"{occ[0] - mean[0]:+.2f}" if occ and mean else "-")
        table.append(cells)
    header = ["views"] + [h for voxel in s.voxel_sizes
                          for h in [f"{p} {voxel:g}" for p in s.policies] + [f"occ - mean {voxel:g}"]]
    options = ", ".join(f"{k}={v:g}" for k, v in REALISTIC.items())
    return f"""### With the error models of real predictions

The same sweep (shape={s.shapes[0]}) with simulate_predictions({options}) on top of the default errors:
optical blur, per-view exposure and white balance, a specular / sheen term, mixed pixels at depth edges and
head-feature noise where a model is unsure (simulator.h). The per-pixel Gaussians are decoded from the raw head
features (Predictions.decoded_gaussians); the targets' ground truth has the same optics. PSNR (dB), mean ±
standard deviation over seeds {list(s.realistic_seeds)}.

{md_table(header, table)}
"""
