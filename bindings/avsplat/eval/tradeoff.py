"""Report `tradeoff`: error against run time (voxel size x policy, float32 vs float64, renderer cut-offs)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING, Any, Mapping, Sequence

import numpy as np
import numpy.typing as npt

import avsplat

from ..render import render
from ._common import POLICIES, Progress, Row, best_time, fmt, max_abs
from ._report import machine, md_table, write_report

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..core import Camera

@dataclass
class TradeoffSettings:
    """What run_tradeoff measures; the defaults are the committed report's."""

    views: int = 16
    width: int = 160
    height: int = 120
    target_views: int = 4
    seed: int = 0
    voxel_sizes: tuple[float, ...] = (0.005, 0.01, 0.02, 0.04, 0.08)
    policies: tuple[str, ...] = POLICIES
    render_voxel: float = 0.01         # the fused cloud the renderer studies use
    render_scale: int = 2              # renderer studies render at render_scale x the view size
    alpha_thresholds: tuple[float, ...] = (1 / 255, 0.01, 0.03, 0.1)
    transmittance_stops: tuple[float, ...] = (1e-4, 1e-3, 1e-2, 0.05)
    extent_sigmas: tuple[float, ...] = (3.0, 2.5, 2.0, 1.5)
    repeats: int = 5

    @staticmethod
    def quick() -> "TradeoffSettings":
        return TradeoffSettings(views=4, width=48, height=36, target_views=1, voxel_sizes=(0.04, 0.08),
                                render_voxel=0.04, render_scale=1, alpha_thresholds=(1 / 255, 0.05),
                                transmittance_stops=(1e-4, 1e-2), extent_sigmas=(3.0, 2.0), repeats=1)


# The renderer's defaults (RenderOptions, read through the binding) and the reference for the
# cut-off study: float64 with every cut-off pushed far past where it could matter.
_DEFAULT_CUTOFFS: dict[str, float] = {k: avsplat.defaults["render"][k]
                                       for k in ("alpha_threshold", "transmittance_stop", "extent_sigma")}
_EXACT_CUTOFFS: dict[str, float] = dict(alpha_threshold=1e-7, transmittance_stop=1e-9, extent_sigma=8.0)


def _scaled(cam: Camera, k: int) -> Camera:
    """The camera with k times the pixels (same field of view and pose)."""
    if k == 1:
        return cam
    return avsplat.Camera(cam.fx * k, cam.fy * k, cam.cx * k, cam.cy * k, cam.width * k, cam.height * k,
                          cam.world_to_camera, cam.near, cam.far)


def run_tradeoff(out_dir: str, settings: TradeoffSettings | None = None, quick: bool = False) -> list[Row]:
    """Error against run time. Three studies on one simulated scene (S views), each point an
    (error, seconds) pair:

    - voxel: voxel size x policy: PSNR of the held-out renders against the ground truth vs the
      time of fusion plus rendering every held-out view.
    - precision: the renderer in float32 and float64 on the fused cloud (voxel render_voxel,
      occupancy): PSNR against the ground truth, largest difference from float64, time.
    - cutoff: alpha_threshold, transmittance_stop and extent_sigma, one at a time from the
      defaults (float32): PSNR and largest difference against a float64 render with the cut-offs
      pushed out of the way (alpha 1e-7, transmittance 1e-9, 8 sigma), time.

    Fusion and render times are the best of `repeats` calls. Writes tradeoff.csv, .png, .md;
    returns the rows.

    Parameters
    ----------
    out_dir : str
        Folder for tradeoff.csv, tradeoff.png and tradeoff.md.
    settings : TradeoffSettings, optional
        The report's settings; the defaults when None.
    quick : bool
        Tiny settings (seconds; for smoke tests, not for conclusions).

    Returns
    -------
    list of Row
        One row per measurement, as written to tradeoff.csv.
    """
    s = settings or (TradeoffSettings.quick() if quick else TradeoffSettings())
    os.makedirs(out_dir, exist_ok=True)
    preds = avsplat.simulate_predictions(views=s.views, width=s.width, height=s.height,
                                         target_views=s.target_views, seed=s.seed)
    cloud = preds.gaussians()
    targets = list(preds.target_cameras)
    n_steps = len(s.voxel_sizes) * len(s.policies) + 2 + len(s.alpha_thresholds) + len(s.transmittance_stops) + \
        len(s.extent_sigmas)
    progress = Progress("tradeoff", n_steps)
    rows: list[Row] = []

    truth = [avsplat.ground_truth(cam).color.copy() for cam in targets]
    for voxel in s.voxel_sizes:
        for policy in s.policies:
            result, fuse_s = best_time(lambda: avsplat.fuse_gaussians(cloud, voxel, policy=policy), s.repeats)
            psnrs, render_s = [], 0.0
            for cam, gt in zip(targets, truth):
                r, t = best_time(lambda: render(result.cloud, cam), s.repeats)
                render_s += t
                psnrs.append(avsplat.psnr(r.color, gt))
            rows.append(dict(study="voxel", setting=f"voxel={voxel:g}", policy=policy, precision="float32",
                             gaussians=len(result), psnr_gt=float(np.mean(psnrs)), max_abs_ref="", psnr_ref="",
                             fusion_s=fuse_s, render_s=render_s, seconds=fuse_s + render_s))
            progress.advance(f"voxel {voxel:g} {policy}")

    # The renderer studies: the fused cloud at render_voxel, at render_scale x the resolution.
    fused = avsplat.fuse_gaussians(cloud, s.render_voxel, policy="occupancy").cloud
    big = [_scaled(cam, s.render_scale) for cam in targets]
    big_truth = [avsplat.ground_truth(cam).color.copy() for cam in big]

    def render_all(precision: str, **cutoffs: Any) -> tuple[list[npt.NDArray[np.float32]], float]:
        images: list[npt.NDArray[np.float32]] = []
        total = 0.0
        for cam in big:
            r, t = best_time(lambda: render(fused, cam, precision=precision, **cutoffs), s.repeats)
            images.append(r.color.copy())
            total += t
        return images, total

    f64, f64_s = render_all("float64", **_DEFAULT_CUTOFFS)
    for precision in ("float32", "float64"):
        images, secs = (f64, f64_s) if precision == "float64" else render_all("float32", **_DEFAULT_CUTOFFS)
        rows.append(dict(study="precision", setting=precision, policy="occupancy", precision=precision,
                         gaussians=len(fused),
                         psnr_gt=float(np.mean([avsplat.psnr(i, g) for i, g in zip(images, big_truth)])),
                         max_abs_ref=max(max_abs(i, r) for i, r in zip(images, f64)), psnr_ref="",
                         fusion_s="", render_s=secs, seconds=secs))
        progress.advance(precision)

    exact, _ = render_all("float64", **_EXACT_CUTOFFS)
    studies = [("alpha_threshold", s.alpha_thresholds), ("transmittance_stop", s.transmittance_stops),
               ("extent_sigma", s.extent_sigmas)]
    for knob, values in studies:
        for value in values:
            cutoffs = dict(_DEFAULT_CUTOFFS)
            cutoffs[knob] = value
            images, secs = render_all("float32", **cutoffs)
            rows.append(dict(study="cutoff", setting=f"{knob}={value:.4g}", policy="occupancy", precision="float32",
                             gaussians=len(fused),
                             psnr_gt=float(np.mean([avsplat.psnr(i, g) for i, g in zip(images, big_truth)])),
                             max_abs_ref=max(max_abs(i, r) for i, r in zip(images, exact)),
                             psnr_ref=float(np.mean([avsplat.psnr(i, r) for i, r in zip(images, exact)])),
                             fusion_s="", render_s=secs, seconds=secs))
            progress.advance(f"{knob} {value:.4g}")

    columns = ["study", "setting", "policy", "precision", "gaussians", "psnr_gt", "max_abs_ref", "psnr_ref",
               "fusion_s", "render_s", "seconds"]
    write_report(out_dir, "tradeoff", rows, columns, plot=lambda plt: _plot_tradeoff(plt, rows, s),
                 title="Error against run time", body=_tradeoff_md(rows, s, len(targets)), quick=quick)
    return rows


def _plot_tradeoff(plt: ModuleType, rows: Sequence[Row], s: TradeoffSettings) -> Figure:
    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    ax = axes[0]
    for policy in s.policies:
        pts = [r for r in rows if r["study"] == "voxel" and r["policy"] == policy]
        ax.plot([r["seconds"] for r in pts], [r["psnr_gt"] for r in pts], marker="o", label=policy)
        for r in pts:
            ax.annotate(r["setting"].split("=")[1], (r["seconds"], r["psnr_gt"]), fontsize=7,
                        textcoords="offset points", xytext=(3, 3))
    ax.set_xscale("log")
    ax.set_xlabel("fusion + rendering the held-out views (s)")
    ax.set_ylabel("PSNR vs ground truth (dB)")
    ax.set_title(f"voxel size x policy ({s.views} views)")
    ax.legend()
    ax.grid(alpha=0.3)

    ax = axes[1]
    for r in (r for r in rows if r["study"] == "precision"):
        # float64 is the reference (error 0): drawn at the floor of the log axis.
        ax.scatter(r["render_s"], max(r["max_abs_ref"], 1e-8), s=60,
                   label=f"{r['setting']}: PSNR vs truth {r['psnr_gt']:.3f} dB")
    ax.set_yscale("log")
    ax.set_xlabel("render time, all held-out views (s)")
    ax.set_ylabel("max |colour - float64 render| (floored at 1e-8)")
    ax.set_title("renderer float32 vs float64")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)

    ax = axes[2]
    for knob in ("alpha_threshold", "transmittance_stop", "extent_sigma"):
        pts = [r for r in rows if r["study"] == "cutoff" and r["setting"].startswith(knob)]
        ax.plot([r["render_s"] for r in pts], [max(r["max_abs_ref"], 1e-8) for r in pts], marker="o", label=knob)
        for r in pts:
            ax.annotate(r["setting"].split("=")[1], (r["render_s"], max(r["max_abs_ref"], 1e-8)), fontsize=7,
                        textcoords="offset points", xytext=(3, 3))
    ax.set_yscale("log")
    ax.set_xlabel("render time, all held-out views (s)")
    ax.set_ylabel("max |colour - exact float64 render|")
    ax.set_title("renderer cut-offs (one at a time from the defaults)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    return fig


def _cutoff_text(cutoffs: Mapping[str, float]) -> str:
    return ", ".join(f"{k} {v:.4g}" for k, v in cutoffs.items())


def _tradeoff_md(rows: Sequence[Row], s: TradeoffSettings, n_targets: int) -> str:
    voxel = [[r["setting"].split("=")[1], r["policy"], r["gaussians"], f"{r['psnr_gt']:.2f}", f"{r['fusion_s']:.3f}",
              f"{r['render_s']:.3f}", f"{r['seconds']:.3f}"] for r in rows if r["study"] == "voxel"]
    precision = [[r["setting"], f"{r['psnr_gt']:.3f}", fmt(r["max_abs_ref"], 3), f"{r['render_s']:.3f}"]
                 for r in rows if r["study"] == "precision"]
    cutoff = [[r["setting"], f"{r['psnr_gt']:.3f}", fmt(r["psnr_ref"], 4), fmt(r["max_abs_ref"], 3),
               f"{r['render_s']:.3f}"] for r in rows if r["study"] == "cutoff"]
    w, h = s.width * s.render_scale, s.height * s.render_scale
    return f"""One simulated scene ({s.views} views of {s.width}x{s.height}, seed {s.seed}), {n_targets} held-out views.
Times are wall-clock seconds on {machine()}; each is the best of {s.repeats} runs.

## Voxel size x policy

PSNR of the held-out renders against the ray-cast ground truth, and the time of fusion plus
rendering all {n_targets} held-out views.

{md_table(["voxel", "policy", "Gaussians", "PSNR (dB)", "fusion (s)", "render (s)", "total (s)"], voxel)}

## Renderer float32 vs float64

The occupancy-fused cloud at voxel {s.render_voxel}, rendered at {w}x{h}.

{md_table(["precision", "PSNR vs truth (dB)", "max abs diff vs float64", "render (s)"], precision)}

## Renderer cut-offs

One cut-off at a time from the defaults ({_cutoff_text(_DEFAULT_CUTOFFS)}), float32, same cloud and size. The reference is a float64 render with
{_cutoff_text(_EXACT_CUTOFFS)}.

{md_table(["setting", "PSNR vs truth (dB)", "PSNR vs exact (dB)", "max abs diff vs exact", "render (s)"], cutoff)}
"""
