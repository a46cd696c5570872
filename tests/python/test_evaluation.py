"""Smoke test of the evaluation reports (avsplat.evaluation) with their tiny --quick settings.

Each report must write its CSV, PNG and markdown; a measured row is recomputed here with the
public API (the same simulation, fusion, render and metric), so the report measures what it says.
"""

import csv
import math
import os

import numpy as np
import pytest

import avsplat
from avsplat import evaluation


def read_csv(path):
    with open(path) as f:
        return list(csv.DictReader(f))


def check_outputs(out_dir, name):
    for ext in ("csv", "png", "md"):
        path = os.path.join(out_dir, f"{name}.{ext}")
        assert os.path.getsize(path) > 0, path
    with open(os.path.join(out_dir, f"{name}.png"), "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    md = open(os.path.join(out_dir, f"{name}.md")).read()
    assert f"avsplat eval {name} -o " in md and "--quick" in md
    assert "|---|" in md
    return read_csv(os.path.join(out_dir, f"{name}.csv")), md


@pytest.fixture(scope="module")
def out_dir(tmp_path_factory):
    return str(tmp_path_factory.mktemp("reports"))


def test_scaling_report(out_dir):
    s = evaluation.ScalingSettings.quick()
    rows = evaluation.run_scaling(out_dir, quick=True)
    table, md = check_outputs(out_dir, "scaling")
    assert len(table) == len(rows)
    main = [r for r in table if r["condition"] == "default"]
    per_view = len(s.shapes) * len(s.voxel_sizes) * len(s.policies) + (1 if s.unfused else 0)
    assert len(main) == len(s.seeds) * len(s.views) * per_view
    conditions = {r["condition"] for r in table}
    assert conditions == set(evaluation.ABLATIONS) | {evaluation.scaling.REALISTIC_CONDITION}
    assert "occupancy - mean" in md and "With the error models of real predictions" in md
    realistic = [r for r in table if r["condition"] == evaluation.scaling.REALISTIC_CONDITION]
    assert len(realistic) == len(s.realistic_seeds) * len(s.views) * len(s.voxel_sizes) * len(s.policies)

    # Recompute one row with the API: same simulation, fusion, targets and metrics.
    views, voxel = s.views[-1], s.voxel_sizes[0]
    row = next(r for r in main if int(r["views"]) == views and r["policy"] == "occupancy"
               and r["shape"] == s.shapes[-1] and float(r["voxel"]) == voxel)
    preds = avsplat.simulate_predictions(views=views, width=s.width, height=s.height,
                                         target_views=min(s.target_views, views - 1), seed=s.seeds[0])
    fused = avsplat.fuse_gaussians(preds.gaussians(), voxel, policy="occupancy", shape=s.shapes[-1]).cloud
    targets = avsplat.target_cameras(views=max(s.views), target_views=s.target_views, width=s.width, height=s.height)
    psnr = np.mean([avsplat.psnr(avsplat.render(fused, c).color, avsplat.ground_truth(c).color) for c in targets])
    assert int(row["gaussians"]) == len(fused)
    assert float(row["psnr"]) == pytest.approx(psnr, abs=1e-9)
    for r in table:
        assert 0 < float(r["ssim"]) <= 1 and math.isfinite(float(r["psnr"]))


def test_tradeoff_report(out_dir):
    s = evaluation.TradeoffSettings.quick()
    evaluation.run_tradeoff(out_dir, quick=True)
    table, md = check_outputs(out_dir, "tradeoff")
    studies = [r["study"] for r in table]
    assert studies.count("voxel") == len(s.voxel_sizes) * len(s.policies)
    assert studies.count("precision") == 2
    assert studies.count("cutoff") == len(s.alpha_thresholds) + len(s.transmittance_stops) + len(s.extent_sigmas)
    f64 = next(r for r in table if r["study"] == "precision" and r["setting"] == "float64")
    assert float(f64["max_abs_ref"]) == 0.0  # the float64 render is the reference itself
    for r in table:
        assert float(r["seconds"]) > 0 and math.isfinite(float(r["psnr_gt"]))
    # Larger voxels never give more Gaussians.
    for policy in s.policies:
        counts = [int(r["gaussians"]) for r in table if r["study"] == "voxel" and r["policy"] == policy]
        assert counts == sorted(counts, reverse=True)


def test_stability_report(out_dir):
    rows = evaluation.run_stability(out_dir, quick=True)
    table, md = check_outputs(out_dir, "stability")
    assert len(table) == len(rows)
    assert all(r["all_finite"] == "True" for r in table)
    names = " ".join(r["case"] for r in table)
    for case in ("+-1e30", "FLT_MAX", "tau_min", "tau_max", "variance 0", "needles", "near plane", "one 16x16 tile",
                 "coordinates of 1e6"):
        assert case in names, case
    # The fusion test suite holds float32 within 1e-5 of float64 on weights and features; the
    # Gaussian cases (scales up to 1e4) are compared relatively.
    for r in table:
        if r["suite"] == "fusion":
            assert float(r["max_err"]) < 1e-3, r


def test_views_report(out_dir):
    s = evaluation.ViewsSettings.quick()
    rows = evaluation.run_views(out_dir, quick=True)
    table, md = check_outputs(out_dir, "views")
    assert len(table) == len(rows) == len(s.seeds) * len(s.counts) * 4
    assert {r["strategy"] for r in table} == {"coverage", "coverage_confident", "capture", "uniform"}
    assert "coverage - capture" in md
    preds = avsplat.simulate_predictions(views=s.views, width=s.width, height=s.height,
                                         target_views=s.target_views, seed=s.seeds[0])
    n = s.counts[0]
    # The coverage row fused the views select_views_by_coverage picks, and its PSNR is the API's.
    order = avsplat.select_views_by_coverage(preds.points, s.coverage_voxel, budget=n, valid=preds.valid).order
    row = next(r for r in table if r["strategy"] == "coverage" and int(r["n"]) == n)
    assert row["views"] == " ".join(map(str, order))
    pick = avsplat.gaussians_from_point_maps(preds.points[order], preds.colors[order], preds.confidence[order],
                                             [preds.cameras[i] for i in order], preds.normals[order],
                                             preds.valid[order])
    fused = avsplat.fuse_gaussians(pick, s.voxel, policy=s.policy).cloud
    targets = avsplat.target_cameras(views=s.views, target_views=s.target_views, width=s.width, height=s.height)
    psnr = np.mean([avsplat.psnr(avsplat.render(fused, c).color, avsplat.ground_truth(c).color) for c in targets])
    assert float(row["psnr"]) == pytest.approx(psnr, abs=1e-9)
    capture = next(r for r in table if r["strategy"] == "capture" and int(r["n"]) == n)
    assert capture["views"] == " ".join(map(str, range(n)))
    # Fusing every view is the same scene whatever the strategy.
    full = [r for r in table if int(r["n"]) == s.views]
    assert len({r["psnr"] for r in full}) == 1


def test_regimes_report(out_dir):
    s = evaluation.RegimesSettings.quick()
    rows = evaluation.run_regimes(out_dir, quick=True)
    table, md = check_outputs(out_dir, "regimes")
    per_sim = 2 * 3  # paths x policies
    n_sims = (len(s.grid_views) * len(s.grid_voxels) + sum(len(v) for v in s.models.values())
              + len(s.rhos) * len(s.rho_views) + len(s.curve_rhos) * len(s.curve_views))
    assert len(table) == len(rows) == n_sims * per_sim
    assert {r["path"] for r in table} == {"decoded", "raw"}
    assert "occupancy - mean" in md and "Dense-view scaling" in md
    # A raw-path row is the API's: fuse_voxels on the raw features, decode, render, PSNR against
    # the ground truth with the inputs' optics.
    row = next(r for r in table if r["experiment"] == "rho" and r["rho"] == "0.9" and r["path"] == "raw"
               and r["policy"] == "occupancy")
    options = dict(evaluation.regimes.REALISTIC, confidence_rho=0.9)
    views = int(row["views"])
    preds = avsplat.simulate_predictions(views=views, width=s.width, height=s.height,
                                         target_views=min(s.target_views, views - 1), seed=s.seed, **options)
    assert float(row["rho_measured"]) == pytest.approx(preds.confidence_spearman, abs=1e-12)
    v = preds.valid
    fused = avsplat.fuse_voxels(preds.points[v], preds.features[v], s.rho_voxel, confidence=preds.confidence[v],
                                policy="occupancy")
    cloud = avsplat.decode_gaussians(fused.positions, fused.features, preds.feature_layout)
    targets = avsplat.target_cameras(views=max(max(s.grid_views), max(s.rho_views), max(s.curve_views),
                                               s.model_views), target_views=s.target_views, width=s.width,
                                     height=s.height)
    truth = [avsplat.ground_truth(c, footprint_sigma=options["footprint_sigma"], specular=options["specular"]).color
             for c in targets]
    psnr = np.mean([avsplat.psnr(avsplat.render(cloud, c).color, t) for c, t in zip(targets, truth)])
    assert float(row["psnr"]) == pytest.approx(psnr, abs=1e-9)
    # Level 0 of every model is the same simulation: identical rows.
    zero = {}
    for r in table:
        if r["experiment"] == "model" and float(r["strength"]) == 0:
            zero.setdefault((r["path"], r["policy"]), set()).add(r["psnr"])
    assert len(zero) == per_sim and all(len(x) == 1 for x in zero.values())


def test_command_line_main(tmp_path, capsys):
    assert evaluation.main(["tradeoff", "-o", str(tmp_path), "--quick"]) == 0
    assert "wrote" in capsys.readouterr().out
    blocker = tmp_path / "file"
    blocker.write_text("x")
    assert evaluation.main(["tradeoff", "-o", str(blocker / "sub"), "--quick"]) == 1
    err = capsys.readouterr().err.strip().split("\n")
    assert len(err) == 1 and err[0].startswith("avsplat: error: eval tradeoff")
