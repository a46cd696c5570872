"""Files and command lines from a hostile user: small files that declare gigabytes, files the
writers produce at the edges of the formats, command-line values at the edge of their types, and
the exit codes of `avsplat --help` (2 usage, 3 input, 4 output)."""
import io
import json
import os
import resource
import subprocess
import sys
import zipfile

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import avsplat

BUILD = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(avsplat.__file__))))
BIN = os.path.join(BUILD, "apps", "avsplat")
needs_cli = pytest.mark.skipif(not os.access(BIN, os.X_OK), reason=f"no avsplat binary at {BIN}")


def cli(*args, env=None):
    return subprocess.run([BIN, *map(str, args)], capture_output=True, text=True, timeout=300, env=env)


def peak_rss_of(code, *args):
    """Runs `code` in a child Python; returns (return code, stdout, stderr, peak RSS in MB of the child
    and its children)."""
    wrapper = ("import resource, subprocess, sys\n"
               "p = subprocess.run(sys.argv[1:], capture_output=True, text=True)\n"
               "print(p.returncode); print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss // 1024)\n"
               "sys.stderr.write(p.stderr)\n")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(sys.path))
    p = subprocess.run([sys.executable, "-c", wrapper, *args], capture_output=True, text=True, timeout=300, env=env)
    rc, rss = p.stdout.split()[:2]
    return int(rc), p.stderr, int(rss)


def cloud_of(n, seed=0, degree=0):
    rng = np.random.default_rng(seed)
    k = (degree + 1) ** 2
    return avsplat.GaussianCloud(rng.normal(size=(n, 3)), rng.uniform(0.01, 0.1, (n, 3)), rng.normal(size=(n, 4)),
                                 rng.uniform(0, 1, n), rng.normal(size=(n, k, 3)) * 0.3)


# ---- SOG: nearly constant images that declare gigabytes ------------------------------------------

def constant_webp(side):
    from PIL import Image
    b = io.BytesIO()
    Image.new("RGBA", (side, side), (7, 9, 11, 255)).save(b, "WEBP", lossless=True, method=0)
    return b.getvalue()


def test_a_small_sog_declaring_millions_of_identical_gaussians_is_refused_before_decoding(tmp_path):
    pytest.importorskip("PIL.WebPImagePlugin")
    src = tmp_path / "src"
    avsplat.write_sog(str(src), cloud_of(64))
    meta = json.loads((src / "meta.json").read_text())
    count, side = 1 << 22, 2048
    meta["count"] = count
    image = constant_webp(side)
    names = [*meta["means"]["files"], *meta["scales"]["files"], *meta["quats"]["files"], *meta["sh0"]["files"]]
    bomb = tmp_path / "bomb.sog"
    with zipfile.ZipFile(bomb, "w", zipfile.ZIP_STORED) as z:
        z.writestr("meta.json", json.dumps(meta))
        for name in names:
            z.writestr(name, image)
    assert bomb.stat().st_size < 64 << 10
    code = ("import sys, avsplat\n"
            "try:\n    avsplat.read_sog(sys.argv[1])\nexcept OSError as e:\n    print(e); sys.exit(3)\n")
    rc, err, rss = peak_rss_of(code, sys.executable, "-c", code, str(bomb))
    assert rc == 3, err
    assert rss < 200, rss  # the cloud alone would take 235 MB, the images 64 MB each


def test_write_sog_refuses_what_read_sog_would_refuse(tmp_path):
    n = (1 << 20) + 4
    c = avsplat.GaussianCloud.empty(n, 0)
    with pytest.raises(OSError, match="65536 times"):
        avsplat.write_sog(str(tmp_path / "same.sog"), c, iterations=0)
    assert not (tmp_path / "same.sog").exists()
    small = avsplat.GaussianCloud.empty(1000, 0)  # under 2^20 Gaussians: no bound
    avsplat.write_sog(str(tmp_path / "small.sog"), small, iterations=0)
    assert len(avsplat.read_sog(str(tmp_path / "small.sog"))) == 1000


# ---- SPZ: identical Gaussians compress past deflate's ratio under ZSTD ---------------------------

def test_spz_of_identical_gaussians_reads_back(tmp_path):
    c = avsplat.GaussianCloud.empty(100000, 0)
    c.scales[:] = 0.01
    path = str(tmp_path / "same.spz")
    avsplat.write_spz(path, c)
    assert os.path.getsize(path) < 2000
    back = avsplat.read_spz(path)
    assert len(back) == 100000
    np.testing.assert_allclose(back.scales, 0.01, rtol=0.05)


# ---- writers refuse what their readers would refuse ----------------------------------------------

EDGES = [0.0, 1e-38, 1.0, 1e30, 1e37, 1.5e38, 2e38, 3e38, float(np.finfo(np.float32).max)]
WRITERS = {
    "ply": (avsplat.write_ply, avsplat.read_ply, "x.ply"),
    "compressed": (avsplat.write_compressed_ply, avsplat.read_compressed_ply, "x.compressed.ply"),
    "spz": (avsplat.write_spz, avsplat.read_spz, "x.spz"),
    "sog": (lambda p, c: avsplat.write_sog(p, c, iterations=1), avsplat.read_sog, "x.sog"),
    "splat": (avsplat.write_splat, avsplat.read_splat, "x.splat"),
}


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(mean=st.sampled_from(EDGES), sign=st.sampled_from([1.0, -1.0]), axis=st.integers(0, 2),
       scale=st.sampled_from(EDGES[1:]), dc=st.sampled_from(EDGES), fmt=st.sampled_from(sorted(WRITERS)))
def test_what_a_writer_accepts_its_reader_reads(tmp_path, mean, sign, axis, scale, dc, fmt):
    write, read, name = WRITERS[fmt]
    c = cloud_of(8, seed=1)
    c.means[3, axis] = sign * mean
    c.scales[5, axis] = scale
    c.sh[6, 0, axis] = sign * dc
    path = str(tmp_path / name)
    try:
        write(path, c)
    except ValueError as e:
        assert "[" in str(e)  # names the index
        return
    back = read(path)
    assert len(back) == 8


def test_writers_name_the_gaussian_they_refuse(tmp_path):
    c = cloud_of(8)
    c.means[5, 1] = 3e38
    with pytest.raises(ValueError, match=r"means\[5\]\[1\]"):
        avsplat.write_sog(str(tmp_path / "far.sog"), c)
    with pytest.raises(ValueError, match=r"means\[5\]\[1\]"):
        avsplat.write_compressed_ply(str(tmp_path / "far.compressed.ply"), c)


# ---- .npz: shapes checked before inflating -------------------------------------------------------

def deflated_npz(path, name, shape, dtype="<f4"):
    """An .npz with one deflated entry of zeros of `shape`, made without holding the array."""
    header = f"{{'descr': '{dtype}', 'fortran_order': False, 'shape': {tuple(shape)}, }}"
    header = header + " " * (63 - (10 + len(header)) % 64) + "\n"
    prefix = b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header.encode()
    size = int(np.prod(shape)) * np.dtype(dtype).itemsize
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        with z.open(name + ".npy", "w", force_zip64=True) as f:
            f.write(prefix)
            zeros = bytes(1 << 22)
            left = size
            while left:
                f.write(zeros[:min(left, len(zeros))])
                left -= min(left, len(zeros))


@needs_cli
def test_a_prediction_npz_of_the_wrong_shape_is_refused_before_inflating(tmp_path):
    path = tmp_path / "bomb.npz"
    deflated_npz(path, "points", (1 << 26,))  # 256 MB of float32, the wrong shape
    assert path.stat().st_size < 2 << 20
    rc, err, rss = peak_rss_of("", BIN, "fuse", str(path), "-o", str(tmp_path / "o.ply"), "--voxel", "0.1")
    assert rc == 3, err
    assert "shape (67108864,)" in err
    assert rss < 150, rss


# ---- .splat is not guessed from the size alone ---------------------------------------------------

def test_json_whose_size_is_a_multiple_of_32_is_not_read_as_splat(tmp_path):
    p = tmp_path / "brackets.json"
    p.write_text("[" * (1 << 20) + "]" * (1 << 20))
    with pytest.raises(OSError, match="not .splat records"):
        avsplat.read_gaussians(str(p))


# ---- command lines -------------------------------------------------------------------------------

@needs_cli
def test_cli_exit_codes_follow_the_table(tmp_path):
    good = tmp_path / "g.ply"
    avsplat.write_ply(str(good), cloud_of(100))
    p = cli("fuse", tmp_path / "missing.ply", "-o", tmp_path / "o.ply", "--voxel", "0.1")
    assert p.returncode == 3 and "missing.ply" in p.stderr and len(p.stderr.splitlines()) == 1, p.stderr
    p = cli("simplify", tmp_path / "missing.ply", tmp_path / "o.ply", "--target-count", "5")
    assert p.returncode == 3, p.stderr
    p = cli("fuse", good, "-o", tmp_path / "o.ply", "--voxel", "0.1", "--memory-limit", "16777216T")
    assert p.returncode != 0 and "2^64" in p.stderr and "0 MB" not in p.stdout, p.stdout + p.stderr
    p = cli("simplify", good, tmp_path / "o.ply", "--target-count", "0")
    assert p.returncode == 2 and len(p.stderr) < 200 and ">= 1" in p.stderr, p.stderr


@needs_cli
def test_spill_files_that_cannot_be_written_are_an_output_error(tmp_path):
    good = tmp_path / "g.ply"
    avsplat.write_ply(str(good), cloud_of(20000))
    args = ("fuse", good, "-o", tmp_path / "o.ply", "--voxel", "0.01", "--memory-limit", "64K")
    # A work folder that cannot be made (TMPDIR is not a folder) ...
    p = cli(*args, env=dict(os.environ, TMPDIR="/dev/full"))
    assert p.returncode == 4, p.stdout + p.stderr
    # ... and spill files that cannot grow (a file-size limit, as a full disk).
    limit = lambda: resource.setrlimit(resource.RLIMIT_FSIZE, (8192, 8192))  # noqa: E731
    p = subprocess.run([BIN, *map(str, args)], capture_output=True, text=True, timeout=300, preexec_fn=limit,
                       env=dict(os.environ, TMPDIR=str(tmp_path)))
    assert p.returncode == 4 and "spill file" in p.stderr, p.stdout + p.stderr
    assert not [n for n in os.listdir(tmp_path) if n.startswith("avsplat-fusion-")]


def test_fusion_stream_memory_limit_beyond_size_t_is_a_value_error():
    with pytest.raises(ValueError, match="memory_limit"):
        avsplat.FusionStream(0.1, memory_limit=2**70)
    with pytest.raises(TypeError, match="memory_limit"):
        avsplat.FusionStream(0.1, memory_limit="1G")


@needs_cli
def test_cli_bogus_scheduler_is_a_one_line_usage_error(tmp_path):
    pytest.importorskip("distributed")
    good = tmp_path / "g.ply"
    avsplat.write_ply(str(good), cloud_of(100))
    env = dict(os.environ, AVSPLAT_PYTHON=sys.executable, PYTHONPATH=os.pathsep.join(sys.path))
    p = cli("fuse", good, "-o", tmp_path / "o.ply", "--voxel", "0.1", "--scheduler", "bogus", env=env)
    assert p.returncode == 2, p.stderr
    assert p.stderr.count("\n") == 1 and p.stderr.startswith("avsplat: error: --scheduler 'bogus'"), p.stderr
