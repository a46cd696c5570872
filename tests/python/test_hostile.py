"""The Python API under hostile use: odd paths, odd files, odd arrays.

Each case either gives a correct result (checked against the same call on clean float32
input) or the documented exception (ValueError naming the argument, OSError naming the file,
MemoryError), never a crash and never a silently wrong result.
"""
import json
import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import avsplat

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
SEED_PLY = os.path.join(ROOT, "tests", "fuzz", "corpus", "ply", "deg1.ply")


def small_cloud(n=5, seed=0):
    rng = np.random.default_rng(seed)
    return avsplat.GaussianCloud(
        rng.normal(size=(n, 3)), rng.uniform(0.01, 0.1, (n, 3)), rng.normal(size=(n, 4)),
        rng.uniform(0, 1, n), rng.normal(size=(n, 1, 3)))


# ---- paths -------------------------------------------------------------------------------


def test_non_utf8_file_names_read_and_write(tmp_path):
    name = os.path.join(os.fsencode(tmp_path), b"\xff\xfe scene.ply")
    cloud = small_cloud()
    avsplat.write_ply(name, cloud)
    for path in (name, os.fsdecode(name)):  # bytes, and str with surrogate escapes
        back = avsplat.read_ply(path)
        np.testing.assert_array_equal(back.means, cloud.means)


def test_error_message_keeps_non_utf8_file_name(tmp_path):
    missing = os.path.join(os.fsencode(tmp_path), b"\xffmissing.ply")
    with pytest.raises(OSError) as err:
        avsplat.read_ply(missing)
    assert "\\xffmissing.ply" in str(err.value)


@pytest.mark.parametrize("call", [
    lambda p: avsplat.read_ply(p),
    lambda p: avsplat.read_splat(p),
    lambda p: avsplat.read_camera_json(p),
    lambda p: avsplat.write_ply(p, small_cloud()),
])
def test_nul_in_path_is_refused(tmp_path, call):
    with pytest.raises(ValueError, match="NUL"):
        call(str(tmp_path / "a") + "\0b.ply")
    assert not (tmp_path / "a").exists()  # the truncated name was never written


def test_deeply_nested_camera_json_is_an_os_error(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text('{"a":' * 100000 + "1" + "}" * 100000)
    with pytest.raises(OSError, match="nested deeper than 64"):
        avsplat.read_cameras_json(str(path))


def test_camera_json_on_a_full_disk_fails_loudly():
    cam = avsplat.Camera.look_at(np.array([0, 0, -2.0]), np.zeros(3), np.array([0, -1, 0.0]),
                                 60, 64, 48)
    with pytest.raises(OSError, match="No space left on device"):
        avsplat.write_camera_json("/dev/full", cam)


def test_failed_write_keeps_the_previous_file(tmp_path):
    path = tmp_path / "cams.json"
    cam = avsplat.Camera.look_at(np.array([0, 0, -2.0]), np.zeros(3), np.array([0, -1, 0.0]),
                                 60, 64, 48)
    avsplat.write_camera_json(str(path), cam)
    good = path.read_bytes()
    os.chmod(tmp_path, 0o500)
    try:
        if os.access(tmp_path, os.W_OK):
            pytest.skip("running as root: a read-only folder is still writable")
        with pytest.raises(OSError, match="cams.json"):
            avsplat.write_camera_json(str(path), cam)
    finally:
        os.chmod(tmp_path, 0o700)
    assert path.read_bytes() == good
    assert json.loads(good)


# ---- arrays ------------------------------------------------------------------------------

DTYPES = st.sampled_from([np.float32, np.float64, np.float16, np.int32, np.int64, np.uint8,
                          np.bool_])


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(n=st.integers(0, 40), c=st.integers(0, 4), dtype=DTYPES, reverse=st.booleans(),
       seed=st.integers(0, 2**16))
def test_fuse_voxels_any_dtype_and_stride_equals_clean_float32(n, c, dtype, reverse, seed):
    rng = np.random.default_rng(seed)
    positions = (rng.normal(size=(n, 3)) * 3).astype(dtype)
    features = (rng.normal(size=(n, c)) * 3).astype(dtype)
    if reverse:  # negative strides
        positions, features = positions[::-1], features[::-1]
    got = avsplat.fuse_voxels(positions, features, 0.5)
    want = avsplat.fuse_voxels(np.ascontiguousarray(positions, np.float32),
                               np.ascontiguousarray(features, np.float32), 0.5)
    np.testing.assert_array_equal(got.positions, want.positions)
    np.testing.assert_array_equal(got.features, want.features)
    np.testing.assert_array_equal(got.voxel_coords, want.voxel_coords)


@settings(max_examples=60, deadline=None)
@given(shape=hnp.array_shapes(min_dims=0, max_dims=3, min_side=0, max_side=5))
def test_fuse_voxels_wrong_rank_names_the_argument(shape):
    positions = np.zeros(shape, np.float32)
    if positions.ndim == 2 and positions.shape[1] == 3:
        return  # a valid shape
    with pytest.raises(ValueError, match="positions"):
        avsplat.fuse_voxels(positions, np.zeros((positions.shape[0] if positions.ndim else 0, 1),
                                                np.float32), 0.5)


@settings(max_examples=40, deadline=None)
@given(value=st.sampled_from([np.nan, np.inf, -np.inf, 1e38, -1e38, 1e-45, 0.0]),
       voxel=st.sampled_from([0.5, 1e-30, 1e30, 0.0, -1.0, np.nan, np.inf]))
def test_fuse_voxels_extreme_values_raise_or_are_exact(value, voxel):
    positions = np.zeros((4, 3), np.float32)
    positions[2, 1] = value
    features = np.ones((4, 2), np.float32)
    try:
        out = avsplat.fuse_voxels(positions, features, voxel)
    except ValueError as e:
        assert "positions" in str(e) or "voxel_size" in str(e)
        return
    assert np.isfinite(out.positions).all() and np.isfinite(out.features).all()
    np.testing.assert_array_equal(out.features, 1.0)  # every weighted mean of ones is one


def test_gaussian_cloud_object_and_complex_dtypes_raise_value_or_type_error():
    for bad in (np.array([[object()] * 3]), np.zeros((1, 3), np.complex64)):
        with pytest.raises((ValueError, TypeError)):
            avsplat.GaussianCloud(bad, np.ones((1, 3)), np.array([[1, 0, 0, 0]]), np.ones(1),
                                  np.zeros((1, 1, 3)))


def test_render_of_an_absurd_image_size_is_a_clean_error():
    cloud = small_cloud()
    cam = avsplat.Camera.look_at(np.array([0, 0, -2.0]), np.zeros(3), np.array([0, -1, 0.0]),
                                 60, 10**6, 10**6)
    with pytest.raises((ValueError, MemoryError)):
        avsplat.render(cloud, cam)


def test_failed_png_write_keeps_the_old_png_and_the_symlink(tmp_path):
    import subprocess
    import sys
    png = tmp_path / "render.png"
    img = np.random.default_rng(0).uniform(size=(64, 64, 3))
    avsplat.write_color_png(str(png), img)
    good = png.read_bytes()
    # A file-size limit below the new PNG's size: the write fails in the child (OSError, not
    # SIGXFSZ), and the old PNG is intact.
    code = (
        "import resource, signal, sys, numpy as np, avsplat\n"
        "signal.signal(signal.SIGXFSZ, signal.SIG_IGN)\n"
        "resource.setrlimit(resource.RLIMIT_FSIZE, (1000, 1000))\n"
        "noise = np.random.default_rng(1).uniform(size=(256, 256, 3))\n"
        "try:\n"
        "    avsplat.write_color_png(sys.argv[1], noise)\n"
        "except OSError as e:\n"
        "    print('OSError', e); sys.exit(3)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    run = subprocess.run([sys.executable, "-c", code, str(png)], env=env, capture_output=True, text=True)
    assert run.returncode == 3, run.stdout + run.stderr
    assert png.read_bytes() == good
    assert sorted(os.listdir(tmp_path)) == ["render.png"]  # no temporary file left behind
    # A symlink to a full device: the write fails and the link is still a link to it.
    link = tmp_path / "full.png"
    os.symlink("/dev/full", link)
    with pytest.raises(OSError, match="No space left on device"):
        avsplat.write_color_png(str(link), img)
    assert os.readlink(link) == "/dev/full"


@pytest.mark.parametrize("reader", [avsplat.read_ply, avsplat.read_splat, avsplat.read_cameras_json])
def test_directories_fifos_and_devices_are_refused_at_once(tmp_path, reader):
    fifo = tmp_path / "pipe.ply"
    os.mkfifo(fifo)
    # A FIFO with no writer would block open() forever; /dev/zero would read without end.
    for path, message in ((tmp_path, "is a directory"), (fifo, "not a regular file"),
                          ("/dev/zero", "not a regular file")):
        with pytest.raises(OSError, match=message) as err:
            reader(str(path))
        assert str(path) in str(err.value)


def test_views_kept_across_sanitize_stay_valid():
    # sanitize() used to rebuild the arrays, freeing the memory that earlier numpy views used:
    # writing through them was a use-after-free. It now compacts in place.
    cloud = small_cloud(1000)
    cloud.opacities[::2] = np.nan
    means, sh = cloud.means, cloud.sh
    kept_means = np.array(cloud.means[1::2])
    report = cloud.sanitize()
    assert report.kept == 500 and report.non_finite == 500
    np.testing.assert_array_equal(cloud.means, kept_means)
    np.testing.assert_array_equal(means[:500], kept_means)  # the old view sees the compacted rows
    means[:] = 1.0  # writes through a view kept across sanitize land in live memory
    sh[:] = 0.0
    np.testing.assert_array_equal(cloud.means, 1.0)


def test_sanitize_while_another_thread_fuses_does_not_crash():
    import threading
    cloud = small_cloud(200000, seed=3)
    cloud.opacities[::3] = 2.0  # invalid: dropped by sanitize, tolerated by on_invalid="drop"
    errors = []

    def fuse():
        try:
            for _ in range(3):
                avsplat.fuse_gaussians(cloud, 0.05, on_invalid="drop")
        except (ValueError, RuntimeError) as e:  # a documented error is fine, a crash is not
            errors.append(e)

    t = threading.Thread(target=fuse)
    t.start()
    cloud.sanitize()
    t.join()
    assert len(cloud) == 200000 - len(range(0, 200000, 3))


def test_cli_exit_codes_say_what_failed(tmp_path):
    import resource
    import subprocess
    binary = os.path.join(os.path.dirname(os.path.dirname(os.path.dirname(
        os.path.abspath(avsplat.__file__)))), "apps", "avsplat")
    good = tmp_path / "g.ply"
    avsplat.write_ply(str(good), small_cloud(2000))
    bad = tmp_path / "bad.ply"
    bad.write_bytes(good.read_bytes()[:150])

    def cli(*args, limit=None):
        def preexec():
            if limit:
                resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
        return subprocess.run([binary, *map(str, args)], capture_output=True, text=True, preexec_fn=preexec)

    p = cli("bogus")
    assert p.returncode == 2 and "unknown subcommand 'bogus'" in p.stderr and p.stdout == ""
    p = cli("convert", bad, tmp_path / "o.splat")
    assert p.returncode == 3 and str(bad) in p.stderr and p.stdout == ""
    p = cli("convert", good, "/dev/full/o.splat")
    assert p.returncode == 4 and "/dev/full/o.splat" in p.stderr
    out = tmp_path / "o.ply"
    out.write_bytes(b"previous file")
    p = cli("convert", good, out, limit=4096)  # the tool ignores SIGXFSZ and reports the error
    assert p.returncode == 4 and "File too large" in p.stderr, p.stderr
    assert out.read_bytes() == b"previous file"
    assert "Exit codes" in cli("--help").stdout


# ---- sizes before allocating -------------------------------------------------------------------

def test_a_huge_broadcast_input_is_a_memory_error_naming_the_argument():
    """Broadcast views present gigabytes in no memory; converting them must fail cleanly, as a
    MemoryError that names the argument (it was a misleading 'expected a float array of shape'),
    under an address-space limit so that the test never really allocates them."""
    import subprocess
    import sys
    code = r'''
import resource, numpy as np, avsplat
resource.setrlimit(resource.RLIMIT_AS, (3 << 30, 3 << 30))
f = lambda shape: np.broadcast_to(np.float32(0.5), shape)
cases = {
    "positions": lambda: avsplat.fuse_voxels(f((1 << 31, 3)), f((1 << 31, 1)), 0.5),
    "features": lambda: avsplat.fuse_voxels(f((1 << 20, 3)), f((1 << 20, 1 << 14)), 0.5),
    "means": lambda: avsplat.GaussianCloud(f((1 << 31, 3)), f((1 << 31, 3)), f((1 << 31, 4)), f((1 << 31,)),
                                           f((1 << 31, 1, 3))),
    "points": lambda: avsplat.gaussians_from_point_maps(f((64, 4096, 4096, 3)), f((64, 4096, 4096, 3)), None),
    "a": lambda: avsplat.psnr(f((1 << 16, 1 << 16, 3)), f((1 << 16, 1 << 16, 3))),
}
for arg, call in cases.items():
    try:
        call()
        print(arg, "returned")
    except MemoryError as e:
        print(arg, "MemoryError", str(e).startswith(arg + ":"))
'''
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                       env={**os.environ, "OMP_NUM_THREADS": "1"})
    assert p.returncode == 0, p.stderr
    lines = p.stdout.strip().split("\n")
    assert len(lines) == 5, p.stdout
    for line in lines:
        assert line.endswith("MemoryError True"), line


# ---- inputs changed by another thread during a call --------------------------------------------

def test_inputs_mutated_by_another_thread_during_calls_cannot_crash():
    """The documented rule (README, Reliability): inputs are read, not copied, while the GIL is
    released; another thread writing to them during a call gives a result of mixed old and new
    values or an exception (ValueError, or RuntimeError from an internal check that sees values
    change under it, e.g. a confidence that became NaN after validation), never a crash. Run in a child process, so that a crash fails this test
    instead of killing pytest."""
    import subprocess
    import sys
    code = r'''
import threading, numpy as np, avsplat
rng = np.random.default_rng(0)
n = 40000
pos = (rng.normal(size=(n, 3)) * 2).astype(np.float32)
feat = rng.normal(size=(n, 4)).astype(np.float32)
conf = rng.normal(size=n).astype(np.float32)
pred = avsplat.simulate_predictions(views=2, width=64, height=48, seed=0, target_views=1)
cloud, cam = pred.gaussians(), pred.target_cameras[0]
points, colors = np.array(pred.points, np.float32), np.array(pred.colors, np.float32)
targets = [pos, conf, points, cloud.means, cloud.scales, cloud.rotations, cloud.opacities, cloud.sh]
stop = threading.Event()
def mutate():
    r = np.random.default_rng(1)
    vals = np.array([np.nan, np.inf, -np.inf, 1e30, -1e30, 0.0, 1e-3, 5.0, -1.0], np.float32)
    while not stop.is_set():
        flat = targets[r.integers(0, len(targets))].reshape(-1)
        idx = r.integers(0, flat.size, 500)
        if r.integers(0, 2):
            flat[idx] = vals[r.integers(0, len(vals))]
        else:  # plausible values far from the others: keys leave the first pass's box
            flat[idx] = r.normal(size=500).astype(np.float32) * np.float32(r.choice([1, 1e3, 1e6]))
t = threading.Thread(target=mutate)
t.start()
calls = [
    lambda: avsplat.fuse_voxels(pos, feat, 0.05, confidence=conf, policy="occupancy"),
    lambda: avsplat.fuse_voxels(pos, feat, 0.05, on_invalid="drop"),
    lambda: avsplat.SparseVoxelGrid(pos, 0.05),
    lambda: avsplat.fuse_gaussians(cloud, 0.02, on_invalid="drop"),
    lambda: avsplat.render(cloud, cam),
    lambda: avsplat.gaussians_from_point_maps(points, colors, None),
    lambda: avsplat.chamfer_distance(pos[:3000], pos[3000:6000]),
]
outcomes = {"ok": 0, "ValueError": 0, "MemoryError": 0, "RuntimeError": 0}
try:
    for _ in range(25):
        for call in calls:
            try:
                call()
                outcomes["ok"] += 1
            except (ValueError, MemoryError, RuntimeError) as e:
                outcomes[type(e).__name__] += 1
finally:
    stop.set()
    t.join()
print(outcomes)
'''
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=600)
    assert p.returncode == 0, f"rc {p.returncode}\n{p.stdout}\n{p.stderr[-2000:]}"
    outcomes = eval(p.stdout.strip().split("\n")[-1])
    assert sum(outcomes.values()) == 25 * 7


def test_names_in_a_file_that_are_not_utf8_round_trip(tmp_path):
    """Found by test_properties.py: a PLY property name with a byte that is not UTF-8 made
    read_ply_data raise UnicodeDecodeError. Names are decoded with surrogate escapes, as
    os.fsdecode does, so they round-trip to the file's bytes."""
    header = (b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
              b"property float opacity\nproperty float scale_0\nproperty float scale_1\nproperty float scale_2\n"
              b"property float rot_0\nproperty float rot_1\nproperty float rot_2\nproperty float rot_3\n"
              b"property float f_dc_0\nproperty float f_dc_1\nproperty float f_dc_2\nproperty float t\x80mp\n"
              b"end_header\n0 0 0 0 0 0 0 1 0 0 0 0 0 0 7\n")
    path = tmp_path / "names.ply"
    path.write_bytes(header)
    columns = avsplat.read_ply_data(str(path))["vertex"]
    name = next(k for k in columns if k.startswith("t"))
    assert os.fsencode(name) == b"t\x80mp" and columns[name][0] == 7
    extras = avsplat.read_ply(str(path)).extras
    assert [os.fsencode(k) for k in extras] == [b"t\x80mp"]
