"""Evaluation reports: dense-view scaling, error against run time, numerical stability.

Each report is one function that writes ``<name>.csv`` (every measurement), ``<name>.png`` (a
plot) and ``<name>.md`` (a markdown table with the command that made it) into a directory, and
returns the rows it measured:

    run_scaling(out_dir)    views x fusion policy: PSNR, SSIM, Gaussian count, fusion time
    run_tradeoff(out_dir)   voxel size x policy, float32 vs float64, renderer cut-offs:
                            (error, seconds) points
    run_stability(out_dir)  the stiff and extreme cases of the fusion and renderer test suites:
                            error of the float32 path against float64, finiteness, time

From a shell (``avsplat eval REPORT -o DIR`` runs exactly this)::

    PYTHONPATH=build/python /usr/bin/python3 -m avsplat.evaluation scaling -o apps/benchmarks/reports

``--quick`` (``quick=True``) shrinks every report to a few seconds for smoke tests; its numbers
are not meant for conclusions. Progress goes to stderr as a bar on a terminal, and as plain lines
on stdout otherwise. Timings are wall-clock seconds of the C++ calls (GIL released), best of a
few repeats where noted, on whatever machine runs the report; the markdown says which.
"""

from __future__ import annotations

import argparse
import csv
import math
import os
import platform
import sys
import time
from dataclasses import dataclass, field

import numpy as np

import avsplat

POLICIES = ("mean", "softmax", "occupancy")
_PYTHON = "PYTHONPATH=build/python /usr/bin/python3 -m avsplat.evaluation"


# ------------------------------------------------------------------------------------------------
# Shared helpers


class _Progress:
    """A bar redrawn on stderr when it is a terminal; plain lines on stdout at each tenth otherwise."""

    def __init__(self, label: str, total: int):
        self.label, self.total, self.done = label, max(int(total), 1), 0
        self.start = time.perf_counter()
        self.terminal = sys.stderr.isatty()
        self.last_tenth = 0

    def advance(self, detail: str = "") -> None:
        self.done = min(self.total, self.done + 1)
        elapsed = time.perf_counter() - self.start
        if self.terminal:
            filled = 30 * self.done // self.total
            bar = "#" * filled + "." * (30 - filled)
            sys.stderr.write(f"\r\033[K{self.label} [{bar}] {self.done}/{self.total} {elapsed:.1f} s {detail[-40:]}")
            sys.stderr.flush()
            if self.done == self.total:
                sys.stderr.write("\r\033[K")
                sys.stderr.flush()
            return
        tenth = 10 * self.done // self.total
        if tenth != self.last_tenth or self.done == self.total:
            self.last_tenth = tenth
            print(f"{self.label}: {self.done}/{self.total} {detail} ({elapsed:.1f} s)", flush=True)


def _best_time(fn, repeats: int):
    """(result of the last call, smallest wall time in seconds over `repeats` calls)."""
    best, result = math.inf, None
    for _ in range(max(1, repeats)):
        t0 = time.perf_counter()
        result = fn()
        best = min(best, time.perf_counter() - t0)
    return result, best


def _write_csv(path: str, rows: list[dict], columns: list[str]) -> None:
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: _csv_value(r.get(k, "")) for k in columns})


def _csv_value(v):
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("inf" if v > 0 else "-inf" if v < 0 else "nan")
    return v


def _md_table(header: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _machine() -> str:
    """The machine, and how busy it was: timings on a shared machine depend on both."""
    threads = os.environ.get("OMP_NUM_THREADS", str(os.cpu_count()))
    wait = os.environ.get("OMP_WAIT_POLICY")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return (f"{platform.machine()} {platform.system()}, {os.cpu_count()} CPU cores, OpenMP threads {threads}"
            + (f", OMP_WAIT_POLICY={wait}" if wait else "") + f", load average {load:.1f} when the report was written")


def _command(name: str, out_dir: str, quick: bool) -> str:
    args = f"{name} -o {out_dir}" + (" --quick" if quick else "")
    # OpenMP settings change the timings, so the command says which were used.
    env = "".join(f"{k}={os.environ[k]} " for k in ("OMP_NUM_THREADS", "OMP_WAIT_POLICY") if k in os.environ)
    return f"{env}build/apps/avsplat eval {args}\n# runs: {env}{_PYTHON} {args}"


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _max_abs(a, b) -> float:
    """max |a - b| (equal infinities count as no error, any other non-finite value as infinite)."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    if a.size == 0:
        return 0.0
    with np.errstate(invalid="ignore"):
        d = np.abs(a - b)
    d[a == b] = 0.0
    d[~np.isfinite(d)] = np.inf
    return float(d.max())


def _max_err(a, ref) -> float:
    """max |a - ref| / max(1, |ref|): the absolute error for values up to 1 (colours, weights),
    the relative error for larger ones (scales of 1e4, coordinates of 1e6)."""
    a = np.asarray(a, dtype=np.float64)
    ref = np.asarray(ref, dtype=np.float64)
    if a.size == 0:
        return 0.0
    with np.errstate(invalid="ignore"):
        d = np.abs(a - ref) / np.maximum(1.0, np.abs(ref))
    d[a == ref] = 0.0
    d[~np.isfinite(d)] = np.inf
    return float(d.max())


def _finite(*arrays) -> bool:
    return all(bool(np.all(np.isfinite(np.asarray(a)))) for a in arrays)


def _fmt(v: float, digits: int = 3) -> str:
    if isinstance(v, float) and not math.isfinite(v):
        return "inf" if v > 0 else "nan"
    return f"{v:.{digits}g}"


# ------------------------------------------------------------------------------------------------
# 1. Dense-view scaling


@dataclass
class ScalingSettings:
    """What run_scaling measures; the defaults are the committed report's."""

    views: tuple = (3, 6, 16, 32, 48, 64)
    policies: tuple = POLICIES
    width: int = 160
    height: int = 120
    target_views: int = 6
    seeds: tuple = (0, 1, 2)
    # About one and two pixel footprints at the arc's centre (2.6 / fy = 0.020 at 160 x 120).
    voxel_sizes: tuple = (0.02, 0.04)
    # How fuse_gaussians combines the shapes: the library default (average of log-scales and
    # rotations, which keeps per-pixel sizes) and moment matching (covers the voxel's spread).
    shapes: tuple = ("average", "moment")
    unfused: bool = True  # also render the raw per-pixel Gaussians (no fusion) as a reference
    # Which simulated error drives the trend: the same runs with one error source switched off
    # (simulator options of simulator.h), at these view counts, first seed, first shape.
    ablation_views: tuple = (6, 64)

    @staticmethod
    def quick() -> "ScalingSettings":
        return ScalingSettings(views=(3, 6), width=40, height=30, target_views=1, seeds=(0,), voxel_sizes=(0.05,),
                               ablation_views=(3,))


# Simulator options (simulator.h) that switch one error source off, for the ablation.
ABLATIONS = {
    "default": {},
    "no flying pixels": dict(flying_pixels=False),
    "no pose noise": dict(pose_noise_rot_deg=0.0, pose_noise_trans=0.0),
    "no depth noise": dict(depth_noise=0.0),
    "no noise": dict(flying_pixels=False, pose_noise_rot_deg=0.0, pose_noise_trans=0.0, depth_noise=0.0),
}


def _score(cloud, targets, truth):
    """Mean PSNR and SSIM over the targets, and the mean render time."""
    psnrs, ssims, seconds = [], [], 0.0
    for cam, gt in zip(targets, truth):
        r, t = _best_time(lambda: avsplat.render(cloud, cam), 1)
        seconds += t
        psnrs.append(avsplat.psnr(r.color, gt))
        ssims.append(avsplat.ssim(r.color, gt))
    return float(np.mean(psnrs)), float(np.mean(ssims)), seconds / len(targets)


def _scaling_rows(cloud, views, seed, condition, shapes, s, targets, truth, with_unfused):
    rows = []
    for shape in shapes:
        for voxel in s.voxel_sizes:
            for policy in s.policies:
                result, fuse_s = _best_time(
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


def run_scaling(out_dir: str, settings: ScalingSettings | None = None, quick: bool = False) -> list[dict]:
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
    """
    s = settings or (ScalingSettings.quick() if quick else ScalingSettings())
    os.makedirs(out_dir, exist_ok=True)
    s_max = max(s.views)
    targets = avsplat.target_cameras(views=s_max, target_views=s.target_views, width=s.width, height=s.height)
    truth = [avsplat.ground_truth(cam).color.copy() for cam in targets]
    ablation = [(c, v) for c in ABLATIONS if c != "default" for v in s.ablation_views]
    progress = _Progress("scaling", len(s.seeds) * len(s.views) + len(ablation))
    rows = []
    for seed in s.seeds:
        for views in s.views:
            preds = avsplat.simulate_predictions(views=views, width=s.width, height=s.height,
                                                 target_views=min(s.target_views, views - 1), seed=seed)
            rows += _scaling_rows(preds.gaussians(), views, seed, "default", s.shapes, s, targets, truth, s.unfused)
            progress.advance(f"seed {seed}, {views} views")
    for condition, views in ablation:
        preds = avsplat.simulate_predictions(views=views, width=s.width, height=s.height,
                                             target_views=min(s.target_views, views - 1), seed=s.seeds[0],
                                             **ABLATIONS[condition])
        rows += _scaling_rows(preds.gaussians(), views, s.seeds[0], condition, s.shapes[:1], s, targets, truth,
                              False)
        progress.advance(f"{condition}, {views} views")
    columns = ["condition", "views", "shape", "voxel", "policy", "seed", "psnr", "ssim", "gaussians", "samples",
               "fusion_s", "render_s"]
    _write_csv(os.path.join(out_dir, "scaling.csv"), rows, columns)
    _plot_scaling(os.path.join(out_dir, "scaling.png"), rows, s)
    _write_scaling_md(os.path.join(out_dir, "scaling.md"), rows, s, quick)
    return rows


def _aggregate(rows, key_fields, value):
    """{key: (mean, std)} of value over the rows sharing key_fields."""
    groups: dict = {}
    for r in rows:
        groups.setdefault(tuple(r[k] for k in key_fields), []).append(r[value])
    return {k: (float(np.mean(v)), float(np.std(v))) for k, v in groups.items()}


def _methods(s: ScalingSettings, shape: str):
    """(label, policy, voxel) of the curves of one shape mode: each policy at each voxel size."""
    return [(f"{p}, voxel {v:g}", p, v) for v in s.voxel_sizes for p in s.policies]


def _plot_scaling(path, rows, s: ScalingSettings):
    plt = _pyplot()
    main = [r for r in rows if r["condition"] == "default"]
    fig, axes = plt.subplots(len(s.shapes), 3, figsize=(17, 4.6 * len(s.shapes)), squeeze=False)
    colors = {"mean": "tab:blue", "softmax": "tab:orange", "occupancy": "tab:green", "unfused": "tab:gray"}
    dashes = {v: ("-" if k == 0 else "--") for k, v in enumerate(s.voxel_sizes)}
    # The Gaussian count does not depend on the shape mode: the last column shows it once, then
    # the fusion time.
    last = [("gaussians", "Gaussians after fusion", True), ("fusion_s", "fusion time (s)", True)]
    unfused = _aggregate([r for r in main if r["policy"] == "unfused"], ["views"], "psnr")
    unfused_ssim = _aggregate([r for r in main if r["policy"] == "unfused"], ["views"], "ssim")
    for k, (row_axes, shape) in enumerate(zip(axes, s.shapes)):
        panels = [("psnr", "PSNR (dB), held-out views", False), ("ssim", "SSIM, held-out views", False),
                  last[min(k, 1)]]
        for ax, (value, label, log) in zip(row_axes, panels):
            agg = _aggregate([r for r in main if r["shape"] == shape and r[value] != ""], ["policy", "voxel", "views"],
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
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _write_scaling_md(path, rows, s: ScalingSettings, quick):
    main = [r for r in rows if r["condition"] == "default"]
    key = ["shape", "policy", "voxel", "views"]
    psnr = _aggregate(main, key, "psnr")
    ssim = _aggregate(main, key, "ssim")
    count = _aggregate(main, key, "gaussians")
    fuse = _aggregate([r for r in main if r["fusion_s"] != ""], key, "fusion_s")
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
        tables.append(title + "\n\n" + _md_table(["views", "policy", "PSNR (dB)", "SSIM", "Gaussians",
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
    tables_text = "\n\n".join(tables)
    text = f"""# Dense-view scaling

Does occupancy-guided fusion keep improving as views are added while averaging saturates or degrades?
Simulated predictions of the default scene (avsplat.simulate_predictions with its default errors:
depth noise 0.4 %, pose noise 0.2 deg / 0.004, flying pixels, confidence noise 0.5),
{s.width}x{s.height} pixels per view, one flat Gaussian per valid pixel (Predictions.gaussians),
fused with each policy (default knobs) and shape mode ({", ".join(s.shapes)}) at fixed voxel sizes
{", ".join(f"{v:g}" for v in s.voxel_sizes)} (the pixel footprint at the centre of the scene is about 0.02),
rendered at {s.target_views} held-out views (the same cameras for every view count) and scored against the
ray-cast ground truth. Mean ± standard deviation over {len(s.seeds)} seed(s) {list(s.seeds)}. "unfused"
renders every per-pixel Gaussian. Fusion time is the fuse_gaussians call alone, on {_machine()}.

{tables_text}

{chr(10).join(facts)}

### Which simulated error drives the trend

Seed {s.seeds[0]}, shape={shape0}, PSNR (dB) at {views_label} views with one error source of the simulator
switched off (simulator options), and the number of fused Gaussians.

{_md_table(["condition", "voxel"] + [f"{p} PSNR" for p in s.policies] + ["Gaussians"], abl_table)}

Regenerate with:

```
{_command("scaling", os.path.relpath(os.path.dirname(path)), quick)}
```
"""
    with open(path, "w") as f:
        f.write(text)


# ------------------------------------------------------------------------------------------------
# 2. Error against run time


@dataclass
class TradeoffSettings:
    """What run_tradeoff measures; the defaults are the committed report's."""

    views: int = 16
    width: int = 160
    height: int = 120
    target_views: int = 4
    seed: int = 0
    voxel_sizes: tuple = (0.005, 0.01, 0.02, 0.04, 0.08)
    policies: tuple = POLICIES
    render_voxel: float = 0.01         # the fused cloud the renderer studies use
    render_scale: int = 2              # renderer studies render at render_scale x the view size
    alpha_thresholds: tuple = (1 / 255, 0.01, 0.03, 0.1)
    transmittance_stops: tuple = (1e-4, 1e-3, 1e-2, 0.05)
    extent_sigmas: tuple = (3.0, 2.5, 2.0, 1.5)
    repeats: int = 5

    @staticmethod
    def quick() -> "TradeoffSettings":
        return TradeoffSettings(views=4, width=48, height=36, target_views=1, voxel_sizes=(0.04, 0.08),
                                render_voxel=0.04, render_scale=1, alpha_thresholds=(1 / 255, 0.05),
                                transmittance_stops=(1e-4, 1e-2), extent_sigmas=(3.0, 2.0), repeats=1)


# The renderer's defaults (render.h) and the reference for the cut-off study: float64 with every
# cut-off pushed far past where it could matter.
_DEFAULT_CUTOFFS = dict(alpha_threshold=1 / 255, transmittance_stop=1e-4, extent_sigma=3.0)
_EXACT_CUTOFFS = dict(alpha_threshold=1e-7, transmittance_stop=1e-9, extent_sigma=8.0)


def _scaled(cam, k: int):
    """The camera with k times the pixels (same field of view and pose)."""
    if k == 1:
        return cam
    return avsplat.Camera(cam.fx * k, cam.fy * k, cam.cx * k, cam.cy * k, cam.width * k, cam.height * k,
                          cam.world_to_camera, cam.near, cam.far)


def run_tradeoff(out_dir: str, settings: TradeoffSettings | None = None, quick: bool = False) -> list[dict]:
    """Error against run time. Three studies on one simulated scene (S views), each point an
    (error, seconds) pair:

    voxel      voxel size x policy: PSNR of the held-out renders against the ground truth vs the
               time of fusion plus rendering every held-out view.
    precision  the renderer in float32 and float64 on the fused cloud (voxel render_voxel,
               occupancy): PSNR against the ground truth, largest difference from float64, time.
    cutoff     alpha_threshold, transmittance_stop and extent_sigma, one at a time from the defaults
               (float32): PSNR and largest difference against a float64 render with the cut-offs
               pushed out of the way (alpha 1e-7, transmittance 1e-9, 8 sigma), time.
    Fusion and render times are the best of `repeats` calls. Writes tradeoff.csv, .png, .md;
    returns the rows.
    """
    s = settings or (TradeoffSettings.quick() if quick else TradeoffSettings())
    os.makedirs(out_dir, exist_ok=True)
    preds = avsplat.simulate_predictions(views=s.views, width=s.width, height=s.height,
                                         target_views=s.target_views, seed=s.seed)
    cloud = preds.gaussians()
    targets = list(preds.target_cameras)
    n_steps = len(s.voxel_sizes) * len(s.policies) + 2 + len(s.alpha_thresholds) + len(s.transmittance_stops) + \
        len(s.extent_sigmas)
    progress = _Progress("tradeoff", n_steps)
    rows = []

    truth = [avsplat.ground_truth(cam).color.copy() for cam in targets]
    for voxel in s.voxel_sizes:
        for policy in s.policies:
            result, fuse_s = _best_time(lambda: avsplat.fuse_gaussians(cloud, voxel, policy=policy), s.repeats)
            psnrs, render_s = [], 0.0
            for cam, gt in zip(targets, truth):
                r, t = _best_time(lambda: avsplat.render(result.cloud, cam), s.repeats)
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

    def render_all(precision, **cutoffs):
        images, total = [], 0.0
        for cam in big:
            r, t = _best_time(lambda: avsplat.render(fused, cam, precision=precision, **cutoffs), s.repeats)
            images.append(r.color.copy())
            total += t
        return images, total

    f64, f64_s = render_all("float64", **_DEFAULT_CUTOFFS)
    for precision in ("float32", "float64"):
        images, secs = (f64, f64_s) if precision == "float64" else render_all("float32", **_DEFAULT_CUTOFFS)
        rows.append(dict(study="precision", setting=precision, policy="occupancy", precision=precision,
                         gaussians=len(fused),
                         psnr_gt=float(np.mean([avsplat.psnr(i, g) for i, g in zip(images, big_truth)])),
                         max_abs_ref=max(_max_abs(i, r) for i, r in zip(images, f64)), psnr_ref="",
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
                             max_abs_ref=max(_max_abs(i, r) for i, r in zip(images, exact)),
                             psnr_ref=float(np.mean([avsplat.psnr(i, r) for i, r in zip(images, exact)])),
                             fusion_s="", render_s=secs, seconds=secs))
            progress.advance(f"{knob} {value:.4g}")

    columns = ["study", "setting", "policy", "precision", "gaussians", "psnr_gt", "max_abs_ref", "psnr_ref",
               "fusion_s", "render_s", "seconds"]
    _write_csv(os.path.join(out_dir, "tradeoff.csv"), rows, columns)
    _plot_tradeoff(os.path.join(out_dir, "tradeoff.png"), rows, s)
    _write_tradeoff_md(os.path.join(out_dir, "tradeoff.md"), rows, s, len(targets), quick)
    return rows


def _plot_tradeoff(path, rows, s: TradeoffSettings):
    plt = _pyplot()
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
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _write_tradeoff_md(path, rows, s: TradeoffSettings, n_targets: int, quick: bool):
    voxel = [[r["setting"].split("=")[1], r["policy"], r["gaussians"], f"{r['psnr_gt']:.2f}", f"{r['fusion_s']:.3f}",
              f"{r['render_s']:.3f}", f"{r['seconds']:.3f}"] for r in rows if r["study"] == "voxel"]
    precision = [[r["setting"], f"{r['psnr_gt']:.3f}", _fmt(r["max_abs_ref"], 3), f"{r['render_s']:.3f}"]
                 for r in rows if r["study"] == "precision"]
    cutoff = [[r["setting"], f"{r['psnr_gt']:.3f}", _fmt(r["psnr_ref"], 4), _fmt(r["max_abs_ref"], 3),
               f"{r['render_s']:.3f}"] for r in rows if r["study"] == "cutoff"]
    w, h = s.width * s.render_scale, s.height * s.render_scale
    text = f"""# Error against run time

One simulated scene ({s.views} views of {s.width}x{s.height}, seed {s.seed}), {n_targets} held-out views.
Times are wall-clock seconds on {_machine()}; each is the best of {s.repeats} runs.

## Voxel size x policy

PSNR of the held-out renders against the ray-cast ground truth, and the time of fusion plus
rendering all {n_targets} held-out views.

{_md_table(["voxel", "policy", "Gaussians", "PSNR (dB)", "fusion (s)", "render (s)", "total (s)"], voxel)}

## Renderer float32 vs float64

The occupancy-fused cloud at voxel {s.render_voxel}, rendered at {w}x{h}.

{_md_table(["precision", "PSNR vs truth (dB)", "max abs diff vs float64", "render (s)"], precision)}

## Renderer cut-offs

One cut-off at a time from the defaults (alpha_threshold 1/255, transmittance_stop 1e-4,
extent_sigma 3), float32, same cloud and size. The reference is a float64 render with
alpha_threshold 1e-7, transmittance_stop 1e-9 and extent_sigma 8.

{_md_table(["setting", "PSNR vs truth (dB)", "PSNR vs exact (dB)", "max abs diff vs exact", "render (s)"], cutoff)}

Regenerate with:

```
{_command("tradeoff", os.path.relpath(os.path.dirname(path)), quick)}
```
"""
    with open(path, "w") as f:
        f.write(text)


# ------------------------------------------------------------------------------------------------
# 3. Stability


@dataclass
class _Case:
    """One stiff or extreme input: run(precision) returns the outputs to compare."""

    suite: str
    name: str
    run: object
    policy: str = ""
    extra: dict = field(default_factory=dict)


def _onehot_voxel(conf):
    """One voxel of len(conf) samples with one-hot features, so that the fused features are the weights."""
    n = len(conf)
    pos = np.zeros((n, 3), np.float32)
    pos[:, 0] = np.linspace(-0.3, 0.3, n)
    pos[:, 1] = np.linspace(0.1, -0.1, n)
    return pos, np.eye(n, dtype=np.float32), np.asarray(conf, np.float32)


def _random_voxel(n, channels, seed, spread=0.45):
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-spread, spread, (n, 3)).astype(np.float32)
    feat = rng.normal(size=(n, channels)).astype(np.float32)
    conf = rng.normal(scale=2.0, size=n).astype(np.float32)
    return pos, feat, conf


def _fusion_cases(quick: bool) -> list[_Case]:
    big = 20_000 if quick else 1_000_000
    many = 10_000 if quick else 100_000
    fmax = float(np.finfo(np.float32).max)
    cases = []

    def voxels(pos, feat, conf, voxel=1.0, **knobs):
        def run(policy, precision):
            r = avsplat.fuse_voxels(pos, feat, voxel, confidence=conf, policy=policy, precision=precision, **knobs)
            return dict(positions=r.positions.copy(), features=r.features.copy(), reliability=r.reliability.copy(),
                        entropy=r.entropy.copy())

        return run

    specs = [
        ("confidences +-1e30 mixed, 6 samples", _onehot_voxel([1e30, -1e30, 1e30, 0, -1e30, 5]), {}),
        ("all confidences +1e30", _onehot_voxel([1e30] * 6), {}),
        ("all confidences -1e30", _onehot_voxel([-1e30] * 6), {}),
        ("confidences +-FLT_MAX", _onehot_voxel([fmax, -fmax, 0, fmax, 1, -1]), {}),
        ("sparsemax, confidences +-1e30", _onehot_voxel([1e30, -1e30, 1e30, 0, -1e30, 5]), dict(weights="sparsemax")),
        ("probability mapping, c = 0 and 1 exactly", _onehot_voxel([0, 1, 0.5, 1, 0, 0.25]),
         dict(confidence_mapping="probability")),
        ("positive mapping, c = 0 and 1e30", _onehot_voxel([0, 1e30, 1, 0, 1e30, 2]), dict(confidence_mapping="positive")),
    ]
    pos, feat, conf = _random_voxel(many, 3, 17)
    conf[:] = 0
    conf[4321] = 50
    specs.append((f"one dominant sample (c = 50) among {many:,} at c = 0", (pos, feat, conf), {}))
    specs.append(("2000 samples in one voxel (tau clips at tau_min)", _random_voxel(2000, 2, 23), {}))
    specs.append(("2 samples, tau0 = 50 (tau clips at tau_max)", _random_voxel(2, 2, 29), dict(tau0=50.0)))
    specs.append((f"{big:,} samples in one voxel", _random_voxel(big, 2, 31), {}))
    pos, feat, conf = _random_voxel(50, 4, 37)
    pos[:] = (0.125, -0.25, 0.0)
    specs.append(("50 samples at one point (variance 0)", (pos, feat, conf), {}))
    pos, feat, conf = _random_voxel(many, 3, 41, spread=0.5)
    pos = (pos.astype(np.float64) + 1e6).astype(np.float32)
    specs.append((f"{many:,} samples at coordinates ~1e6, voxel 0.01", (pos, feat, conf), dict(voxel=0.01)))
    for name, (p, f, c), knobs in specs:
        knobs = dict(knobs)
        voxel = knobs.pop("voxel", 1.0)
        for policy in POLICIES:
            cases.append(_Case("fusion", name, voxels(p, f, c, voxel, **knobs), policy=policy))

    # fuse_gaussians with stiff shapes: scales from 1e-8 to 1e4, moment matching and averaging.
    rng = np.random.default_rng(43)
    n = 600
    means = rng.uniform(-0.5, 0.5, (n, 3)).astype(np.float32)
    scales = (10.0 ** rng.uniform(-8, 4, (n, 3))).astype(np.float32)
    rots = rng.normal(size=(n, 4)).astype(np.float32)
    cloud = avsplat.GaussianCloud(means, scales, rots, rng.uniform(0, 1, n).astype(np.float32),
                                  rng.normal(size=(n, 4, 3)).astype(np.float32),
                                  confidence=rng.normal(scale=3, size=n).astype(np.float32))
    for shape in ("average", "moment"):
        def run(policy, precision, shape=shape):
            r = avsplat.fuse_gaussians(cloud, 0.25, policy=policy, precision=precision, shape=shape)
            c = r.cloud
            return dict(means=c.means.copy(), scales=c.scales.copy(), rotations=c.rotations.copy(),
                        opacities=c.opacities.copy(), sh=c.sh.copy())

        for policy in POLICIES:
            cases.append(_Case("fusion", f"Gaussians with scales 1e-8..1e4, shape={shape}", run, policy=policy))
    return cases


def _cloud(means, scales, quats, opacities, colors):
    """A GaussianCloud of degree 0 from colours in [0, 1]."""
    c0 = 0.28209479177387814
    sh = ((np.asarray(colors, np.float64) - 0.5) / c0).astype(np.float32)[:, None, :]
    return avsplat.GaussianCloud(np.asarray(means, np.float32), np.asarray(scales, np.float32),
                                 np.asarray(quats, np.float32), np.asarray(opacities, np.float32), sh)


def _stiff_scene(scale_sets, z, seed):
    rng = np.random.default_rng(seed)
    rows = []
    for s in scale_sets:
        for rep in range(20):
            rows.append((np.array([0.5 * rng.normal(), 0.5 * rng.normal(), z + 0.3 * rng.normal()]), np.array(s),
                         rng.normal(size=4), 1.0 if rep % 5 == 0 else rng.uniform(), rng.uniform(size=3)))
    return _cloud(*[np.array([r[k] for r in rows]) for k in range(5)])


def _axis_camera(width=64, height=48, f=50.0):
    return avsplat.Camera(f, f, width / 2, height / 2, width, height)


def _render_cases(quick: bool) -> list[_Case]:
    cam = _axis_camera()
    bg = (0.2, 0.4, 0.6)

    def renders(cloud, camera=cam):
        def run(policy, precision, antialiased=False):
            r = avsplat.render(cloud, camera, precision=precision, background=bg, antialiased=antialiased)
            # "_visible" is reported, not compared: a count that differs explains a large error.
            return dict(color=r.color.copy(), alpha=r.alpha.copy(), depth=r.depth.copy(), _visible=r.stats.visible)

        return run

    needles = _stiff_scene([(1, 1e-6, 1e-6), (1e-6, 1, 1e-6), (1, 1, 1e-6), (1e-6, 1, 1)], 3.0, 1)
    tiny_huge = _stiff_scene([(1e-8, 1e-8, 1e-8), (1e4, 1e4, 1e4), (1e4, 1e-8, 1)], 3.0, 2)
    near = []
    for z in (0.01 * 1.001, 0.01 * 0.999, 0.01, 0.0, -0.3, 0.3):
        near.append(((0.001, -0.002, z), (0.5, 0.2, 1.0), (0.9, 0.1, 0.3, 0.2), 0.8, (0.9, 0.1, 0.5)))
    near.append(((0, 0, 0.05), (2, 2, 2), (1, 0, 0, 0), 0.5, (0.1, 0.9, 0.1)))
    near_cloud = _cloud(*[np.array([r[k] for r in near]) for k in range(5)])
    binary = _stiff_scene([(0.1, 0.2, 0.3)], 3.0, 3)
    binary.opacities = (np.arange(len(binary)) % 2).astype(np.float32)
    rng = np.random.default_rng(4)
    n_tile = 10_000 if quick else 100_000
    u = rng.uniform(size=(n_tile, 7))
    tile = _cloud(np.stack([(16 * u[:, 0] - 32) / 50 * 4, (16 * u[:, 1] - 24) / 50 * 4, 4 + 0.01 * u[:, 2]], 1),
                  np.tile([0.01, 0.02, 0.01], (n_tile, 1)), np.tile([1, 0, 0, 0], (n_tile, 1)),
                  0.004 + 0.016 * u[:, 3], u[:, 4:7])
    # Coordinates of 1e6 with the camera near them; offsets are multiples of 1/16, exact there.
    steps = np.random.default_rng(8).integers(-16, 17, size=(200, 3)) / 16.0
    base = np.array([1e6, -1e6, 1e6])
    i = np.arange(200)
    shapes = np.stack([0.05 + 0.1 * (i % 3), np.full(200, 0.1), np.full(200, 0.07)], 1)
    quats = np.stack([np.ones(200), 0.1 * (i % 5), np.full(200, 0.2), np.full(200, -0.1)], 1)
    cols = np.stack([0.1 * (i % 10), np.full(200, 0.5), 1 - 0.1 * (i % 10)], 1)
    far_cloud = _cloud(base + steps, shapes, quats, np.full(200, 0.7), cols)
    origin_cloud = _cloud(steps, shapes, quats, np.full(200, 0.7), cols)
    eye = np.array([0.3, -0.4, -3.0])
    cam_far = avsplat.Camera.look_at(base + eye, base, np.array([0, -1, 0]), 60.0, 64, 48)
    cam_origin = avsplat.Camera.look_at(eye, np.zeros(3), np.array([0, -1, 0]), 60.0, 64, 48)
    origin_image = avsplat.render(origin_cloud, cam_origin, precision="float64", background=bg).color.copy()

    cases = [
        _Case("render", "needles and pancakes: scale ratios of 1e6", renders(needles)),
        _Case("render", "needles and pancakes: scale ratios of 1e6 (antialiased)",
              lambda policy, precision, run=renders(needles): run(policy, precision, True)),
        _Case("render", "scales of 1e-8 and 1e4", renders(tiny_huge)),
        _Case("render", "Gaussians straddling the near plane, camera inside a Gaussian", renders(near_cloud)),
        _Case("render", "opacities 0 and 1 only", renders(binary)),
        _Case("render", f"{n_tile:,} Gaussians in one 16x16 tile", renders(tile)),
        _Case("render", "coordinates of 1e6, camera near them", renders(far_cloud, cam_far),
              extra=dict(origin_image=origin_image)),
    ]
    return cases


def run_stability(out_dir: str, quick: bool = False) -> list[dict]:
    """Every stiff and extreme case of the fusion and renderer test suites (tests/cpp/test_fusion.cpp,
    tests/cpp/test_render.cpp "[stress]"), rebuilt here through the Python API, run in float32 and
    in float64: the largest difference of every output, |a - b| / max(1, |b|) (fusion: positions,
    features or Gaussian parameters, reliability, entropy; render: colour, alpha, depth), whether every output
    of both runs is finite, and the float32 time. Writes stability.csv, .png, .md; returns the rows.
    """
    os.makedirs(out_dir, exist_ok=True)
    cases = _fusion_cases(quick) + _render_cases(quick)
    progress = _Progress("stability", len(cases))
    rows = []
    for case in cases:
        out32, t32 = _best_time(lambda: case.run(case.policy, "float32"), 1)
        out64, t64 = _best_time(lambda: case.run(case.policy, "float64"), 1)
        keys = [k for k in out64 if not k.startswith("_")]
        errors = {k: _max_err(out32[k], out64[k]) for k in keys}
        worst = max(errors, key=errors.get)
        notes = []
        if "_visible" in out64:
            v32, v64 = out32["_visible"], out64["_visible"]
            notes.append(f"visible Gaussians {v32} (float32), {v64} (float64)" if v32 != v64 else f"visible {v64}")
        if "origin_image" in case.extra:
            notes.append("colour vs the same scene at the origin (float64): max abs diff "
                         f"{_fmt(_max_abs(out32['color'], case.extra['origin_image']))}")
        row = dict(suite=case.suite, case=case.name, policy=case.policy or "-", max_err=errors[worst],
                   worst_output=worst, all_finite=_finite(*(out32[k] for k in keys), *(out64[k] for k in keys)),
                   seconds_f32=t32, seconds_f64=t64, notes="; ".join(notes))
        rows.append(row)
        progress.advance(case.name[:30])
    columns = ["suite", "case", "policy", "max_err", "worst_output", "all_finite", "seconds_f32", "seconds_f64",
               "notes"]
    _write_csv(os.path.join(out_dir, "stability.csv"), rows, columns)
    _plot_stability(os.path.join(out_dir, "stability.png"), rows)
    _write_stability_md(os.path.join(out_dir, "stability.md"), rows, quick)
    return rows


def _plot_stability(path, rows):
    plt = _pyplot()
    fig, ax = plt.subplots(figsize=(10, 0.28 * len(rows) + 1.5))
    labels = [f"{r['case'][:58]}" + (f" [{r['policy']}]" if r["policy"] != "-" else "") for r in rows]
    errs = [max(r["max_err"], 1e-12) if math.isfinite(r["max_err"]) else 1.0 for r in rows]
    colors = ["tab:blue" if r["suite"] == "fusion" else "tab:orange" for r in rows]
    colors = [c if r["all_finite"] else "tab:red" for c, r in zip(colors, rows)]
    y = np.arange(len(rows))
    ax.barh(y, errs, color=colors)
    ax.set_yticks(y)
    ax.set_yticklabels(labels, fontsize=7)
    ax.invert_yaxis()
    ax.set_xscale("log")
    ax.set_xlabel("max |float32 - float64| / max(1, |float64|) (floored at 1e-12; red: non-finite output)")
    ax.set_title("Stiff and extreme cases: float32 against the float64 reference\n(blue: fusion, orange: render)")
    ax.grid(alpha=0.3, axis="x")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _write_stability_md(path, rows, quick):
    table = [[r["suite"], r["case"], r["policy"], _fmt(r["max_err"], 3), r["worst_output"],
              "yes" if r["all_finite"] else "**no**", f"{r['seconds_f32'] * 1e3:.1f}", r["notes"]] for r in rows]
    worst = max(rows, key=lambda r: r["max_err"])
    finite = sum(r["all_finite"] for r in rows)
    text = f"""# Stability: stiff and extreme cases against float64

Every stiff and extreme case of the fusion and renderer test suites, rebuilt through the Python
API and run with precision float32 (the fast path) and float64 (the reference path). "max err" is
the largest of |float32 - float64| / max(1, |float64|) over every output, i.e. the absolute error
of values up to 1 (colours, alpha, weights) and the relative error of larger ones; "output" names
the output where it occurs (fusion: fused positions and features, or the fused Gaussian
parameters, and the reliability and entropy diagnostics; render: colour, alpha and depth).
Fusion cases with one-hot features make the fused features equal to the weights.
Time is the float32 call, on {_machine()}.

{_md_table(["suite", "case", "policy", "max err", "output", "all finite", "time (ms)", "notes"], table)}

{finite}/{len(rows)} cases finite in both precisions; the largest difference is
{_fmt(worst["max_err"])} in {worst["worst_output"]} ({worst["case"]}{", " + worst["policy"] if worst["policy"] != "-" else ""}).

Regenerate with:

```
{_command("stability", os.path.relpath(os.path.dirname(path)), quick)}
```
"""
    with open(path, "w") as f:
        f.write(text)


# ------------------------------------------------------------------------------------------------
# Command line


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m avsplat.evaluation", description=__doc__.split("\n\n")[0])
    parser.add_argument("report", choices=["scaling", "tradeoff", "stability"])
    parser.add_argument("-o", "--output-dir", default=".", help="directory for <report>.csv, .png and .md")
    parser.add_argument("--quick", action="store_true", help="tiny settings for smoke tests")
    args = parser.parse_args(argv)
    run = {"scaling": run_scaling, "tradeoff": run_tradeoff, "stability": run_stability}[args.report]
    try:
        t0 = time.perf_counter()
        run(args.output_dir, quick=args.quick)
    except Exception as e:  # one clear line, as the avsplat command-line tool reports errors
        message = " ".join(str(e).split()) or type(e).__name__
        print(f"avsplat: error: eval {args.report}: {message}", file=sys.stderr)
        return 1
    for ext in ("csv", "png", "md"):
        print(f"wrote {os.path.join(args.output_dir, args.report + '.' + ext)}")
    print(f"{args.report}: done in {time.perf_counter() - t0:.1f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
