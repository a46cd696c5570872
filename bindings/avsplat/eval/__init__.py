"""Evaluation reports: dense-view scaling, error against run time, numerical stability.

Each report is one function that writes ``<name>.csv`` (every measurement), ``<name>.png`` (a
plot) and ``<name>.md`` (a markdown table with the command that made it) into a directory, and
returns the rows it measured:

    run_scaling(out_dir)    views x fusion policy: PSNR, SSIM, Gaussian count, fusion time
    run_tradeoff(out_dir)   voxel size x policy, float32 vs float64, renderer cut-offs:
                            (error, seconds) points
    run_stability(out_dir)  the stiff and extreme cases of the fusion and renderer test suites:
                            error of the float32 path against float64, finiteness, time
    run_views(out_dir)      n of S views fused, chosen by greedy coverage, capture order or
                            evenly spaced: PSNR, SSIM, fusion time
    run_regimes(out_dir)    the regime map: policy x fusion path (decoded Gaussians, raw
                            features) over samples per voxel, error-model strength and the
                            confidence's informativeness, and a dense-view curve
    run_reduction(out_dir)  simplify to 1/2 .. 1/16 of the Gaussians, ours against
                            splat-transform: PSNR, SSIM vs the unreduced renders, time, bytes
    run_stitching(out_dir)  chunked captures: registration error against overlap and noise,
                            with and without the pose graph; held-out PSNR / SSIM of stitched
                            scenes against the true-transform ceiling; time per stage
    run_lod(out_dir)        level-of-detail sets, avsplat.build_lod against splat-transform's
                            route (-d per level, then its LOD writer): per level Gaussians,
                            bytes, PSNR, SSIM vs level 0, and the whole build's time

From a shell (``avsplat eval REPORT -o DIR`` runs exactly this, with avsplat importable)::

    python3 -m avsplat.eval scaling -o apps/benchmarks/reports

``--quick`` (``quick=True``) shrinks every report to a few seconds for smoke tests; its numbers
are not meant for conclusions. Progress goes to stderr as a bar on a terminal, and as plain lines
on stdout otherwise. Timings are wall-clock seconds of the C++ calls (GIL released), best of a
few repeats where noted, on whatever machine runs the report; the markdown says which.

One module per report (scaling, tradeoff, stability, views); all of them write their files through
_report.write_report. A new report is a module with a ``run_<name>(out_dir, quick=False)`` that
measures rows and hands them to write_report, plus one entry in REPORTS below.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from typing import Protocol, Sequence

from ._common import POLICIES, Row
from .scaling import ABLATIONS, ScalingSettings, run_scaling
from .stability import run_stability
from .tradeoff import TradeoffSettings, run_tradeoff
from .views import ViewsSettings, run_views
from .regimes import RegimesSettings, run_regimes
from .reduction import ReductionSettings, run_reduction
from .stitching import StitchingSettings, run_stitching
from .lod import LodSettings, run_lod


class Report(Protocol):
    """A report's run function: measures, writes the files into out_dir and returns the rows."""

    def __call__(self, out_dir: str, *, quick: bool = False) -> list[Row]: ...


# Report name (the file stem and the word of `avsplat eval NAME`) -> run(out_dir, quick=...).
REPORTS: dict[str, Report] = {
    "scaling": run_scaling,
    "tradeoff": run_tradeoff,
    "stability": run_stability,
    "views": run_views,
    "regimes": run_regimes,
    "reduction": run_reduction,
    "stitching": run_stitching,
    "lod": run_lod,
}

__all__ = ["ABLATIONS", "POLICIES", "REPORTS", "ScalingSettings", "TradeoffSettings", "main", "run_scaling",
           "run_stability", "run_tradeoff", "run_views", "ViewsSettings", "RegimesSettings", "run_regimes",
           "ReductionSettings", "run_reduction", "StitchingSettings", "run_stitching", "LodSettings", "run_lod"]


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m avsplat.eval", description=__doc__.split("\n\n")[0])
    parser.add_argument("report", help="one of " + ", ".join(REPORTS))
    parser.add_argument("-o", "--output-dir", default=".", help="directory for <report>.csv, .png and .md")
    parser.add_argument("--quick", action="store_true", help="tiny settings for smoke tests")
    args = parser.parse_args(argv)
    run = REPORTS.get(args.report)
    if run is None:  # one line, as `avsplat eval` reports usage errors (exit code 2)
        print(f"avsplat: error: eval: unknown report '{args.report}' (one of {', '.join(REPORTS)})", file=sys.stderr)
        return 2
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
