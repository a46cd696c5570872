"""What the tool says: summaries that report real figures, help that lists what it reads,
errors that name the files."""

import os
import re
import subprocess

import numpy as np
import pytest

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")

pytestmark = pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")


def run(*args):
    return subprocess.run([BIN, *map(str, args)], capture_output=True, text=True, timeout=300)


def cloud_of(n, seed=0, confidence=False):
    rng = np.random.default_rng(seed)
    m = rng.uniform(-1, 1, size=(n, 3)).astype(np.float32)
    return avsplat.GaussianCloud(m, np.full((n, 3), 0.01, np.float32), np.tile(np.float32([1, 0, 0, 0]), (n, 1)),
                                 np.full(n, 0.5, np.float32), rng.normal(size=(n, 1, 3)).astype(np.float32),
                                 confidence=rng.normal(size=n).astype(np.float32) if confidence else None)


def test_fuse_reports_the_time_the_fusion_took(tmp_path):
    # The clock used to be read before the fusion ran (both in one call's arguments), so the
    # summary said "in 0.000 s" whatever the input. 200k samples take well over a millisecond.
    avsplat.write_ply(tmp_path / "in.ply", cloud_of(200_000))
    p = run("fuse", tmp_path / "in.ply", "-o", tmp_path / "out.ply", "--voxel", "0.01")
    assert p.returncode == 0, p.stderr
    seconds = float(re.search(r"in ([0-9.]+) s", p.stdout).group(1))
    assert seconds > 0.0, p.stdout


def test_no_subcommand_lists_the_subcommands():
    p = run()
    assert p.returncode == 2
    assert p.stderr.count("\n") == 1
    for name in ("info", "convert", "fuse", "render", "prune", "simplify", "cameras", "view"):
        assert name in p.stderr
    p = run("cameras")
    assert p.returncode == 2 and "orbit, colmap" in p.stderr


def test_help_lists_every_format_the_subcommand_reads(tmp_path):
    cloud = cloud_of(50)
    names = set()
    for suffix in (".ply", ".compressed.ply", ".splat", ".spz", ".sog"):
        path = tmp_path / f"scene{suffix}"
        avsplat.write_gaussians(path, cloud)
        names.add(avsplat.detect_gaussian_format(path).name)
        assert run("info", path).returncode == 0
        assert run("render", path, "--size", "16x12", "-o", tmp_path / "r.png").returncode == 0
    assert len(names) == 5
    for cmd in ("info", "render", "prune", "simplify", "fuse", "convert"):
        text = " ".join(run(cmd, "--help").stdout.split())
        missing = [n for n in sorted(names) if n not in text]
        assert not missing, f"avsplat {cmd} --help does not name {missing}"


def test_simplify_ratio_accepts_a_percentage(tmp_path):
    avsplat.write_ply(tmp_path / "in.ply", cloud_of(400))
    for ratio in ("25%", "0.25"):
        p = run("simplify", tmp_path / "in.ply", tmp_path / "out.ply", "--ratio", ratio)
        assert p.returncode == 0, p.stderr
        assert "400 -> 100 Gaussians" in p.stdout
    for bad in ("x%", "250%", "25%%"):
        p = run("simplify", tmp_path / "in.ply", tmp_path / "out.ply", "--ratio", bad)
        assert p.returncode == 2 and "--ratio" in p.stderr


def test_fuse_names_the_files_whose_channels_differ(tmp_path):
    a, b = tmp_path / "with_conf.ply", tmp_path / "without.ply"
    avsplat.write_ply(a, cloud_of(30, confidence=True))
    avsplat.write_ply(b, cloud_of(30, seed=1))
    for first, second in ((a, b), (b, a)):
        p = run("fuse", first, second, "-o", tmp_path / "out.ply", "--voxel", "0.1")
        assert p.returncode == 3
        assert str(first) in p.stderr and str(second) in p.stderr and "confidence" in p.stderr
        assert "clouds[" not in p.stderr


def test_fuse_warns_about_unmasked_pixels_at_the_origin_and_help_documents_valid(tmp_path):
    rng = np.random.default_rng(2)
    S, H, W = 1, 6, 8
    points = rng.uniform(-1, 1, size=(S, H, W, 3)).astype(np.float32)
    points[0, :2] = 0.0  # 16 pixels the model did not predict
    arrays = dict(points=points, colors=np.full((S, H, W, 3), 0.5, np.float32),
                  scales=np.full((S, H, W, 3), 0.01, np.float32),
                  rotations=np.tile(np.float32([1, 0, 0, 0]), (S, H, W, 1)),
                  opacities=np.full((S, H, W), 0.5, np.float32))
    np.savez(tmp_path / "no_valid.npz", **arrays)
    p = run("fuse", tmp_path / "no_valid.npz", "-o", tmp_path / "out.ply", "--voxel", "0.05")
    assert p.returncode == 0, p.stderr
    assert "no_valid.npz: 16 samples lie exactly at (0, 0, 0)" in p.stderr and "valid" in p.stderr
    valid = np.ones((S, H, W), bool)
    valid[0, :2] = False
    np.savez(tmp_path / "with_valid.npz", valid=valid, **arrays)
    p = run("fuse", tmp_path / "with_valid.npz", "-o", tmp_path / "out.ply", "--voxel", "0.05")
    assert p.returncode == 0 and "warning" not in p.stderr
    assert "`valid` (S, H, W)" in " ".join(run("fuse", "--help").stdout.split())


def test_simplify_max_error_shows_a_bar_on_a_terminal_only(tmp_path):
    import pty

    avsplat.write_ply(tmp_path / "in.ply", cloud_of(300))
    args = [BIN, "simplify", str(tmp_path / "in.ply"), str(tmp_path / "out.ply"), "--max-error", "0.05", "--orbit", "2",
            "--size", "32x24"]
    p = subprocess.run(args, capture_output=True, text=True, timeout=300)
    assert p.returncode == 0 and p.stderr == "" and "searching" not in p.stdout
    for quiet, shown in (([], True), (["--quiet"], False)):
        master, slave = pty.openpty()
        try:
            p = subprocess.run(args + quiet, stdout=subprocess.PIPE, stderr=slave, timeout=300)
            os.close(slave)
            terminal = b""
            while True:
                try:
                    chunk = os.read(master, 65536)
                except OSError:
                    break
                if not chunk:
                    break
                terminal += chunk
        finally:
            os.close(master)
        assert p.returncode == 0
        assert (b"searching the count" in terminal) == shown
