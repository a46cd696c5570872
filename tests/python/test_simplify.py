"""avsplat.simplify: the moment match against numpy, budgets, determinism, errors, the CLI, and
the peer (PlayCanvas's splat-transform) on the same cloud."""

import os
import subprocess
import tempfile

import numpy as np
import pytest

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")


def quat_to_matrix(q):
    w, x, y, z = np.asarray(q, np.float64) / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                     [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                     [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


def covariance(cloud, i):
    r = quat_to_matrix(cloud.rotations[i])
    return r @ np.diag(np.asarray(cloud.scales[i], np.float64) ** 2) @ r.T


def area(a, b, c, p=1.6075):
    return 4 * np.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3) ** (1 / p)


def clustered(n, seed=0, clusters=40, degree=1):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-2, 2, (clusters, 3))
    means = centres[np.arange(n) % clusters] + rng.normal(0, 0.05, (n, 3))
    q = rng.normal(size=(n, 4))
    k = (degree + 1) ** 2
    return avsplat.GaussianCloud(means.astype(np.float32), rng.uniform(0.005, 0.025, (n, 3)).astype(np.float32),
                                 (q / np.linalg.norm(q, axis=1, keepdims=True)).astype(np.float32),
                                 rng.uniform(0.05, 0.95, n).astype(np.float32),
                                 rng.uniform(-0.5, 0.5, (n, k, 3)).astype(np.float32))


def test_pair_merge_matches_numpy_moment_matching():
    rng = np.random.default_rng(4)
    for _ in range(20):
        means = rng.normal(size=(2, 3))
        scales = rng.uniform(0.01, 0.5, (2, 3))
        q = rng.normal(size=(2, 4))
        op = rng.uniform(0.01, 1.0, 2)
        sh = rng.normal(size=(2, 4, 3))
        c = avsplat.GaussianCloud(means.astype(np.float32), scales.astype(np.float32), q.astype(np.float32),
                                  op.astype(np.float32), sh.astype(np.float32))
        m = np.asarray(c.means, np.float64)
        s = np.asarray(c.scales, np.float64)
        o = np.asarray(c.opacities, np.float64)
        w = o * np.array([area(*s[0]), area(*s[1])])
        p = w / w.sum()
        mu = p @ m
        sigma = sum(p[i] * (covariance(c, i) + np.outer(m[i] - mu, m[i] - mu)) for i in range(2))
        axes = np.sqrt(np.linalg.eigvalsh(sigma))
        opacity = min(w.sum() / area(*axes), 1.0)
        r = avsplat.simplify(c, target_count=1, method="merge")
        g = r.cloud
        assert r.output_count == 1 and r.method == "merge" and np.isnan(r.voxel_size)
        np.testing.assert_allclose(g.means[0], mu, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(covariance(g, 0), sigma, rtol=1e-4, atol=1e-6 * np.abs(sigma).max())
        np.testing.assert_allclose(g.scales[0], axes, rtol=1e-5)
        np.testing.assert_allclose(g.opacities[0], opacity, rtol=1e-5)
        np.testing.assert_allclose(g.sh[0], p[0] * np.asarray(c.sh[0], np.float64) + p[1] * np.asarray(c.sh[1], np.float64),
                                   rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("method", ["merge", "voxel"])
def test_counts_within_two_percent(method):
    c = clustered(6000, seed=1)
    for ratio in (1 / 2, 1 / 4, 1 / 8, 1 / 16):
        target = round(ratio * len(c))
        r = avsplat.simplify(c, ratio=ratio, method=method)
        assert abs(r.output_count - target) <= 0.02 * target, (ratio, r)
        assert len(r.cloud) == r.output_count and r.input_count == len(c) and r.target_count == target
        assert r.iterations >= 1  # merge rounds, or voxel sizes tried
        if method == "merge":
            assert r.output_count == target
        else:
            assert r.voxel_size > 0
    assert avsplat.simplify(c, target_count=len(c) + 5, method=method).output_count == len(c)


@pytest.mark.parametrize("method", ["merge", "voxel"])
def test_deterministic_and_independent_of_input_order(method):
    c = clustered(3000, seed=2)
    perm = np.random.default_rng(0).permutation(len(c))
    shuffled = avsplat.GaussianCloud(c.means[perm], c.scales[perm], c.rotations[perm], c.opacities[perm], c.sh[perm])
    a = avsplat.simplify(c, ratio=0.2, method=method).cloud
    b = avsplat.simplify(shuffled, ratio=0.2, method=method).cloud
    for field in ("means", "scales", "rotations", "opacities", "sh"):
        assert np.array_equal(getattr(a, field), getattr(b, field)), field


def test_antialiased_flag_is_kept():
    # A simplified antialiased scene still renders with the 2D filter (and SPZ files keep the flag).
    c = clustered(800, seed=4, degree=2)
    for flag in (True, False):
        c.antialiased = flag
        for method in ("merge", "voxel"):
            assert avsplat.simplify(c, ratio=0.25, method=method).cloud.antialiased == flag
        assert avsplat.reduce_sh(c, degree=1).cloud.antialiased == flag
        assert avsplat.prune(c).cloud.antialiased == flag


def test_thread_count_does_not_change_the_result():
    # OMP_NUM_THREADS is read at start-up, so each count runs in its own interpreter.
    code = ("import avsplat, numpy as np, sys\n"
            "rng = np.random.default_rng(3); n = 40000\n"
            "c = avsplat.GaussianCloud(rng.uniform(-1, 1, (n, 3)).astype(np.float32),"
            " rng.uniform(0.005, 0.02, (n, 3)).astype(np.float32), rng.normal(size=(n, 4)).astype(np.float32),"
            " rng.uniform(0, 1, n).astype(np.float32), rng.normal(size=(n, 1, 3)).astype(np.float32))\n"
            "for m in ('merge', 'voxel'):\n"
            "    r = avsplat.simplify(c, ratio=0.25, method=m).cloud\n"
            "    sys.stdout.write(m + ' ' + str(hash(r.means.tobytes() + r.scales.tobytes() + r.rotations.tobytes()"
            " + r.opacities.tobytes() + r.sh.tobytes())) + '\\n')\n")
    outs = []
    for threads in ("1", "2"):
        env = dict(os.environ, OMP_NUM_THREADS=threads, PYTHONHASHSEED="0")
        p = subprocess.run(["/usr/bin/python3", "-c", code], capture_output=True, text=True, env=env, timeout=300)
        assert p.returncode == 0, p.stderr
        outs.append(p.stdout)
    assert outs[0] == outs[1]


def test_stiff_cases():
    c = clustered(200, seed=5)
    # One point: merge reaches the target, voxel can only give one Gaussian.
    one = avsplat.GaussianCloud(np.full((200, 3), 0.5, np.float32), c.scales, c.rotations, c.opacities, c.sh)
    r = avsplat.simplify(one, target_count=50, method="merge")
    assert r.output_count == 50 and np.allclose(r.cloud.means, 0.5)
    assert avsplat.simplify(one, target_count=50, method="voxel").output_count == 1
    # Scales 1e-8 and 1e4, opacities 0 and 1.
    scales = np.where(np.arange(600).reshape(200, 3) % 2 == 0, 1e-8, 1e4).astype(np.float32)
    opac = (np.arange(200) % 2).astype(np.float32)
    stiff = avsplat.GaussianCloud(c.means, scales, c.rotations, opac, c.sh)
    for method in ("merge", "voxel"):
        for target in (1, 37, 200):
            g = avsplat.simplify(stiff, target_count=target, method=method).cloud
            for field in ("means", "scales", "rotations", "opacities", "sh"):
                assert np.all(np.isfinite(getattr(g, field))), (method, target, field)
            assert np.all((g.opacities >= 0) & (g.opacities <= 1))
            assert np.all(g.scales >= 0) and np.all(g.scales <= 2e4)
            np.testing.assert_allclose(np.linalg.norm(g.rotations, axis=1), 1, atol=1e-5)



@pytest.mark.parametrize("opacity", [0.01, 0.3])
def test_many_identical_gaussians(opacity):
    # 100,000 copies of one Gaussian (a degenerate cloud: every distance and every cost ties).
    # The all-kNN tree once scanned every leaf from every leaf here (29 s for this call); now it is
    # linear. Moment matching of identical Gaussians gives the same mean and covariance; the
    # merged opacity is the ink m * opacity * area of the m originals over the same area, capped
    # at 1: min(1, m * opacity) (moment_merge.h, merged_opacity).
    n = 100_000
    q = np.array([0.9, 0.1, 0.2, 0.3])
    q /= np.linalg.norm(q)
    sh = np.array([[0.1, -0.2, 0.3], [0.05, 0.0, -0.05], [0.2, 0.1, 0.0], [-0.1, 0.3, 0.2]], np.float32)
    c = avsplat.GaussianCloud(np.tile(np.float32([0.3, -0.2, 1.0]), (n, 1)),
                              np.tile(np.float32([0.01, 0.02, 0.03]), (n, 1)),
                              np.tile(q.astype(np.float32), (n, 1)), np.full(n, opacity, np.float32),
                              np.tile(sh, (n, 1, 1)))
    r = avsplat.simplify(c, ratio=1 / 16, method="merge")
    target = round(n / 16)
    assert r.target_count == target and abs(r.output_count - target) <= 0.02 * target, r
    g = r.cloud
    assert len(g) == r.output_count
    np.testing.assert_array_equal(g.means, np.asarray(c.means)[:len(g)])
    want = covariance(c, 0)
    for i in range(0, len(g), 97):
        np.testing.assert_allclose(covariance(g, i), want, rtol=1e-5, atol=1e-5 * np.abs(want).max())
    np.testing.assert_allclose(g.sh, np.tile(sh, (len(g), 1, 1)), rtol=1e-5, atol=1e-7)
    o = np.asarray(g.opacities, np.float64)
    if opacity * 64 < 1:
        # Never capped (6 rounds: at most 64 originals in one): each output holds m >= 1 whole
        # originals, and together all n (the ink is kept).
        m = o / opacity
        np.testing.assert_allclose(m, np.round(m), atol=1e-3)
        assert m.min() >= 1 - 1e-3 and r.iterations <= 6
        np.testing.assert_allclose(o.sum(), n * opacity, rtol=1e-4)
    else:
        # Each output is min(1, m * opacity) for a whole m >= 1, and merged ones (m >= 2) exist.
        allowed = np.minimum(1.0, np.arange(1, 65) * opacity)
        assert np.all(np.abs(o[:, None] - allowed[None, :]).min(axis=1) <= 1e-5 * allowed.max())
        assert np.any(o > opacity + 1e-5)

def test_max_error_with_cameras():
    c = clustered(1500, seed=6, clusters=20)
    cams = [avsplat.Camera.look_at([0, 0, 7], [0, 0, 0], [0, 1, 0], 50.0, 64, 48),
            avsplat.Camera.look_at([6, 2, 2], [0, 0, 0], [0, 1, 0], 50.0, 64, 48)]
    r = avsplat.simplify(c, max_error=0.01, cameras=cams)
    assert r.error <= 0.01 and r.output_count < len(c) and r.searches >= 2
    # The reported error is the RMSE of the returned cloud's renders against the input's.
    sq = [np.mean((avsplat.render(r.cloud, k).color.astype(np.float64) - avsplat.render(c, k).color) ** 2) for k in cams]
    assert r.error == pytest.approx(np.sqrt(np.mean(sq)), rel=1e-4, abs=1e-7)
    # A tighter bound keeps more Gaussians.
    assert avsplat.simplify(c, max_error=0.002, cameras=cams).output_count >= r.output_count
    assert np.isnan(avsplat.simplify(c, ratio=0.5).error)
    assert avsplat.simplify(c, ratio=0.5, cameras=cams[0]).error > 0


def test_bad_arguments_name_them():
    c = clustered(10)
    with pytest.raises(ValueError, match="exactly one of"):
        avsplat.simplify(c)
    with pytest.raises(ValueError, match="exactly one of"):
        avsplat.simplify(c, ratio=0.5, target_count=3)
    with pytest.raises(ValueError, match="ratio"):
        avsplat.simplify(c, ratio=0.0)
    with pytest.raises(ValueError, match="target_count"):
        avsplat.simplify(c, target_count=0)
    with pytest.raises(ValueError, match="max_error"):
        avsplat.simplify(c, max_error=0.1)
    with pytest.raises(ValueError, match="method: 'bogus' is not one of 'merge', 'voxel'"):
        avsplat.simplify(c, ratio=0.5, method="bogus")
    with pytest.raises(TypeError, match="cameras"):
        avsplat.simplify(c, ratio=0.5, cameras=[1, 2])
    bad = avsplat.GaussianCloud(c.means, c.scales, c.rotations, c.opacities, c.sh)
    bad.means[3, 1] = np.nan
    with pytest.raises(ValueError, match=r"means\[3"):
        avsplat.simplify(bad, ratio=0.5)


@pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")
def test_cli(tmp_path):
    c = clustered(800, seed=7)
    src = str(tmp_path / "in.ply")
    avsplat.write_ply(src, c)
    for args, method in ((["--ratio", "0.25"], "merge"), (["--target-count", "100", "--method", "voxel"], "voxel")):
        out = str(tmp_path / f"out-{method}.splat")
        p = subprocess.run([BIN, "simplify", src, out, *args], capture_output=True, text=True, timeout=120)
        assert p.returncode == 0, p.stderr
        got = avsplat.read_gaussians(out)
        api = avsplat.simplify(avsplat.read_ply(src), **({"ratio": 0.25} if method == "merge" else
                                                        {"target_count": 100, "method": "voxel"}))
        assert len(got) == api.output_count
        np.testing.assert_allclose(np.sort(got.means[:, 0]), np.sort(api.cloud.means[:, 0]), atol=1e-6)
    cams = str(tmp_path / "cams.json")
    avsplat.write_cameras_json(cams, [avsplat.Camera.look_at([0, 0, 7], [0, 0, 0], [0, 1, 0], 50.0, 48, 36)])
    p = subprocess.run([BIN, "simplify", src, str(tmp_path / "e.ply"), "--max-error", "0.02", "--cameras", cams],
                       capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and "rendered RMSE" in p.stdout, p.stderr
    for bad in (["--ratio", "0.5", "--target-count", "3"], [], ["--max-error", "0.1"], ["--ratio", "2"],
                ["--ratio", "0.5", "--method", "bogus"]):
        p = subprocess.run([BIN, "simplify", src, str(tmp_path / "x.ply"), *bad], capture_output=True, text=True)
        assert p.returncode != 0 and len(p.stderr.strip().splitlines()) == 1, (bad, p.stderr)
        assert not os.path.exists(tmp_path / "x.ply")


def test_peer_splat_transform_on_the_same_cloud(splat_transform, tmp_path):
    """Our merge at 1/4 is at least as close to the unreduced renders as splat-transform's -d."""
    c = clustered(4000, seed=8, clusters=60)
    src = str(tmp_path / "in.ply")
    avsplat.write_ply(src, c)
    dst = str(tmp_path / "st.ply")
    splat_transform(src, "-d", "1000", dst)
    peer = avsplat.read_gaussians(dst)
    assert len(peer) == 1000
    ours = avsplat.simplify(c, target_count=1000).cloud
    cams = [avsplat.Camera.look_at([5 * np.cos(a), 1.5, 5 * np.sin(a)], [0, 0, 0], [0, -1, 0], 60.0, 96, 72)
            for a in np.linspace(0, 2 * np.pi, 4, endpoint=False)]
    ref = [avsplat.render(c, k).color for k in cams]
    psnr_ours = np.mean([avsplat.psnr(avsplat.render(ours, k).color, r) for k, r in zip(cams, ref)])
    psnr_peer = np.mean([avsplat.psnr(avsplat.render(peer, k).color, r) for k, r in zip(cams, ref)])
    assert psnr_ours >= psnr_peer, (psnr_ours, psnr_peer)


def test_reduction_report(tmp_path, splat_transform):
    """`avsplat eval reduction` (quick settings, one ratio, and a small stand-in for the large scene):
    its files, and its merge row is what the API gives on the same scene."""
    import csv
    import dataclasses

    from avsplat.evaluation import reduction

    s = dataclasses.replace(reduction.ReductionSettings.quick(), ratios=(1 / 4,), large_count=3000,
                            large_ratios=(1 / 2,), sog_max_count=2000, real_scenes=(), scale_counts=())
    rows = reduction.run_reduction(str(tmp_path), settings=s, quick=True)
    for ext in ("csv", "png", "md"):
        assert os.path.getsize(tmp_path / f"reduction.{ext}") > 0
    md = (tmp_path / "reduction.md").read_text()
    assert "avsplat eval reduction -o" in md and "|---|" in md and "splat-transform v3.7.0" in md
    table = list(csv.DictReader(open(tmp_path / "reduction.csv")))
    # Four scenes: the input, 2 of ours, 2 of the peer's; the two SH-degree-3 scenes add reduce_sh
    # (max_error and degree 0) and -H 0; the large one has no SH-band rows.
    assert len(table) == len(rows) == 4 * (1 + 4) + 2 * 3
    assert not any(r["scene"] == "large" and r["method"] in ("reduce_sh", "st-H") for r in rows)
    assert {r["ratio"] for r in rows if r["scene"] == "large" and r["method"] != "input"} == {1 / 2}
    assert {r["method"] for r in table} == {"input", "merge", "voxel", "st-decimate", "st-adaptive", "reduce_sh",
                                            "st-H"}
    assert {r["scene"] for r in table} == {"embedded", "trained", "held-out", "large"}
    assert "**large**" in md and "- large 1/2:" in md
    assert "held-out" in md and "SH bands" in md
    # The verdict of each scene and ratio names both metrics of the quality goal, each judged from the
    # rows themselves.
    for scene in ("embedded", "trained", "held-out"):
        line = next(x for x in md.splitlines() if x.startswith(f"- {scene} 1/4:"))
        by = {r["method"]: r for r in rows if r["scene"] == scene and r["ratio"] == 1 / 4}
        best = max((by["merge"], by["voxel"]), key=lambda r: r["psnr"])
        for metric, name in (("psnr", "PSNR"), ("ssim", "SSIM")):
            met = all(best[metric] >= by[p][metric] for p in ("st-decimate", "st-adaptive"))
            assert f"{name} at least both peers': " + ("yes" if met else "**no**") in line, line
    # Every format write_gaussians writes has its bytes in every row; .sog only up to sog_max_count.
    for ext in (".ply", ".splat", ".compressed.ply", ".spz"):
        assert all(int(r[f"bytes{ext}"]) > 0 for r in table)
    for r in table:
        assert (r["bytes.sog"] != "") == (int(r["output_count"]) <= 2000), r
    assert any(r["bytes.sog"] == "" for r in table) and any(r["bytes.sog"] != "" for r in table)
    for scene in ("trained", "held-out"):
        ours_sh = next(r for r in rows if r["scene"] == scene and r["method"] == "reduce_sh" and r["sh_asked"] == 0)
        peer_sh = next(r for r in rows if r["scene"] == scene and r["method"] == "st-H")
        # Dropping the same bands: the same file size and the same renders.
        assert ours_sh["sh_degree_out"] == peer_sh["sh_degree_out"] == 0
        assert ours_sh["bytes.ply"] == peer_sh["bytes.ply"]
        assert ours_sh["psnr"] == pytest.approx(peer_sh["psnr"], abs=0.05)
    preds = avsplat.simulate_predictions(views=s.views, width=s.width, height=s.height, target_views=s.target_views,
                                         seed=s.seed)
    scene = avsplat.fuse_gaussians(preds.gaussians(), s.voxel, policy="occupancy").cloud
    target = round(len(scene) / 4)
    ours = avsplat.simplify(scene, target_count=target, method="merge").cloud
    psnr = np.mean([avsplat.psnr(avsplat.render(ours, k).color, avsplat.render(scene, k).color)
                    for k in preds.target_cameras])
    row = next(r for r in rows if r["scene"] == "embedded" and r["method"] == "merge")
    assert row["output_count"] == target and row["psnr"] == pytest.approx(psnr, rel=1e-9)
    peer = next(r for r in rows if r["scene"] == "embedded" and r["method"] == "st-decimate")
    assert peer["output_count"] == target and peer["bytes.ply"] == row["bytes.ply"]  # same count and layout


def test_resize_scene_subsamples_and_tiles_to_the_exact_count():
    """resize_scene: a subset of the rows below the input's count; above it, copies shifted on the
    horizontal grid by 1.1 x the robust extent, every row one of the input's, shifted."""
    from avsplat.eval._real_scenes import resize_scene

    rng = np.random.default_rng(3)
    n = 500
    means = rng.uniform(-1, 1, (n, 3)).astype(np.float32)
    c = avsplat.GaussianCloud(means, np.full((n, 3), 0.01, np.float32), np.tile([1, 0, 0, 0], (n, 1)).astype(np.float32),
                              rng.uniform(0.1, 1, n).astype(np.float32), rng.normal(size=(n, 1, 3)).astype(np.float32))
    small = resize_scene(c, 123)
    assert len(small) == 123
    rows = {tuple(m) for m in c.means.tolist()}
    assert all(tuple(m) in rows for m in small.means.tolist())
    big = resize_scene(c, 2100)  # 5 copies on a 3 x 3 grid
    assert len(big) == 2100
    step = 1.1 * (np.percentile(means.astype(np.float64), 98, axis=0) - np.percentile(means.astype(np.float64), 2, axis=0))
    by_opacity = {float(o): i for i, o in enumerate(c.opacities)}
    shifts = set()
    for m, o in zip(big.means, big.opacities):
        d = m.astype(np.float64) - means[by_opacity[float(o)]]
        assert d[1] == pytest.approx(0.0, abs=1e-6)
        shifts.add((round(d[0] / step[0]), round(d[2] / step[2])))
    assert shifts == {(0, 0), (1, 0), (2, 0), (0, 1), (1, 1)}
    with pytest.raises(ValueError, match="count"):
        resize_scene(c, 0)


def test_reduction_report_on_real_scenes(tmp_path, splat_transform):
    """The report's real-scene part (tiny settings): every real scene, the SOG v1 logo read through
    splat-transform when avsplat cannot read it, the scale series and the renders side by side;
    the merge rows are what the API gives on the same subsampled scene. Skips without the real
    scenes (../shared/data/real)."""
    import dataclasses

    from avsplat.evaluation import reduction
    from avsplat.eval._real_scenes import REAL_SCENES, read_real_scene, real_data_dir, resize_scene

    real = real_data_dir()
    if real is None or not all(os.path.exists(os.path.join(real, f)) for f in REAL_SCENES.values()):
        pytest.skip("the real scenes (../shared/data/real) are absent")
    s = dataclasses.replace(reduction.ReductionSettings.quick(), ratios=(1 / 4,), render_ratio=1 / 4,
                            real_scenes=("guitar", "biker", "logo"), real_max_count=1500, scale_scene="biker",
                            scale_counts=(1000, 2500))
    # Only the real part: the synthetic scenes at their smallest.
    s = dataclasses.replace(s, trained_count=300, heldout_count=300, views=2, width=24, height=18)
    rows = reduction.run_reduction(str(tmp_path), settings=s, quick=True)
    assert os.path.getsize(tmp_path / "reduction_renders.png") > 0
    md = (tmp_path / "reduction.md").read_text()
    assert "Real trained scenes" in md and "Scale series" in md and "reduction_renders.png" in md
    for name in ("guitar", "biker", "logo"):
        by = {r["method"]: r for r in rows if r["scene"] == name}
        assert set(by) == {"input", "merge", "voxel", "st-decimate", "st-adaptive"}, name
        assert by["input"]["input_count"] == 1500 and by["merge"]["output_count"] == 375
        assert not any(k.startswith("bytes") for k in by["merge"])  # no format sizes for real scenes
        assert f"- {name} 1/4:" in md
    scale = [r for r in rows if "scale_count" in r]
    assert {(r["scale_count"], r["method"]) for r in scale} == {
        (c, m) for c in (1000, 2500) for m in ("input", "merge", "st-decimate", "st-adaptive")}
    assert all(r["output_count"] == r["target"] == round(r["scale_count"] / 4) for r in scale if r["method"] != "input")
    # The merge row against the API on the same scene and cameras.
    with tempfile.TemporaryDirectory() as tmp:
        logo = read_real_scene(os.path.join(real, REAL_SCENES["logo"]), None if _reads(real) else _exe(), tmp)
    cloud = resize_scene(logo, 1500)
    cams = avsplat.orbit_cameras(cloud, s.real_cameras, width=s.real_width, height=s.real_height)
    ours = avsplat.simplify(cloud, target_count=375).cloud
    psnr = np.mean([avsplat.psnr(avsplat.render(ours, k).color, avsplat.render(cloud, k).color) for k in cams])
    row = next(r for r in rows if r["scene"] == "logo" and r["method"] == "merge")
    assert row["psnr"] == pytest.approx(psnr, rel=1e-9)


def _reads(real):
    """Whether avsplat reads the SOG v1 logo folder itself."""
    from avsplat.eval._real_scenes import REAL_SCENES

    try:
        avsplat.read_gaussians(os.path.join(real, REAL_SCENES["logo"]))
        return True
    except (ValueError, OSError, RuntimeError):
        return False


def _exe():
    from avsplat.eval.reduction import splat_transform_executable

    return splat_transform_executable()
