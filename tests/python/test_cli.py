"""The avsplat command-line tool: every subcommand with good and bad input.

The binary is the one built beside the imported package (<build>/python/avsplat ->
<build>/apps/avsplat). Outputs are compared with the Python API on the same input: `fuse` with
avsplat.fuse_gaussians / fuse_voxels (through the same PLY encoding, so bit for bit), `render`
with avsplat.render (8-bit PNG, so to the rounding of the PNG). Prediction .npz inputs are written
by numpy itself (np.savez and np.savez_compressed) with several dtypes and layouts. Every error
must be a non-zero exit code and exactly one line on stderr.
"""

import json
import os
import subprocess

import numpy as np
import pytest

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")
C0 = 0.28209479177387814

pytestmark = pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")


def run(*args, cwd=None):
    return subprocess.run([BIN, *map(str, args)], capture_output=True, text=True, timeout=120, cwd=cwd)


def ok(*args, **kw):
    p = run(*args, **kw)
    assert p.returncode == 0, f"avsplat {' '.join(map(str, args))} failed:\n{p.stdout}\n{p.stderr}"
    return p


def error(*args, contains=()):
    """Runs a command that must fail: non-zero exit, one line on stderr containing `contains`."""
    p = run(*args)
    assert p.returncode != 0, f"expected failure:\n{p.stdout}"
    lines = p.stderr.strip("\n").split("\n")
    assert len(lines) == 1, f"expected one line on stderr, got:\n{p.stderr}"
    assert lines[0].startswith("avsplat: error: "), lines[0]
    for c in [contains] if isinstance(contains, str) else contains:
        assert c in lines[0], f"{c!r} not in {lines[0]!r}"
    return lines[0]


# ------------------------------------------------------------------------------------------------
# Inputs


@pytest.fixture(scope="module")
def preds():
    """Small simulated predictions: 2 views of 32 x 24 pixels."""
    return avsplat.simulate_predictions(views=2, width=32, height=24, target_views=1, seed=3)


def gaussian_arrays(preds, rng):
    """Per-pixel Gaussian parameters in the prediction .npz layout (S, H, W, ...)."""
    S, H, W = preds.views, preds.height, preds.width
    q = rng.normal(size=(S, H, W, 4))
    return dict(points=np.array(preds.points), confidence=np.array(preds.confidence), valid=np.array(preds.valid),
                scales=rng.uniform(0.005, 0.05, size=(S, H, W, 3)).astype(np.float32),
                rotations=(q / np.linalg.norm(q, axis=-1, keepdims=True)).astype(np.float32),
                opacities=rng.uniform(0.05, 1.0, size=(S, H, W)).astype(np.float32),
                sh=rng.normal(scale=0.5, size=(S, H, W, 4, 3)).astype(np.float32))


def cloud_from_arrays(a):
    """The GaussianCloud the tool reads from a per-pixel Gaussian .npz: the valid pixels, in order."""
    v = np.asarray(a["valid"], bool)
    f32 = lambda x: np.asarray(x).astype(np.float32)[v]  # noqa: E731
    if "sh" in a:
        sh = f32(a["sh"])
    else:  # SH degree 0 from the colour, computed in double from float32 as the tool does
        sh = ((f32(a["colors"]).astype(np.float64) - 0.5) / C0).astype(np.float32)[:, None, :]
    conf = f32(a["confidence"]) if "confidence" in a else None
    return avsplat.GaussianCloud(f32(a["points"]), f32(a["scales"]), f32(a["rotations"]), f32(a["opacities"]), sh,
                                 confidence=conf)


def ply_roundtrip(cloud, path):
    """The cloud as the tool's PLY output reads back (opacity logit and log-scale in float32)."""
    avsplat.write_ply(str(path), cloud)
    return avsplat.read_ply(str(path))


def assert_same_cloud(a, b):
    assert len(a) == len(b)
    assert a.sh_degree == b.sh_degree
    for name in ("means", "scales", "rotations", "opacities", "sh", "confidence"):
        x, y = getattr(a, name), getattr(b, name)
        if x is None or y is None:
            assert x is None and y is None, name
            continue
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y), err_msg=name)


# ------------------------------------------------------------------------------------------------
# Help and usage


def test_help_of_every_subcommand():
    top = ok("--help").stdout
    for sub in ("info", "convert", "fuse", "render", "eval", "demo"):
        assert sub in top
    for sub, words in {"fuse": ["--voxel", "--policy", "--tau0", "--trim-mass", "--confidence-mapping", "--drop-invalid"],
                       "render": ["--camera", "--depth", "--backend", "--alpha-threshold"],
                       "eval": ["scaling", "--quick"], "info": ["file"], "convert": ["output"]}.items():
        text = ok(sub, "--help").stdout
        assert "Usage" in text
        for w in words:
            assert w in text, (sub, w)


def test_usage_errors_are_one_line():
    error(contains="subcommand")
    error("frobnicate", contains="subcommand")
    error("fuse", contains="required")
    error("info", "a.ply", "b.ply", contains="a.ply")


# ------------------------------------------------------------------------------------------------
# info and convert (with .npz input)


def test_info_and_its_errors(tmp_path, preds):
    path = tmp_path / "g.ply"
    avsplat.write_ply(str(path), preds.gaussians())
    out = ok("info", path).stdout
    assert f"gaussians      {int(np.count_nonzero(preds.valid))}" in out
    error("info", tmp_path / "missing.ply", contains="missing.ply")
    bad = tmp_path / "bad.ply"
    bad.write_bytes(path.read_bytes()[:400])
    error("info", bad, contains="bad.ply")


@pytest.mark.parametrize("compressed", [False, True])
def test_convert_reads_numpy_npz_of_any_dtype_and_layout(tmp_path, preds, compressed):
    rng = np.random.default_rng(5)
    a = gaussian_arrays(preds, rng)
    # The reader converts dtypes and layouts: float64, big-endian, Fortran order, float16, uint8.
    stored = dict(a)
    stored["points"] = a["points"].astype(np.float64)
    stored["scales"] = a["scales"].astype(">f4")
    stored["rotations"] = np.asfortranarray(a["rotations"])
    stored["opacities"] = a["opacities"].astype(np.float16)
    stored["valid"] = a["valid"].astype(np.uint8)
    del stored["sh"]
    stored["colors"] = rng.uniform(size=a["points"].shape).astype(np.float32)
    npz = tmp_path / "preds.npz"
    (np.savez_compressed if compressed else np.savez)(npz, **stored)
    out = tmp_path / "out.ply"
    ok("convert", npz, out)
    expected = dict(stored)
    expected["opacities"] = stored["opacities"].astype(np.float32)
    assert_same_cloud(avsplat.read_ply(str(out)), ply_roundtrip(cloud_from_arrays(expected), tmp_path / "ref.ply"))


def test_convert_errors(tmp_path):
    npz = tmp_path / "x.npz"
    np.savez(npz, points=np.zeros((4, 2), np.float32))
    error("convert", npz, tmp_path / "o.ply", contains=["x.npz", "'points'", "(4, 2)"])
    np.savez(npz, points=np.zeros((4, 3), np.float32), features=np.zeros((4, 2), np.float32))
    error("convert", npz, tmp_path / "o.ply", contains="raw features")


def test_convert_open3d_messages_stay_off_stdout(tmp_path, preds):
    """Open3D's coloured warnings reached stdout: now a failed Open3D write is one
    plain line on stderr that carries Open3D's reason, and stdout stays empty."""
    ply = tmp_path / "g.ply"
    avsplat.write_ply(str(ply), preds.gaussians())
    p = run("convert", ply, tmp_path / "g.pcd")
    if "point-cloud formats need avsplat built with Open3D" in p.stderr:
        pytest.skip("avsplat built without Open3D")
    assert p.returncode == 0, p.stderr
    assert "\x1b" not in p.stdout + p.stderr and "Open3D" not in p.stdout
    line = error("convert", ply, tmp_path / "no_such_dir" / "g.pcd", contains=["g.pcd", "Write PCD failed"])
    assert "\x1b" not in line
    assert run("convert", ply, tmp_path / "no_such_dir" / "g.pcd").stdout == ""


# ------------------------------------------------------------------------------------------------
# fuse


FUSE_CASES = [
    ("occupancy", [], {}),
    ("mean", [], {}),
    ("softmax", [], {}),
    ("occupancy", ["--tau0", "0.5", "--alpha", "0.7", "--n-ref", "4", "--tau-min", "0.1", "--tau-max", "3",
                   "--b-conf", "0.5", "--b-geo", "1.5", "--k-rel", "2", "--eps", "1e-5", "--trim-mass", "0.6",
                   "--weights", "sparsemax", "--shape", "moment", "--precision", "float64"],
     dict(tau0=0.5, alpha=0.7, n_ref=4, tau_min=0.1, tau_max=3, b_conf=0.5, b_geo=1.5, k_rel=2, eps=1e-5,
          trim_mass=0.6, weights="sparsemax", shape="moment", precision="float64")),
]


@pytest.mark.parametrize("policy,flags,knobs", FUSE_CASES, ids=["occupancy", "mean", "softmax", "knobs"])
def test_fuse_gaussian_npz_matches_python(tmp_path, preds, policy, flags, knobs):
    a = gaussian_arrays(preds, np.random.default_rng(7))
    npz = tmp_path / "preds.npz"
    np.savez(npz, **a)
    out, diag = tmp_path / "fused.ply", tmp_path / "diag.npz"
    p = ok("fuse", npz, "-o", out, "--voxel", "0.05", "--policy", policy, "--diagnostics", diag, *flags)
    ref = avsplat.fuse_gaussians(cloud_from_arrays(a), 0.05, policy=policy, **knobs)
    assert_same_cloud(avsplat.read_ply(str(out)), ply_roundtrip(ref.cloud, tmp_path / "ref.ply"))
    d = np.load(diag)
    for name in ("occupancy", "temperature", "variance", "reliability", "kept", "entropy", "voxel_coords"):
        np.testing.assert_array_equal(d[name], np.asarray(getattr(ref, name)), err_msg=name)
    assert f"into {len(ref)} voxels" in p.stdout and f"policy {policy}" in p.stdout
    assert "reading inputs" not in p.stdout + p.stderr  # progress is drawn on a terminal only


def test_fuse_concatenates_ply_and_npz_inputs(tmp_path, preds):
    rng = np.random.default_rng(11)
    a, b = gaussian_arrays(preds, rng), gaussian_arrays(preds, rng)
    for arr in (a, b):
        arr["sh"] = arr["sh"][..., :1, :]  # degree 0, so that the PLY and the .npz agree on it
    ply, npz = tmp_path / "a.ply", tmp_path / "b.npz"
    first = ply_roundtrip(cloud_from_arrays(a), ply)
    np.savez_compressed(npz, **b)
    out = tmp_path / "fused.splat"
    ok("fuse", ply, npz, "-o", out, "--voxel", "0.03")
    ref = avsplat.fuse_gaussians(avsplat.concatenate([first, cloud_from_arrays(b)]), 0.03)
    avsplat.write_splat(str(tmp_path / "ref.splat"), ref.cloud)
    assert (tmp_path / "ref.splat").read_bytes() == out.read_bytes()


def test_fuse_point_maps_npz_matches_python(tmp_path, preds):
    npz = tmp_path / "maps.npz"
    np.savez(npz, points=preds.points, colors=preds.colors, confidence=preds.confidence, valid=preds.valid)
    cams = tmp_path / "cams.json"
    avsplat.write_cameras_json(str(cams), list(preds.cameras))
    for extra, cameras in (([], None), (["--cameras", cams], list(preds.cameras))):
        out = tmp_path / "fused.ply"
        ok("fuse", npz, "-o", out, "--voxel", "0.04", *extra)
        g = avsplat.gaussians_from_point_maps(preds.points, preds.colors, preds.confidence, cameras=cameras,
                                              valid=preds.valid)
        ref = avsplat.fuse_gaussians(g, 0.04)
        assert_same_cloud(avsplat.read_ply(str(out)), ply_roundtrip(ref.cloud, tmp_path / "ref.ply"))


def test_fuse_raw_features_to_npz_matches_fuse_voxels(tmp_path, preds):
    rng = np.random.default_rng(13)
    S, H, W = preds.views, preds.height, preds.width
    feats = rng.normal(size=(S, H, W, 6)).astype(np.float32)
    npz = tmp_path / "feats.npz"
    np.savez(npz, points=preds.points, confidence=preds.confidence, valid=preds.valid, features=feats)
    out = tmp_path / "fused.npz"
    p = ok("fuse", npz, "-o", out, "--voxel", "0.05", "--policy", "softmax", "--trim-mass", "0.9")
    v = np.asarray(preds.valid)
    ref = avsplat.fuse_voxels(np.asarray(preds.points)[v], feats[v], 0.05,
                              confidence=np.asarray(preds.confidence)[v], policy="softmax", trim_mass=0.9)
    got = np.load(out)
    for name in ("positions", "features", "voxel_coords", "occupancy", "temperature", "variance", "reliability",
                 "kept", "entropy"):
        np.testing.assert_array_equal(got[name], np.asarray(getattr(ref, name)), err_msg=name)
    assert got["features"].dtype == np.float32 and got["voxel_coords"].dtype == np.int32
    assert "C = 6" in p.stdout


def test_fuse_drop_invalid(tmp_path, preds):
    a = gaussian_arrays(preds, np.random.default_rng(17))
    idx = np.argwhere(a["valid"])[0]
    a["scales"][tuple(idx)] = np.nan
    npz = tmp_path / "nan.npz"
    np.savez(npz, **a)
    error("fuse", npz, "-o", tmp_path / "o.ply", "--voxel", "0.05", contains="scales")
    p = ok("fuse", npz, "-o", tmp_path / "o.ply", "--voxel", "0.05", "--drop-invalid")
    assert "dropped invalid  1" in p.stdout


def test_fuse_value_errors_name_the_input_file(tmp_path, preds):
    """A NaN in the second of two inputs names that file and the index within it."""
    good, bad = tmp_path / "good.npz", tmp_path / "bad_second.npz"
    np.savez(good, **gaussian_arrays(preds, np.random.default_rng(23)))
    a = gaussian_arrays(preds, np.random.default_rng(29))
    a["scales"][np.nonzero(a["valid"])[0][0], np.nonzero(a["valid"])[1][0], np.nonzero(a["valid"])[2][0], 1] = np.nan
    np.savez(bad, **a)
    # The local index: the first valid pixel is Gaussian 0 of that file.
    want = "GaussianCloud.scales[0"
    for order in ([good, bad], [bad, good]):
        line = error("fuse", *order, "-o", tmp_path / "o.ply", "--voxel", "0.05", contains=[str(bad), want])
        assert str(good) not in line
        # The out-of-core path says the same.
        line = error("fuse", *order, "-o", tmp_path / "o.ply", "--voxel", "0.05", "--memory-limit", "1K",
                     contains=[str(bad), want])
    # One input: its name, too.
    error("fuse", bad, "-o", tmp_path / "o.ply", "--voxel", "0.05", contains=[str(bad), want])


def test_fuse_errors(tmp_path, preds):
    a = gaussian_arrays(preds, np.random.default_rng(19))
    good = tmp_path / "good.npz"
    np.savez(good, **a)
    o = tmp_path / "o.ply"
    error("fuse", tmp_path / "missing.npz", "-o", o, "--voxel", "1", contains="missing.npz")
    # Corrupt archives: truncated, a flipped data byte (CRC), not a zip at all.
    raw = good.read_bytes()
    cut = tmp_path / "cut.npz"
    cut.write_bytes(raw[: len(raw) // 2])
    error("fuse", cut, "-o", o, "--voxel", "1", contains="cut.npz")
    flipped = bytearray(raw)
    flipped[200] ^= 0xFF  # inside the first entry's data
    crc = tmp_path / "crc.npz"
    crc.write_bytes(bytes(flipped))
    error("fuse", crc, "-o", o, "--voxel", "1", contains=["crc.npz", "entry"])
    text = tmp_path / "text.npz"
    text.write_text("not a zip archive at all, just some text " * 3)
    error("fuse", text, "-o", o, "--voxel", "1", contains=["text.npz", "zip"])
    # Corrupt PLY.
    ply = tmp_path / "g.ply"
    avsplat.write_ply(str(ply), cloud_from_arrays(a))
    bad_ply = tmp_path / "bad.ply"
    bad_ply.write_bytes(ply.read_bytes()[:-7])
    error("fuse", bad_ply, "-o", o, "--voxel", "1", contains="bad.ply")
    # Bad knob values: words, numbers, ranges.
    error("fuse", good, "-o", o, "--voxel", "1", "--policy", "median", contains=["--policy", "median"])
    error("fuse", good, "-o", o, "--voxel", "1", "--weights", "hardmax", contains="--weights")
    error("fuse", good, "-o", o, "--voxel", "1", "--tau0", "warm", contains="--tau0")
    error("fuse", good, "-o", o, "--voxel", "1", "--tau-min", "5", contains="tau_max")
    error("fuse", good, "-o", o, "--voxel", "1", "--trim-mass", "1.5", contains="trim_mass")
    error("fuse", good, "-o", o, "--voxel", "0", contains="--voxel")
    error("fuse", good, "-o", o, contains="--voxel")
    # Outputs that do not fit the input.
    error("fuse", good, "-o", tmp_path / "o.txt", "--voxel", "1", contains=".txt")
    error("fuse", good, "-o", tmp_path / "o.npz", "--voxel", "1", contains=".ply or .splat")
    feats = tmp_path / "feats.npz"
    np.savez(feats, points=a["points"], valid=a["valid"], features=np.ones(a["points"].shape[:3] + (2,), np.float32))
    error("fuse", feats, "-o", o, "--voxel", "1", contains="raw features")
    error("fuse", feats, good, "-o", tmp_path / "o.npz", "--voxel", "1", contains="mix")
    # Prediction files with missing or misshaped arrays.
    bad = tmp_path / "bad.npz"
    np.savez(bad, points=a["points"], scales=a["scales"])
    error("fuse", bad, "-o", o, "--voxel", "1", contains=["bad.npz", "rotations"])
    np.savez(bad, points=a["points"], colors=a["points"], confidence=np.zeros((2, 3)))
    error("fuse", bad, "-o", o, "--voxel", "1", contains=["'confidence'", "(2, 3)"])
    np.savez(bad, colors=a["points"])
    error("fuse", bad, "-o", o, "--voxel", "1", contains="no array 'points'")
    np.savez(bad, points=a["points"])
    error("fuse", bad, "-o", o, "--voxel", "1", contains="not enough")
    np.savez(bad, points=a["points"], colors=np.array(["a", "b"]))
    error("fuse", bad, "-o", o, "--voxel", "1", contains=["colors.npy", "not supported"])


# ------------------------------------------------------------------------------------------------
# render


def read_png(path):
    import matplotlib.image

    img = np.asarray(matplotlib.image.imread(str(path)))
    return np.round((img if img.ndim == 2 else img[..., :3]) * 255).astype(np.int32)


def png_of(color):
    """The 8-bit values write_color_png stores: round(255 clamp(v, 0, 1))."""
    return np.round(255 * np.clip(np.asarray(color, np.float64), 0, 1)).astype(np.int32)


def test_render_matches_python(tmp_path, preds):
    cloud = preds.gaussians()
    ply = tmp_path / "g.ply"
    avsplat.write_ply(str(ply), cloud)
    cloud = avsplat.read_ply(str(ply))
    cams = list(preds.target_cameras) + list(preds.cameras)
    cam_json = tmp_path / "cams.json"
    avsplat.write_cameras_json(str(cam_json), cams)
    out, depth, alpha = tmp_path / "c.png", tmp_path / "d.png", tmp_path / "a.png"
    p = ok("render", ply, "--camera", cam_json, "-o", out, "--depth", depth, "--alpha", alpha)
    assert "rendered" in p.stdout
    ref = avsplat.render(cloud, cams[0])
    np.testing.assert_array_equal(read_png(out), png_of(ref.color))
    assert read_png(depth).shape == (cams[0].height, cams[0].width, 3)
    np.testing.assert_array_equal(read_png(alpha), png_of(ref.alpha))
    # Another camera, float64, a background and the cut-off options.
    ok("render", ply, "--camera", cam_json, "--camera-index", "2", "-o", out, "--precision", "float64",
       "--background", "0.2,0.4,0.6", "--alpha-threshold", "0.01", "--extent-sigma", "2.5")
    ref = avsplat.render(cloud, cams[2], precision="float64", background=(0.2, 0.4, 0.6), alpha_threshold=0.01,
                         extent_sigma=2.5)
    np.testing.assert_array_equal(read_png(out), png_of(ref.color))


def test_render_prediction_npz(tmp_path, preds):
    npz = tmp_path / "maps.npz"
    np.savez(npz, points=preds.points, colors=preds.colors, confidence=preds.confidence, valid=preds.valid)
    cam_json = tmp_path / "cam.json"
    avsplat.write_camera_json(str(cam_json), preds.target_cameras[0])
    out = tmp_path / "c.png"
    ok("render", npz, "--camera", cam_json, "-o", out)
    g = avsplat.gaussians_from_point_maps(preds.points, preds.colors, preds.confidence, valid=preds.valid)
    np.testing.assert_array_equal(read_png(out), png_of(avsplat.render(g, preds.target_cameras[0]).color))


def test_render_errors(tmp_path, preds):
    ply = tmp_path / "g.ply"
    avsplat.write_ply(str(ply), preds.gaussians())
    cam = tmp_path / "cam.json"
    avsplat.write_camera_json(str(cam), preds.target_cameras[0])
    out = tmp_path / "c.png"
    error("render", ply, "--camera", cam, "-o", out, "--backend", "gpu", contains=["--backend", "gpu"])
    error("render", ply, "--camera", cam, "-o", tmp_path / "c.jpg", contains="c.jpg")
    error("render", ply, "--camera", cam, "-o", out, "--depth", tmp_path / "d.bmp", contains="d.bmp")
    error("render", tmp_path / "none.ply", "--camera", cam, "-o", out, contains="none.ply")
    error("render", ply, "--camera", tmp_path / "none.json", "-o", out, contains="none.json")
    error("render", ply, "--camera", cam, "--camera-index", "5", "-o", out, contains="index 5")
    error("render", ply, "--camera", cam, "-o", out, "--alpha-threshold", "1.5", contains="alpha_threshold")
    error("render", ply, "--camera", cam, "-o", out, "--background", "1,2", contains="--background")
    bad_cam = tmp_path / "bad.json"
    bad_cam.write_text(json.dumps([{"fx": 10}]))
    error("render", ply, "--camera", bad_cam, "-o", out, contains="bad.json")
    bad_ply = tmp_path / "bad.ply"
    bad_ply.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 5\nend_header\n")
    error("render", bad_ply, "--camera", cam, "-o", out, contains="bad.ply")
    # CUDA: renders when this build has it and a device is present, else one clear line.
    p = run("render", ply, "--camera", cam, "-o", out, "--backend", "cuda")
    if p.returncode != 0:
        assert len(p.stderr.strip().split("\n")) == 1 and "CUDA" in p.stderr


# ------------------------------------------------------------------------------------------------
# eval


def test_eval_runs_the_python_report(tmp_path):
    p = ok("eval", "stability", "--quick", "-o", tmp_path)
    for ext in ("csv", "png", "md"):
        assert (tmp_path / f"stability.{ext}").stat().st_size > 0
    assert "wrote" in p.stdout


def test_eval_errors(tmp_path):
    error("eval", "speed", contains="speed")
    blocker = tmp_path / "file"
    blocker.write_text("x")
    error("eval", "stability", "--quick", "-o", blocker / "sub", contains="eval stability")


def test_eval_report_names_are_the_packages():
    """`avsplat eval` keeps no list of its own: its help names avsplat.evaluation.REPORTS."""
    from avsplat.evaluation import REPORTS
    text = ok("eval", "--help").stdout
    assert "the report: " + ", ".join(REPORTS) in " ".join(text.split())
    line = error("eval", "speed", contains=["unknown report 'speed'", ", ".join(REPORTS)])
    assert run("eval", "speed").returncode == 2, line
