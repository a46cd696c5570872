"""Report `stability`: the stiff and extreme cases of the fusion and renderer test suites, float32
against the float64 reference path."""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from types import ModuleType
from typing import TYPE_CHECKING, Any, Callable, Sequence, TypeAlias

import numpy as np
import numpy.typing as npt

import avsplat

from ..render import render
from ._common import POLICIES, Progress, Row, best_time, finite, fmt, max_abs, max_err
from ._report import machine, md_table, write_report

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from ..core import Camera, GaussianCloud

# The outputs of one run of a case, by name: arrays to compare, and names starting with "_" that
# are only reported.
Outputs: TypeAlias = dict[str, Any]
# The samples of a fusion case: positions (N, 3), features (N, C), confidences (N,).
Samples: TypeAlias = tuple[npt.NDArray[np.float32], npt.NDArray[np.float32], npt.NDArray[np.float32]]

@dataclass
class _Case:
    """One stiff or extreme input: run(precision) returns the outputs to compare."""

    suite: str
    name: str
    run: Callable[[str, str], Outputs]  # run(policy, precision)
    policy: str = ""
    extra: dict[str, Any] = field(default_factory=dict)


def _onehot_voxel(conf: Sequence[float]) -> Samples:
    """One voxel of len(conf) samples with one-hot features, so that the fused features are the weights."""
    n = len(conf)
    pos = np.zeros((n, 3), np.float32)
    pos[:, 0] = np.linspace(-0.3, 0.3, n)
    pos[:, 1] = np.linspace(0.1, -0.1, n)
    return pos, np.eye(n, dtype=np.float32), np.asarray(conf, np.float32)


def _random_voxel(n: int, channels: int, seed: int, spread: float = 0.45) -> Samples:
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-spread, spread, (n, 3)).astype(np.float32)
    feat = rng.normal(size=(n, channels)).astype(np.float32)
    conf = rng.normal(scale=2.0, size=n).astype(np.float32)
    return pos, feat, conf


def _fusion_cases(quick: bool) -> list[_Case]:
    big = 20_000 if quick else 1_000_000
    many = 10_000 if quick else 100_000
    fmax = float(np.finfo(np.float32).max)
    cases: list[_Case] = []

    def voxels(pos: npt.NDArray[np.float32], feat: npt.NDArray[np.float32], conf: npt.NDArray[np.float32],
               voxel: float = 1.0, **knobs: Any) -> Callable[[str, str], Outputs]:
        def run(policy: str, precision: str) -> Outputs:
            r = avsplat.fuse_voxels(pos, feat, voxel, confidence=conf, policy=policy, precision=precision, **knobs)
            return dict(positions=r.positions.copy(), features=r.features.copy(), reliability=r.reliability.copy(),
                        entropy=r.entropy.copy())

        return run

    specs: list[tuple[str, Samples, dict[str, Any]]] = [
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
        def run(policy: str, precision: str, shape: str = shape) -> Outputs:
            r = avsplat.fuse_gaussians(cloud, 0.25, policy=policy, precision=precision, shape=shape)
            c = r.cloud
            return dict(means=c.means.copy(), scales=c.scales.copy(), rotations=c.rotations.copy(),
                        opacities=c.opacities.copy(), sh=c.sh.copy())

        for policy in POLICIES:
            cases.append(_Case("fusion", f"Gaussians with scales 1e-8..1e4, shape={shape}", run, policy=policy))
    return cases


def _cloud(means: npt.ArrayLike, scales: npt.ArrayLike, quats: npt.ArrayLike, opacities: npt.ArrayLike,
           colors: npt.ArrayLike) -> GaussianCloud:
    """A GaussianCloud of degree 0 from colours in [0, 1]."""
    c0 = 0.28209479177387814
    sh = ((np.asarray(colors, np.float64) - 0.5) / c0).astype(np.float32)[:, None, :]
    return avsplat.GaussianCloud(np.asarray(means, np.float32), np.asarray(scales, np.float32),
                                 np.asarray(quats, np.float32), np.asarray(opacities, np.float32), sh)


def _stiff_scene(scale_sets: Sequence[tuple[float, float, float]], z: float, seed: int) -> GaussianCloud:
    rng = np.random.default_rng(seed)
    rows: list[tuple[Any, ...]] = []
    for s in scale_sets:
        for rep in range(20):
            rows.append((np.array([0.5 * rng.normal(), 0.5 * rng.normal(), z + 0.3 * rng.normal()]), np.array(s),
                         rng.normal(size=4), 1.0 if rep % 5 == 0 else rng.uniform(), rng.uniform(size=3)))
    return _cloud(*[np.array([r[k] for r in rows]) for k in range(5)])


def _axis_camera(width: int = 64, height: int = 48, f: float = 50.0) -> Camera:
    return avsplat.Camera(f, f, width / 2, height / 2, width, height)


def _render_cases(quick: bool) -> list[_Case]:
    cam = _axis_camera()
    bg = (0.2, 0.4, 0.6)

    def renders(cloud: GaussianCloud, camera: Camera = cam) -> Callable[..., Outputs]:
        def run(policy: str, precision: str, antialiased: bool = False) -> Outputs:
            r = render(cloud, camera, precision=precision, background=bg, antialiased=antialiased)
            # "_visible" is reported, not compared: a count that differs explains a large error.
            return dict(color=r.color.copy(), alpha=r.alpha.copy(), depth=r.depth.copy(), _visible=r.stats.visible)

        return run

    needles = _stiff_scene([(1, 1e-6, 1e-6), (1e-6, 1, 1e-6), (1, 1, 1e-6), (1e-6, 1, 1)], 3.0, 1)
    tiny_huge = _stiff_scene([(1e-8, 1e-8, 1e-8), (1e4, 1e4, 1e4), (1e4, 1e-8, 1)], 3.0, 2)
    near: list[tuple[Any, ...]] = []
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
    origin_image = render(origin_cloud, cam_origin, precision="float64", background=bg).color.copy()
    needles_run = renders(needles)

    def needles_antialiased(policy: str, precision: str) -> Outputs:
        return needles_run(policy, precision, True)

    cases = [
        _Case("render", "needles and pancakes: scale ratios of 1e6", renders(needles)),
        _Case("render", "needles and pancakes: scale ratios of 1e6 (antialiased)",
              needles_antialiased),
        _Case("render", "scales of 1e-8 and 1e4", renders(tiny_huge)),
        _Case("render", "Gaussians straddling the near plane, camera inside a Gaussian", renders(near_cloud)),
        _Case("render", "opacities 0 and 1 only", renders(binary)),
        _Case("render", f"{n_tile:,} Gaussians in one 16x16 tile", renders(tile)),
        _Case("render", "coordinates of 1e6, camera near them", renders(far_cloud, cam_far),
              extra=dict(origin_image=origin_image)),
    ]
    return cases


def run_stability(out_dir: str, quick: bool = False) -> list[Row]:
    """Every stiff and extreme case of the fusion and renderer test suites (tests/cpp/test_fusion.cpp,
    tests/cpp/test_render.cpp "[stress]"), rebuilt here through the Python API, run in float32 and
    in float64: the largest difference of every output, abs(a - b) / max(1, abs(b)) (fusion: positions,
    features or Gaussian parameters, reliability, entropy; render: colour, alpha, depth), whether every output
    of both runs is finite, and the float32 time. Writes stability.csv, .png, .md; returns the rows.

    Parameters
    ----------
    out_dir : str
        Folder for stability.csv, stability.png and stability.md.
    quick : bool
        Tiny settings (seconds; for smoke tests, not for conclusions).

    Returns
    -------
    list of Row
        One row per measurement, as written to stability.csv.
    """
    os.makedirs(out_dir, exist_ok=True)
    cases = _fusion_cases(quick) + _render_cases(quick)
    progress = Progress("stability", len(cases))
    rows: list[Row] = []
    for case in cases:
        out32, t32 = best_time(lambda: case.run(case.policy, "float32"), 1)
        out64, t64 = best_time(lambda: case.run(case.policy, "float64"), 1)
        keys = [k for k in out64 if not k.startswith("_")]
        errors = {k: max_err(out32[k], out64[k]) for k in keys}
        worst = max(errors, key=errors.__getitem__)
        notes = []
        if "_visible" in out64:
            v32, v64 = out32["_visible"], out64["_visible"]
            notes.append(f"visible Gaussians {v32} (float32), {v64} (float64)" if v32 != v64 else f"visible {v64}")
        if "origin_image" in case.extra:
            notes.append("colour vs the same scene at the origin (float64): max abs diff "
                         f"{fmt(max_abs(out32['color'], case.extra['origin_image']))}")
        row = dict(suite=case.suite, case=case.name, policy=case.policy or "-", max_err=errors[worst],
                   worst_output=worst, all_finite=finite(*(out32[k] for k in keys), *(out64[k] for k in keys)),
                   seconds_f32=t32, seconds_f64=t64, notes="; ".join(notes))
        rows.append(row)
        progress.advance(case.name[:30])
    columns = ["suite", "case", "policy", "max_err", "worst_output", "all_finite", "seconds_f32", "seconds_f64",
               "notes"]
    write_report(out_dir, "stability", rows, columns, plot=lambda plt: _plot_stability(plt, rows),
                 title="Stability: stiff and extreme cases against float64", body=_stability_md(rows), quick=quick)
    return rows


def _plot_stability(plt: ModuleType, rows: Sequence[Row]) -> Figure:
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
    return fig


def _stability_md(rows: Sequence[Row]) -> str:
    table = [[r["suite"], r["case"], r["policy"], fmt(r["max_err"], 3), r["worst_output"],
              "yes" if r["all_finite"] else "**no**", f"{r['seconds_f32'] * 1e3:.1f}", r["notes"]] for r in rows]
    worst = max(rows, key=lambda r: r["max_err"])
    finite = sum(r["all_finite"] for r in rows)
    return f"""Every stiff and extreme case of the fusion and renderer test suites, rebuilt through the Python
API and run with precision float32 (the fast path) and float64 (the reference path). "max err" is
the largest of |float32 - float64| / max(1, |float64|) over every output, i.e. the absolute error
of values up to 1 (colours, alpha, weights) and the relative error of larger ones; "output" names
the output where it occurs (fusion: fused positions and features, or the fused Gaussian
parameters, and the reliability and entropy diagnostics; render: colour, alpha and depth).
Fusion cases with one-hot features make the fused features equal to the weights.
Time is the float32 call, on {machine()}.

{md_table(["suite", "case", "policy", "max err", "output", "all finite", "time (ms)", "notes"], table)}

{finite}/{len(rows)} cases finite in both precisions; the largest difference is
{fmt(worst["max_err"])} in {worst["worst_output"]} ({worst["case"]}{", " + worst["policy"] if worst["policy"] != "-" else ""}).
"""
